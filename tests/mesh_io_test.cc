#include "core/mesh_io.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_primitives.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::TestDir;
using testing::WriteText;

namespace fs = std::filesystem;





void ExpectSameMesh(const TriMesh& a, const TriMesh& b) {
  ASSERT_EQ(a.V.rows(), b.V.rows());
  ASSERT_EQ(a.F.rows(), b.F.rows());
  ASSERT_EQ(a.UV.rows(), b.UV.rows());
  ASSERT_EQ(a.N.rows(), b.N.rows());
  EXPECT_TRUE(a.V == b.V);
  EXPECT_TRUE(a.F == b.F);
  EXPECT_TRUE(a.UV == b.UV);
  EXPECT_TRUE(a.N == b.N);
}

// Mesh with values that need all 17 digits.
TriMesh TestSphere() {
  TriMesh m = MakeUVSphere(10.0 / 3.0, 6, 9);
  m.V.array() += 1e-13;
  m.UV.array() *= 1.0 / 7.0;
  return m;
}

// ---------------------------------------------------------------------------
// PLY
// ---------------------------------------------------------------------------

TEST(Ply, BinaryRoundTripIsExact) {
  const fs::path file = TestDir() / "sphere.ply";
  const TriMesh m = TestSphere();
  WritePly(file, m);
  ExpectSameMesh(ReadPly(file), m);
}

TEST(Ply, AsciiRoundTripIsExact) {
  const fs::path file = TestDir() / "sphere_ascii.ply";
  const TriMesh m = TestSphere();
  WritePly(file, m, {.binary = false});
  const std::string text = ReadFileToString(file);
  EXPECT_NE(text.find("format ascii 1.0"), std::string::npos);
  ExpectSameMesh(ReadPly(file), m);
}

TEST(Ply, FloatRoundTripIsWithinFloatPrecision) {
  const fs::path dir = TestDir();
  const TriMesh m = TestSphere();
  for (const bool binary : {true, false}) {
    const fs::path file = dir / (binary ? "float_bin.ply" : "float_ascii.ply");
    WritePly(file, m, {.binary = binary, .double_precision = false});
    const TriMesh r = ReadPly(file);
    ASSERT_EQ(r.V.rows(), m.V.rows());
    EXPECT_TRUE(r.F == m.F);
    const double eps = std::numeric_limits<float>::epsilon();
    EXPECT_LE((r.V - m.V).cwiseAbs().maxCoeff(), eps * m.V.cwiseAbs().maxCoeff());
    EXPECT_LE((r.UV - m.UV).cwiseAbs().maxCoeff(), eps);
    EXPECT_LE((r.N - m.N).cwiseAbs().maxCoeff(), eps);
    EXPECT_GT((r.V - m.V).cwiseAbs().maxCoeff(), 0.0);  // really float
  }
}

TEST(Ply, MeshWithoutUVOrNormalsRoundTrips) {
  const fs::path file = TestDir() / "bare.ply";
  TriMesh m = MakeGrid(3, 2, 3.0, 2.0);
  m.UV.resize(0, 2);
  m.N.resize(0, 3);
  WritePly(file, m);
  const std::string text = ReadFileToString(file);
  EXPECT_EQ(text.find("property double u"), std::string::npos);
  EXPECT_EQ(text.find("property double nx"), std::string::npos);
  ExpectSameMesh(ReadPly(file), m);
}

template <class T>
void AppendBigEndian(std::string* out, T value) {
  char b[sizeof(T)];
  std::memcpy(b, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::little) std::reverse(b, b + sizeof(T));
  out->append(b, sizeof(T));
}

TEST(Ply, ReadsBigEndianWithUnknownPropertiesAndElements) {
  // A unit square as one quad plus a triangle, float positions, an unknown uchar
  // colour, s/t texture coordinates, a short list per vertex, an unknown element
  // between vertices and faces, and ushort-counted uint indices.
  std::string ply =
      "ply\n"
      "format binary_big_endian 1.0\n"
      "comment hand-written\n"
      "element vertex 5\n"
      "property float x\n"
      "property float y\n"
      "property float z\n"
      "property uchar red\n"
      "property double s\n"
      "property double t\n"
      "property list uchar short tags\n"
      "element material 2\n"
      "property int id\n"
      "property list uint double weights\n"
      "element face 2\n"
      "property uchar flags\n"
      "property list ushort uint vertex_index\n"
      "property float quality\n"
      "end_header\n";
  const float xyz[5][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {2, 0.5f, 0}};
  for (int i = 0; i < 5; ++i) {
    for (float c : xyz[i]) AppendBigEndian(&ply, c);
    AppendBigEndian(&ply, static_cast<uint8_t>(200 + i));
    AppendBigEndian(&ply, 0.25 * i);
    AppendBigEndian(&ply, 1.0 - 0.25 * i);
    AppendBigEndian(&ply, static_cast<uint8_t>(i % 3));
    for (int k = 0; k < i % 3; ++k) AppendBigEndian(&ply, static_cast<int16_t>(-k));
  }
  for (int m = 0; m < 2; ++m) {
    AppendBigEndian(&ply, static_cast<int32_t>(m));
    AppendBigEndian(&ply, static_cast<uint32_t>(m + 1));
    for (int k = 0; k <= m; ++k) AppendBigEndian(&ply, 0.5);
  }
  AppendBigEndian(&ply, static_cast<uint8_t>(7));
  AppendBigEndian(&ply, static_cast<uint16_t>(4));
  for (uint32_t v : {0u, 1u, 2u, 3u}) AppendBigEndian(&ply, v);
  AppendBigEndian(&ply, 0.5f);
  AppendBigEndian(&ply, static_cast<uint8_t>(8));
  AppendBigEndian(&ply, static_cast<uint16_t>(3));
  for (uint32_t v : {1u, 4u, 2u}) AppendBigEndian(&ply, v);
  AppendBigEndian(&ply, 0.75f);

  const fs::path file = TestDir() / "big.ply";
  WriteText(file, ply);
  const TriMesh m = ReadPly(file);
  ASSERT_EQ(m.num_vertices(), 5);
  ASSERT_EQ(m.num_faces(), 3);  // quad fan (2) + triangle
  for (int i = 0; i < 5; ++i) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(m.V(i, k), xyz[i][k]);
    EXPECT_EQ(m.UV(i, 0), 0.25 * i);
    EXPECT_EQ(m.UV(i, 1), 1.0 - 0.25 * i);
  }
  EXPECT_FALSE(m.has_normals());
  EXPECT_EQ(m.F.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(m.F.row(2), Eigen::RowVector3i(1, 4, 2));
}

TEST(Ply, AsciiWithExtrasAndQuads) {
  const fs::path file = TestDir() / "quads.ply";
  WriteText(file,
            "ply\r\n"
            "format ascii 1.0\r\n"
            "element vertex 6\r\n"
            "property double x\r\nproperty double y\r\nproperty double z\r\n"
            "property float confidence\r\n"
            "property float texture_u\r\nproperty float texture_v\r\n"
            "element face 2\r\n"
            "property list uchar int vertex_indices\r\n"
            "property list uchar float extra\r\n"
            "element edge 1\r\n"
            "property int vertex1\r\nproperty int vertex2\r\n"
            "end_header\r\n"
            "0 0 0 0.9 0 0\r\n1 0 0 0.9 0.5 0\r\n2 0 0 1 1 0\r\n"
            "0 1 0 1 0 1\r\n1 1 0 1 0.5 1\r\n2 1 0 1 1 1\r\n"
            "4 0 1 4 3 2 0.5 0.25\r\n4 1 2 5 4 0\r\n"
            "0 1\r\n");
  const TriMesh m = ReadPly(file);
  EXPECT_EQ(m.num_vertices(), 6);
  ASSERT_EQ(m.num_faces(), 4);
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 4, 3));
  EXPECT_EQ(m.F.row(3), Eigen::RowVector3i(1, 5, 4));
  EXPECT_EQ(m.UV(4, 0), 0.5);
  EXPECT_EQ(m.UV(4, 1), 1.0);
}

TEST(Ply, MalformedFilesNameFileAndProblem) {
  const fs::path dir = TestDir();
  const TriMesh m = MakeGrid(2, 2, 1.0, 1.0);

  const fs::path missing = dir / "missing.ply";
  EXPECT_ERROR_HAS(ReadPly(missing), missing.string() + ": file does not exist");

  const fs::path magic = dir / "magic.ply";
  WriteText(magic, "solid cube\nfacet normal 0 0 1\n");
  EXPECT_ERROR_HAS(ReadPly(magic), magic.string() + ": not a PLY file");

  const fs::path format = dir / "format.ply";
  WriteText(format, "ply\nformat binary_middle_endian 1.0\nelement vertex 0\nend_header\n");
  EXPECT_ERROR_HAS(ReadPly(format), format.string() + ":2: unsupported PLY format 'binary_middle_endian'");

  const fs::path header = dir / "header.ply";
  WriteText(header, "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n0\n");
  EXPECT_ERROR_HAS(ReadPly(header), header.string() + ":4: unknown property type 'quad'");

  const fs::path no_end = dir / "no_end.ply";
  WriteText(no_end, "ply\nformat ascii 1.0\nelement vertex 1\n");
  EXPECT_ERROR_HAS(ReadPly(no_end), no_end.string() + ": PLY header has no 'end_header'");

  const fs::path truncated = dir / "truncated.ply";
  WritePly(truncated, m);
  std::string bytes = ReadFileToString(truncated);
  WriteText(truncated, bytes.substr(0, bytes.size() - 7));
  EXPECT_ERROR_HAS(ReadPly(truncated), truncated.string() + ": data ends early");
  EXPECT_ERROR_HAS(ReadPly(truncated), "element 'face'");
  // Cut inside the vertices: caught by the size check before any allocation.
  WriteText(truncated, bytes.substr(0, bytes.find("end_header") + 20));
  EXPECT_ERROR_HAS(ReadPly(truncated), "element 'vertex' declares 9 entries");

  const fs::path ascii_bad = dir / "ascii_bad.ply";
  WriteText(ascii_bad, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                       "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                       "end_header\n0 0 0\n1 0 zero\n0 1 0\n3 0 1 2\n");
  EXPECT_ERROR_HAS(ReadPly(ascii_bad), ascii_bad.string() + ":11: bad number 'zero'");

  const fs::path range = dir / "range.ply";
  WriteText(range, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                   "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                   "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  EXPECT_ERROR_HAS(ReadPly(range), range.string() + ": face 0 references vertex 3, but the file has 3 vertices");

  const fs::path nan = dir / "nan.ply";
  WriteText(nan, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                 "end_header\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n");
  EXPECT_ERROR_HAS(ReadPly(nan), nan.string() + ": vertex 1 has a non-finite coordinate");

  const fs::path no_z = dir / "no_z.ply";
  WriteText(no_z, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                      "end_header\n0 0\n");
  EXPECT_ERROR_HAS(ReadPly(no_z), no_z.string() + ": element 'vertex' has no property 'z'");
}

TEST(Ply, FailedWriteLeavesNoFileAndKeepsTheOldOne) {
  const fs::path dir = TestDir();
  TriMesh bad = MakeGrid(2, 2, 1.0, 1.0);
  bad.V(4, 1) = std::numeric_limits<double>::quiet_NaN();
  const fs::path fresh = dir / "fresh.ply";
  EXPECT_ERROR_HAS(WritePly(fresh, bad), fresh.string() + ": vertex 4 has a non-finite coordinate");
  EXPECT_FALSE(fs::exists(fresh));

  const fs::path existing = dir / "existing.obj";
  const TriMesh good = MakeGrid(1, 1, 1.0, 1.0);
  WriteObj(existing, good);
  const std::string before = ReadFileToString(existing);
  EXPECT_THROW(WriteObj(existing, bad), Error);
  EXPECT_EQ(ReadFileToString(existing), before);
  int files = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1);  // no temporaries left behind
}

// ---------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------

TEST(Obj, RoundTripIsExact) {
  const fs::path dir = TestDir();
  TriMesh m = MakeGrid(4, 3, 10.0 / 3.0, 1.0 / 7.0);
  m.V.col(2).setConstant(0.1 + 0.2);
  const fs::path file = dir / "grid.obj";
  WriteObj(file, m);
  TriMesh r = ReadObj(file);
  EXPECT_FALSE(r.has_normals());  // vn are written for viewers but not read
  r.N = m.N;
  ExpectSameMesh(r, m);

  // Without UVs and normals: plain "f a b c".
  m.UV.resize(0, 2);
  m.N.resize(0, 3);
  WriteObj(file, m);
  EXPECT_NE(ReadFileToString(file).find("\nf 1 2 7\n"), std::string::npos);
  ExpectSameMesh(ReadObj(file), m);
}

TEST(Obj, SphereDropsUnusedVerticesAndMapsBack) {
  const fs::path file = TestDir() / "sphere.obj";
  const TriMesh m = TestSphere();
  WriteObj(file, m);
  const PolygonMesh shape = ReadObjPolygons(file);
  EXPECT_EQ(shape.positions.rows(), m.num_vertices());
  const TriangulatedMesh split = TriangulateAndSplitSeams(shape, file.string());
  EXPECT_EQ(split.mesh.num_vertices(), m.num_vertices() - 2);  // one unused vertex per pole
  for (int i = 0; i < split.mesh.num_vertices(); ++i) {
    EXPECT_TRUE(split.mesh.V.row(i) == m.V.row(split.original_vertex[i]));
    EXPECT_TRUE(split.mesh.UV.row(i) == m.UV.row(split.original_vertex[i]));
  }
  for (int f = 0; f < m.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(split.original_vertex[split.mesh.F(f, k)], m.F(f, k));
  }
}

// Two quads sharing the edge 1-4 (positions), with different UVs on each side:
//   0 --- 1 --- 2          vt 0 1 | 2 3   (left quad uses vt 0..3, right quad 4..7)
//   |  A  |  B  |
//   3 --- 4 --- 5
const char* kTwoQuads =
    "# two quads\n"
    "mtllib x.mtl\n"
    "o patch\n"
    "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\n"
    "vt 0 0\nvt 0.5 0\nvt 0 1\nvt 0.5 1\n"
    "vt 0.6 0\nvt 1 0\nvt 0.6 1\nvt 1 1\n"
    "vn 0 0 1\n"
    "g left\nusemtl skin\ns 1\n"
    "f 1/1/1 4/3/1 5/4/1 2/2/1\n"
    "f -5/-4/-1 -2/-2/-1 -1/-1/-1 -4/-3/-1   # relative: 2/5 5/7 6/8 3/6\n";

TEST(Obj, SeamSplittingKeepsRangesContiguous) {
  const fs::path file = TestDir() / "two_quads.obj";
  WriteText(file, kTwoQuads);
  const PolygonMesh shape = ReadObjPolygons(file);
  ASSERT_EQ(shape.num_faces(), 2);
  EXPECT_EQ(shape.positions.rows(), 6);
  EXPECT_EQ(shape.uvs.rows(), 8);
  EXPECT_EQ(shape.corner_position, (std::vector<int>{0, 3, 4, 1, 1, 4, 5, 2}));
  EXPECT_EQ(shape.corner_uv, (std::vector<int>{0, 2, 3, 1, 4, 6, 7, 5}));

  const TriangulatedMesh split = TriangulateAndSplitSeams(shape, file.string());
  const TriMesh& m = split.mesh;
  EXPECT_EQ(m.num_vertices(), 8);  // positions 1 and 4 are split
  EXPECT_EQ(m.num_faces(), 4);
  EXPECT_EQ(split.original_vertex, (std::vector<int>{0, 1, 1, 2, 3, 4, 4, 5}));
  EXPECT_TRUE(std::is_sorted(split.original_vertex.begin(), split.original_vertex.end()));
  // First appearance: position 1 is first used by the left quad (vt 2 -> u 0.5).
  EXPECT_EQ(m.UV(1, 0), 0.5);
  EXPECT_EQ(m.UV(2, 0), 0.6);
  // Fan from the first corner: left quad (0 3 4 1) -> (0 3 4), (0 4 1).
  EXPECT_EQ(m.F.row(0), Eigen::RowVector3i(0, 4, 5));
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 5, 1));
  EXPECT_EQ(m.F.row(2), Eigen::RowVector3i(2, 6, 7));
  EXPECT_EQ(m.F.row(3), Eigen::RowVector3i(2, 7, 3));
  EXPECT_NO_THROW(ValidateMesh(m, "split", {.uv = true}));
  EXPECT_EQ(ComputeEdgeStats(m).boundary, 8);  // the seam is now a boundary on both sides

  // A blendshape of the same topology maps through the neutral's split.
  std::string moved = kTwoQuads;
  moved.replace(moved.find("v 2 1 0"), 7, "v 2 1 5");
  const fs::path file2 = file.parent_path() / "two_quads_moved.obj";
  WriteText(file2, moved);
  const PolygonMesh shape2 = ReadObjPolygons(file2);
  EXPECT_TRUE(SameTopology(shape, shape2));
  const MatX3d V2 = GatherPositions(shape2, split.original_vertex);
  EXPECT_EQ(V2(7, 2), 5.0);
  EXPECT_EQ((V2 - m.V).cwiseAbs().sum(), 5.0);

  PolygonMesh other = shape2;
  other.corner_uv[0] = 1;
  EXPECT_FALSE(SameTopology(shape, other));
  EXPECT_THROW(GatherPositions(shape, {0, 6}), Error);
}

// Unit cube with 6 quads; `with_uv`: each face has its own 4 texture coordinates.
std::string CubeObj(bool with_uv) {
  std::ostringstream obj;
  for (int i = 0; i < 8; ++i) obj << "v " << (i & 1) << " " << ((i >> 1) & 1) << " " << ((i >> 2) & 1) << "\n";
  const int faces[6][4] = {{1, 3, 4, 2}, {5, 6, 8, 7}, {1, 2, 6, 5},
                           {3, 7, 8, 4}, {1, 5, 7, 3}, {2, 4, 8, 6}};
  // Each face on a UV tile of its own (u in [f, f + 1]), so every corner is a seam.
  for (int f = 0; f < 6 && with_uv; ++f) {
    obj << "vt " << f << " 0\nvt " << f + 1 << " 0\nvt " << f + 1 << " 1\nvt " << f << " 1\n";
  }
  for (int f = 0; f < 6; ++f) {
    obj << "f";
    for (int k = 0; k < 4; ++k) {
      obj << " " << faces[f][k];
      if (with_uv) obj << "/" << 4 * f + k + 1;
    }
    obj << "\n";
  }
  return obj.str();
}

TEST(Obj, CubeSeamsSplitEveryCorner) {
  const fs::path dir = TestDir();
  const fs::path with_uv = dir / "cube_uv.obj";
  WriteText(with_uv, CubeObj(true));
  const PolygonMesh shape = ReadObjPolygons(with_uv);
  const TriangulatedMesh split = TriangulateAndSplitSeams(shape, with_uv.string());
  EXPECT_EQ(split.mesh.num_vertices(), 24);
  EXPECT_EQ(split.mesh.num_faces(), 12);
  for (int v = 0; v < 24; ++v) EXPECT_EQ(split.original_vertex[v], v / 3);
  // Positions 2..5 map to the contiguous output range [6, 18).
  const auto first = std::lower_bound(split.original_vertex.begin(), split.original_vertex.end(), 2);
  const auto last = std::upper_bound(split.original_vertex.begin(), split.original_vertex.end(), 5);
  EXPECT_EQ(first - split.original_vertex.begin(), 6);
  EXPECT_EQ(last - split.original_vertex.begin(), 18);
  EXPECT_EQ(ComputeEdgeStats(split.mesh).boundary, 24);

  const fs::path no_uv = dir / "cube.obj";
  WriteText(no_uv, CubeObj(false));
  const TriMesh cube = ReadObj(no_uv);
  EXPECT_EQ(cube.num_vertices(), 8);
  EXPECT_EQ(cube.num_faces(), 12);
  EXPECT_FALSE(cube.has_uv());
  const EdgeStats stats = ComputeEdgeStats(cube);
  EXPECT_EQ(stats.boundary, 0);
  EXPECT_EQ(stats.non_manifold, 0);
  EXPECT_NEAR(TriangleAreas(cube).sum(), 6.0, 1e-12);
}

TEST(Obj, RepeatedTextureCoordinatesAreNotASeam) {
  // Two triangles sharing an edge whose "vt" lines repeat the same coordinates
  // under new indices (as exporters write them): one chart, no split.
  const fs::path path = TestDir() / "repeated_vt.obj";
  WriteText(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                  "vt 0 0\nvt 1 0\nvt 0 1\nvt 1 0\nvt 1 1\nvt 0 1\n"
                  "f 1/1 2/2 3/3\nf 2/4 4/5 3/6\n");
  const TriangulatedMesh split = TriangulateAndSplitSeams(ReadObjPolygons(path), path.string());
  EXPECT_EQ(split.mesh.num_vertices(), 4);
  EXPECT_EQ(ComputeEdgeStats(split.mesh).boundary, 4);
}

TEST(Obj, MalformedFilesNameFileLineAndProblem) {
  const fs::path dir = TestDir();
  const fs::path missing = dir / "missing.obj";
  EXPECT_ERROR_HAS(ReadObj(missing), missing.string() + ": file does not exist");

  struct Case {
    const char* text;
    const char* expected;  // after "<file>:"
  };
  const Case cases[] = {
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "4: position index 4 out of range: the file has 3 'v' lines"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", "4: relative position index -4 out of range"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "4: position index 0 in face (OBJ indices start at 1)"},
      {"v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "2: non-finite coordinate 'nan' in 'v'"},
      {"v 0 0 0\nv 1 0x 0\n", "2: bad number '0x' in 'v'"},
      {"v 0 0\n", "1: 'v' needs 3 coordinates"},
      {"v 0 0 0\nv 1 0 0\nf 1 2\n", "3: face has 2 corners, needs at least 3"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 1\n", "4: face uses vertex 1 twice"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3\n",
       "5: face mixes corners with and without texture coordinates"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 2 4 3\n",
       "7: face has no texture coordinates, but the face on line 6 has them"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/2 2/1 3/1\n",
       "5: texture coordinate index 2 out of range: the file has 1 'vt' lines"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", "4: bad face corner '1/1/1/1'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2/1 3/1\n", "4: bad texture coordinate index 'x' in face"},
      {"cstype bspline\n", "1: free-form geometry ('cstype') is not supported"},
      {"vx 1 2 3\n", "1: unknown statement 'vx'"},
  };
  int n = 0;
  for (const Case& c : cases) {
    const fs::path file = dir / ("bad" + std::to_string(n++) + ".obj");
    WriteText(file, c.text);
    EXPECT_ERROR_HAS(ReadObj(file), file.string() + ":" + c.expected);
  }
  // Valid file with forward references (faces before vertices) is accepted.
  const fs::path forward = dir / "forward.obj";
  WriteText(forward, "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
  EXPECT_EQ(ReadObj(forward).num_faces(), 1);
  // An empty file has no triangles.
  const fs::path empty = dir / "empty.obj";
  WriteText(empty, "# nothing\n");
  EXPECT_ERROR_HAS(ReadObj(empty), empty.string() + ": mesh has no triangles");
}

TEST(Obj, TriangulateRejectsInconsistentPolygons) {
  PolygonMesh shape;
  shape.positions = MatX3d::Zero(3, 3);
  shape.corner_position = {0, 1, 2};
  shape.face_offsets = {0, 3};
  EXPECT_EQ(TriangulateAndSplitSeams(shape, "shape").mesh.num_faces(), 1);
  shape.corner_position = {0, 1, 3};
  EXPECT_ERROR_HAS(TriangulateAndSplitSeams(shape, "shape"), "shape: corner 2 references position 3");
  shape.corner_position = {0, 1, 2};
  shape.face_offsets = {0, 2, 3};
  EXPECT_ERROR_HAS(TriangulateAndSplitSeams(shape, "shape"), "shape: face 0 has 2 corners");
  shape.face_offsets = {0, 3};
  shape.corner_uv = {0, 0};
  EXPECT_ERROR_HAS(TriangulateAndSplitSeams(shape, "shape"), "shape: 2 corner UV indices for 3 corners");
}

// ---------------------------------------------------------------------------
// Dispatch
// ---------------------------------------------------------------------------

TEST(MeshIo, DispatchOnExtension) {
  const fs::path dir = TestDir();
  const TriMesh m = MakeGrid(2, 2, 2.0, 2.0);
  for (const char* name : {"a.ply", "b.OBJ"}) {
    WriteMesh(dir / name, m);
    TriMesh r = ReadMesh(dir / name);
    if (!r.has_normals()) r.N = m.N;
    ExpectSameMesh(r, m);
  }
  EXPECT_NE(ReadFileToString(dir / "a.ply").find("binary_little_endian"), std::string::npos);
  const fs::path stl = dir / "c.stl";
  EXPECT_ERROR_HAS(WriteMesh(stl, m), stl.string() + ": unsupported mesh file extension '.stl'");
  EXPECT_ERROR_HAS(ReadMesh(stl), "supported: .ply, .obj; .vtp is handled by core/vtk_io.h");
  EXPECT_FALSE(fs::exists(stl));
}

}  // namespace
}  // namespace crease
