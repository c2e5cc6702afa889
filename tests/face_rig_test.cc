#include "core/face_rig.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"

#include <filesystem>
#include <fstream>
#include <set>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh_primitives.h"
#include "core/rig_import.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::TestDir;
using testing::WriteText;
namespace fs = std::filesystem;

const fs::path kSampleRig = fs::path(CREASE_DATA_DIR) / "sample_rig";

FaceRig SmallRig() {
  FaceRig rig;
  rig.neutral = MakeGrid(3, 2, 30.0, 20.0);
  rig.neutral.N.resize(0, 3);
  const int n = 3 * rig.neutral.num_vertices();
  rig.identity_basis = Eigen::MatrixXf::Random(n, 2);
  rig.expression_basis = Eigen::MatrixXf::Random(n, 3);
  rig.identity_names = {"width", "length"};
  rig.expression_names = {"jawOpen", "eyeBlink_L", "eyeBlink_R"};
  rig.landmarks = {{"nose_tip", 5}, {"chin", 1}};
  cv::Mat m = cv::Mat::zeros(32, 32, CV_8UC1);
  m(cv::Rect(0, 0, 16, 8)) = 255;
  rig.regions = {{"forehead", m}};
  rig.part_names = {"face", "eyeball_left"};
  rig.vertex_part.assign(rig.num_vertices(), 0);
  rig.vertex_part[3] = 1;
  return rig;
}


TEST(FaceRig, EvaluateIsTheLinearBlendshapeModel) {
  const FaceRig rig = SmallRig();
  Eigen::VectorXd a(2), b(3);
  a << 0.5, -1.0;
  b << 1.0, 0.0, 0.25;
  const MatX3d V = rig.EvaluatePositions(a, b);
  for (int v = 0; v < rig.num_vertices(); ++v) {
    for (int k = 0; k < 3; ++k) {
      double expect = rig.neutral.V(v, k);
      for (int i = 0; i < 2; ++i) expect += a[i] * rig.identity_basis(3 * v + k, i);
      for (int e = 0; e < 3; ++e) expect += b[e] * rig.expression_basis(3 * v + k, e);
      EXPECT_NEAR(V(v, k), expect, 1e-6);
    }
  }
  // Shorter coefficient vectors mean zeros for the rest; empty gives the neutral.
  EXPECT_EQ(rig.EvaluatePositions({}, {}), rig.neutral.V);
  EXPECT_NE(ErrorOf([&] { rig.EvaluatePositions(Eigen::VectorXd::Zero(3), {}); }).find("3 identity coefficients"),
            std::string::npos);
  EXPECT_EQ(rig.ExpressionIndex("eyeBlink_R"), 2);
  EXPECT_EQ(rig.ExpressionIndex("nope"), -1);
  EXPECT_TRUE(rig.InRegion("forehead", {0.1, 0.1}));
  EXPECT_FALSE(rig.InRegion("forehead", {0.9, 0.9}));
  EXPECT_FALSE(rig.InRegion("chin", {0.1, 0.1}));
}

TEST(FaceRig, FileRoundTripIsExact) {
  const FaceRig rig = SmallRig();
  const fs::path p = ::crease::testing::TestDir() / "small.crig";
  WriteRig(p, rig);
  const FaceRig back = ReadRig(p);
  EXPECT_EQ(back.neutral.V, rig.neutral.V);
  EXPECT_EQ(back.neutral.F, rig.neutral.F);
  EXPECT_EQ(back.neutral.UV, rig.neutral.UV);
  EXPECT_EQ(back.identity_basis, rig.identity_basis);
  EXPECT_EQ(back.expression_basis, rig.expression_basis);
  EXPECT_EQ(back.expression_names, rig.expression_names);
  ASSERT_EQ(back.landmarks.size(), 2u);
  EXPECT_EQ(back.landmarks[0].vertex, 5);
  EXPECT_EQ(back.part_names, rig.part_names);
  EXPECT_EQ(back.vertex_part, rig.vertex_part);
  EXPECT_EQ(back.PartIndex("eyeball_left"), 1);
  ASSERT_EQ(back.regions.size(), 1u);
  EXPECT_EQ(cv::norm(back.regions[0].mask, rig.regions[0].mask, cv::NORM_INF), 0.0);
}

TEST(FaceRig, MalformedFilesGiveNamedErrors) {
  const fs::path dir = ::crease::testing::TestDir();
  const fs::path good = dir / "good.crig";
  WriteRig(good, SmallRig());
  std::string bytes;
  {
    std::ifstream in(good, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const fs::path truncated = dir / "truncated.crig";
  std::ofstream(truncated, std::ios::binary) << bytes.substr(0, bytes.size() - 10);
  EXPECT_NE(ErrorOf([&] { ReadRig(truncated); }).find("truncated.crig: truncated rig file"), std::string::npos);
  const fs::path magic = dir / "magic.crig";
  std::ofstream(magic, std::ios::binary) << "PLY nonsense";
  EXPECT_NE(ErrorOf([&] { ReadRig(magic); }).find("not a crease rig"), std::string::npos);
  std::string v3 = bytes;
  v3[8] = 3;
  const fs::path version = dir / "version.crig";
  std::ofstream(version, std::ios::binary) << v3;
  EXPECT_NE(ErrorOf([&] { ReadRig(version); }).find("version 3 is not supported"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { ReadRig(dir / "absent.crig"); }).find("file does not exist"), std::string::npos);

  FaceRig bad = SmallRig();
  bad.landmarks.push_back({"oops", 1000});
  EXPECT_NE(ErrorOf([&] { WriteRig(dir / "bad.crig", bad); }).find("landmark 'oops' references vertex 1000"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "bad.crig"));
  bad = SmallRig();
  bad.expression_names[1] = "jawOpen";
  EXPECT_NE(ErrorOf([&] { bad.Validate("r"); }).find("expression name 'jawOpen' appears twice"), std::string::npos);
  bad = SmallRig();
  bad.neutral.UV.resize(0, 2);
  EXPECT_NE(ErrorOf([&] { bad.Validate("r"); }).find("no UV coordinates"), std::string::npos);
}

// Issue 19 (cdm_fuzzer): an array shape holding a float (1e72) was converted to
// int64_t (undefined behaviour); sizes whose product overflows 64 bits must not wrap
// to a small count. Every crease array file (.crig, .cdm, .ctrk, .cpr, .cfr) reads
// its header the same way (core/array_file.cc).
TEST(FaceRig, ArrayShapesAreCheckedIntegersWithinTheFile) {
  const fs::path dir = ::crease::testing::TestDir();
  WriteRig(dir / "good.crig", SmallRig());
  const std::string bytes = ReadFileToString(dir / "good.crig");
  auto with_shape = [&](const std::string& name, const std::string& dims) {
    const std::string b = ::crease::testing::EditArrayFileHeader(bytes, [&](std::string h) {
      const size_t shape = h.find("\"shape\":[");
      EXPECT_NE(shape, std::string::npos) << h;
      const size_t open = shape + 9;
      return h.replace(open, h.find(']', open) - open, dims);
    });
    ::crease::testing::WriteText(dir / name, b);
    return ErrorOf([&] { ReadRig(dir / name); });
  };
  const std::string float_error = with_shape("float.crig", "1e72,3");
  EXPECT_NE(float_error.find("float.crig: array"), std::string::npos);
  EXPECT_NE(float_error.find("not an integer"), std::string::npos);
  EXPECT_NE(with_shape("wrap.crig", "17179869183,17179869183,17179869183,17179869183").find("needs more than the"),
            std::string::npos);
  EXPECT_NE(with_shape("negative.crig", "-1,3").find("invalid shape"), std::string::npos);
}

TEST(FaceRig, CompactFileKeepsDeltasWithinHalfAStep) {
  FaceRig rig = SmallRig();
  rig.expression_basis.col(1).setZero();  // a sparse shape, as most expressions are
  rig.identity_basis *= 20.0f;            // ±20 mm
  const fs::path dir = TestDir();
  WriteRig(dir / "raw.crig", rig);
  RigWriteOptions compact;
  compact.compact = true;
  WriteRig(dir / "compact.crig", rig, compact);
  const FaceRig back = ReadRig(dir / "compact.crig");
  EXPECT_EQ(back.neutral.V, rig.neutral.V);
  EXPECT_EQ(back.neutral.F, rig.neutral.F);
  EXPECT_EQ(back.neutral.UV, rig.neutral.UV);
  EXPECT_EQ(back.vertex_part, rig.vertex_part);
  EXPECT_LE((back.identity_basis - rig.identity_basis).cwiseAbs().maxCoeff(), 0.5 * compact.quantum_mm + 1e-6);
  EXPECT_LE((back.expression_basis - rig.expression_basis).cwiseAbs().maxCoeff(), 0.5 * compact.quantum_mm + 1e-6);
  EXPECT_EQ(back.expression_basis.col(1).cwiseAbs().maxCoeff(), 0.0f);
  EXPECT_LT(fs::file_size(dir / "compact.crig"), fs::file_size(dir / "raw.crig"));
  // Lossless compression keeps every float.
  RigWriteOptions lossless;
  lossless.compress = true;
  WriteRig(dir / "lossless.crig", rig, lossless);
  EXPECT_EQ(ReadRig(dir / "lossless.crig").expression_basis, rig.expression_basis);
  EXPECT_EQ(ReadRig(dir / "lossless.crig").identity_basis, rig.identity_basis);
  // A basis beyond ±32767 steps gets a coarser step instead of overflowing.
  rig.expression_basis(0, 0) = 400.0f;
  WriteRig(dir / "big.crig", rig, compact);
  EXPECT_NEAR(ReadRig(dir / "big.crig").expression_basis(0, 0), 400.0f, 0.01f);

  // Corrupt compressed data is an error naming the file and the array.
  std::string bytes;
  {
    std::ifstream in(dir / "compact.crig", std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  bytes[bytes.size() - 200] ^= 0x55;
  bytes[bytes.size() - 201] ^= 0x55;
  WriteText(dir / "corrupt.crig", bytes);
  EXPECT_ERROR_HAS(ReadRig(dir / "corrupt.crig"), "corrupt.crig: array");
}

TEST(RigImport, VertexRangesAreUnambiguous) {
  VertexRange r = ParseVertexRange("[0, 9408]", "t");
  EXPECT_EQ(r.first, 0);
  EXPECT_EQ(r.end, 9409);
  r = ParseVertexRange("[9409,11248)", "t");
  EXPECT_EQ(r.first, 9409);
  EXPECT_EQ(r.end, 11248);
  EXPECT_ERROR_HAS(ParseVertexRange("0:9409", "--face-vertices"), "--face-vertices: vertex range '0:9409' must be");
  EXPECT_ERROR_HAS(ParseVertexRange("[5, 5)", "t"), "is empty");
  EXPECT_EQ(ParseLandmarkIds("1225, 1888,1052 367").size(), 4u);
  EXPECT_ERROR_HAS(ParseLandmarkIds("12, x"), "unexpected 'x'");
}

TEST(RigImport, MultiPartHeadKeepsEveryPartOnItsOwnUvTile) {
  const fs::path dir = TestDir() / "rig";
  fs::copy(kSampleRig, dir, fs::copy_options::recursive);
  const fs::path parts = dir.parent_path() / "parts.json";
  // The upper 27 rows are the face; the rest a second part; the grid's last row is in no part.
  WriteText(parts, R"J([{"name": "face", "vertices": "[0, 1107)"}, {"name": "neck", "vertices": ["[1107, 2132)"]}])J");
  RigImportOptions opt;
  opt.parts = ReadRigParts(parts);
  // ICT-FaceKit's form of the landmark list: vertex_indices.json's idx_to_landmark_verts.
  const nlohmann::json lms = ReadJsonFile(dir / "landmarks.json");
  WriteText(dir.parent_path() / "vertex_indices.json", nlohmann::json{{"idx_to_landmark_verts", lms}}.dump());
  opt.landmark_ids = ParseLandmarkIds((dir.parent_path() / "vertex_indices.json").string());
  RigImportReport report;
  const FaceRig rig = ImportObjRig(dir, opt, &report);
  ASSERT_EQ(rig.part_names, (std::vector<std::string>{"face", "neck"}));
  EXPECT_EQ(report.dropped_triangles, 2 * 40);  // the polygons touching the last row
  EXPECT_EQ(rig.neutral.num_faces(), 2 * 40 * 51);
  EXPECT_EQ(FaceChartTriangles(rig).rows(), 2 * 40 * 26);
  for (int v = 0; v < rig.num_vertices(); ++v) {
    const bool face = rig.vertex_part[v] == 0;
    EXPECT_EQ(face, rig.original_vertex[v] < 1107);
    if (face) {
      EXPECT_LE(rig.neutral.UV(v, 0), 1.0);
    } else {
      EXPECT_GE(rig.neutral.UV(v, 0), 3.0);  // part 1's tile, u in [3, 4)
      EXPECT_LT(rig.neutral.UV(v, 0), 4.0);
    }
  }
  ASSERT_EQ(rig.landmarks.size(), 68u);
  EXPECT_EQ(rig.original_vertex[rig.landmarks[0].vertex], lms[0].get<int>());
  EXPECT_EQ(report.part_vertices.size(), 2u);

  // A part of it (a face-only tracking rig): the face's vertices, OBJ ids and UVs.
  EXPECT_ERROR_HAS(ExtractParts(rig, {"face"}), "lies in a part that is not kept");
  FaceRig unlabelled = rig;
  unlabelled.landmarks.clear();
  const FaceRig face = ExtractParts(unlabelled, {"face", "no such part"});
  EXPECT_EQ(face.part_names, std::vector<std::string>{"face"});
  EXPECT_EQ(face.neutral.num_faces(), FaceChartTriangles(rig).rows());
  EXPECT_EQ(face.num_identity(), rig.num_identity());
  for (int v = 0; v < face.num_vertices(); ++v) EXPECT_LT(face.original_vertex[v], 1107);
  EXPECT_EQ(ExtractParts(rig, {"neck", "face"}).num_vertices(), rig.num_vertices());
  EXPECT_ERROR_HAS(ExtractParts(rig, {"neck"}), "the part \"face\" must be kept");

  // Bad parts files name the file and the problem.
  WriteText(parts, R"J([{"name": "face", "vertices": "[0, 100]"}, {"name": "neck", "vertices": "[100, 200]"}])J");
  EXPECT_ERROR_HAS(ReadRigParts(parts), "parts 'face' and 'neck' overlap");
  WriteText(parts, R"J([{"name": "neck", "vertices": "[0, 100]"}])J");
  EXPECT_ERROR_HAS(ReadRigParts(parts), "no part is named \"face\"");
  WriteText(parts, R"J([{"name": "face", "vertices": "[0, 100]", "colour": 1}])J");
  EXPECT_ERROR_HAS(ReadRigParts(parts), "unknown key 'colour'");
  WriteText(parts, R"J([{"name": "face", "vertices": "0:100"}])J");
  EXPECT_ERROR_HAS(ReadRigParts(parts), "parts.json: part 0 ('face'): vertex range '0:100'");
  WriteText(parts, R"J([{"name": "face", "vertices": "[0, 99999]"}])J");
  opt.parts = ReadRigParts(parts);
  EXPECT_ERROR_HAS(ImportObjRig(dir, opt), "exceeds the 2173 vertices");
}

TEST(RigImport, SampleObjFolder) {
  RigImportOptions opt;
  opt.units_to_mm = UnitsToMm("cm");
  RigImportReport report;
  const FaceRig rig = ImportObjRig(kSampleRig, opt, &report);
  // 41 × 53 grid positions; the centre column (53 vertices) carries two UVs.
  EXPECT_EQ(report.original_vertices, 41 * 53);
  EXPECT_EQ(report.split_vertices, 53);
  EXPECT_EQ(rig.num_vertices(), 41 * 53 + 53);
  EXPECT_EQ(rig.neutral.num_faces(), 2 * 40 * 52);  // quads triangulated
  EXPECT_EQ(rig.num_identity(), 4);
  EXPECT_EQ(rig.num_expressions(), 7);
  EXPECT_EQ(rig.expression_names.front(), "browDown");  // sorted by name
  EXPECT_EQ(rig.landmarks.size(), 68u);
  EXPECT_EQ(rig.regions.size(), StandardRegionNames().size());
  // Centimetres became millimetres: the mask is 15 cm wide.
  const auto [lo, hi] = BoundingBox(rig.neutral);
  EXPECT_NEAR(hi.x() - lo.x(), 150.0, 1e-3);
  // UVs were flipped to crease's v-down convention: the forehead (head +y) has small v.
  const int top = rig.landmarks[rig.LandmarkIndex("ibug_20")].vertex;
  const int chin = rig.landmarks[rig.LandmarkIndex("ibug_9")].vertex;
  EXPECT_LT(rig.neutral.UV(top, 1), rig.neutral.UV(chin, 1));
  // jawOpen moves the chin down (−y) and leaves the forehead alone.
  const int jaw = rig.ExpressionIndex("jawOpen");
  EXPECT_LT(rig.expression_basis(3 * chin + 1, jaw), -5.0);
  EXPECT_NEAR(rig.expression_basis(3 * top + 1, jaw), 0.0, 1e-3);
  // Every seam-split vertex maps back to one OBJ id and sits where its twin does.
  std::map<int, int> first;
  for (int v = 0; v < rig.num_vertices(); ++v) {
    auto [it, inserted] = first.emplace(rig.original_vertex[v], v);
    if (!inserted) {
      EXPECT_EQ(rig.neutral.V.row(v), rig.neutral.V.row(it->second));
    }
  }
  // Regions are non-empty and where they belong.
  for (const auto& r : rig.regions) EXPECT_GT(cv::countNonZero(r.mask), 100) << r.name;
  const Eigen::Vector2d forehead_uv = rig.neutral.UV.row(top).transpose() + Eigen::Vector2d(0, -0.06);
  EXPECT_TRUE(rig.InRegion("forehead", forehead_uv));
  EXPECT_FALSE(rig.InRegion("chin", forehead_uv));
}

TEST(RigImport, FaceRangeCropsAndErrorsNameTheFile) {
  const fs::path dir = ::crease::testing::TestDir() / "crease_rig_import";
  fs::copy(kSampleRig, dir, fs::copy_options::recursive);
  RigImportOptions opt;
  opt.face_last = 41 * 27;  // the upper 27 rows of vertices
  // Landmarks below the face region are an error naming landmarks.json.
  EXPECT_NE(ErrorOf([&] { ImportObjRig(dir, opt); }).find("landmarks.json: landmark"), std::string::npos);
  fs::remove(dir / "landmarks.json");
  RigImportReport report;
  const FaceRig rig = ImportObjRig(dir, opt, &report);
  EXPECT_EQ(rig.neutral.num_faces(), 2 * 40 * 26);
  EXPECT_EQ(report.dropped_triangles, 2 * 40 * 26);
  for (int id : rig.original_vertex) EXPECT_LT(id, 41 * 27);
  EXPECT_TRUE(rig.landmarks.empty());
  EXPECT_TRUE(rig.regions.empty());
  EXPECT_EQ(report.warnings.size(), 2u);

  // A shape with another topology is named.
  {
    std::ofstream out(dir / "expressions" / "jawOpen.obj", std::ios::app);
    out << "f 1/1 2/2 3/3\n";
  }
  EXPECT_NE(ErrorOf([&] { ImportObjRig(dir, opt); }).find("jawOpen.obj: topology differs"), std::string::npos);
  fs::remove(dir / "neutral.obj");
  EXPECT_NE(ErrorOf([&] { ImportObjRig(dir, opt); }).find("no neutral shape found"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { ImportObjRig(dir / "nothing", opt); }).find("not a folder"), std::string::npos);
  opt.face_last = 999999;
  fs::copy_file(kSampleRig / "neutral.obj", dir / "neutral.obj");
  EXPECT_NE(ErrorOf([&] { ImportObjRig(dir, opt); }).find("exceeds"), std::string::npos);
  EXPECT_THROW(UnitsToMm("inch"), Error);
}

}  // namespace
}  // namespace crease
