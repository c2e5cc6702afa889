#include "core/face_rig.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <set>
#include <fmt/format.h>
#include <zlib.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/array_file.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/options.h"

namespace crease {
namespace fs = std::filesystem;
using nlohmann::json;

const std::vector<std::string>& StandardRegionNames() {
  static const std::vector<std::string> names = {"forehead",    "glabella",   "left_eye",
                                                 "right_eye",   "left_cheek", "right_cheek",
                                                 "nose",        "mouth",      "chin"};
  return names;
}

std::vector<std::string> IbugLandmarkNames() {
  std::vector<std::string> names;
  for (int i = 1; i <= 68; ++i) names.push_back(fmt::format("ibug_{}", i));
  return names;
}

MatX3d FaceRig::EvaluatePositions(const Eigen::VectorXd& identity,
                                  const Eigen::VectorXd& expression) const {
  Require(identity.size() <= num_identity(),
          fmt::format("FaceRig::Evaluate: {} identity coefficients given, the rig has {}",
                      identity.size(), num_identity()));
  Require(expression.size() <= num_expressions(),
          fmt::format("FaceRig::Evaluate: {} expression weights given, the rig has {}",
                      expression.size(), num_expressions()));
  Eigen::VectorXd flat = Eigen::Map<const Eigen::VectorXd>(neutral.V.data(), neutral.V.size());
  if (identity.size() > 0) {
    flat += identity_basis.leftCols(identity.size()).cast<double>() * identity;
  }
  if (expression.size() > 0) {
    flat += expression_basis.leftCols(expression.size()).cast<double>() * expression;
  }
  MatX3d V(num_vertices(), 3);
  Eigen::Map<Eigen::VectorXd>(V.data(), V.size()) = flat;
  return V;
}

TriMesh FaceRig::Evaluate(const Eigen::VectorXd& identity, const Eigen::VectorXd& expression) const {
  TriMesh m;
  m.V = EvaluatePositions(identity, expression);
  m.F = neutral.F;
  m.UV = neutral.UV;
  return m;
}

int FaceRig::ExpressionIndex(const std::string& name) const {
  auto it = std::find(expression_names.begin(), expression_names.end(), name);
  return it == expression_names.end() ? -1 : static_cast<int>(it - expression_names.begin());
}

int FaceRig::PartIndex(const std::string& name) const {
  auto it = std::find(part_names.begin(), part_names.end(), name);
  return it == part_names.end() ? -1 : static_cast<int>(it - part_names.begin());
}

int FaceRig::LandmarkIndex(const std::string& name) const {
  for (size_t i = 0; i < landmarks.size(); ++i) {
    if (landmarks[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

const RegionMask* FaceRig::FindRegion(const std::string& name) const {
  for (const auto& r : regions) {
    if (r.name == name) return &r;
  }
  return nullptr;
}

bool FaceRig::InRegion(const std::string& name, const Eigen::Vector2d& uv) const {
  const RegionMask* r = FindRegion(name);
  if (!r || !(uv.x() >= 0 && uv.x() < 1 && uv.y() >= 0 && uv.y() < 1)) return false;
  const int i = static_cast<int>(uv.x() * r->mask.cols), j = static_cast<int>(uv.y() * r->mask.rows);
  return r->mask.at<uint8_t>(j, i) != 0;
}

void FaceRig::Validate(const std::string& what) const {
  ValidateMesh(neutral, what + " (neutral mesh)", {.uv = true});
  const Eigen::Index rows = 3 * static_cast<Eigen::Index>(num_vertices());
  Require(identity_basis.cols() == 0 || identity_basis.rows() == rows,
          fmt::format("{}: identity basis has {} rows, expected 3 x {} vertices = {}", what,
                      identity_basis.rows(), num_vertices(), rows));
  Require(expression_basis.cols() == 0 || expression_basis.rows() == rows,
          fmt::format("{}: expression basis has {} rows, expected 3 x {} vertices = {}", what,
                      expression_basis.rows(), num_vertices(), rows));
  Require(identity_basis.allFinite(), fmt::format("{}: identity basis has non-finite values", what));
  Require(expression_basis.allFinite(), fmt::format("{}: expression basis has non-finite values", what));
  Require(static_cast<int>(identity_names.size()) == num_identity(),
          fmt::format("{}: {} identity names for {} identity modes", what, identity_names.size(), num_identity()));
  Require(static_cast<int>(expression_names.size()) == num_expressions(),
          fmt::format("{}: {} expression names for {} expressions", what, expression_names.size(),
                      num_expressions()));
  auto unique = [&](const std::vector<std::string>& names, const char* kind) {
    std::set<std::string> seen;
    for (const auto& n : names) {
      Require(!n.empty(), fmt::format("{}: an {} name is empty", what, kind));
      Require(seen.insert(n).second, fmt::format("{}: {} name '{}' appears twice", what, kind, n));
    }
  };
  unique(identity_names, "identity");
  unique(expression_names, "expression");
  std::vector<std::string> lm_names;
  for (const auto& l : landmarks) {
    lm_names.push_back(l.name);
    Require(l.vertex >= 0 && l.vertex < num_vertices(),
            fmt::format("{}: landmark '{}' references vertex {}, the rig has {} vertices", what,
                        l.name, l.vertex, num_vertices()));
  }
  unique(lm_names, "landmark");
  std::vector<std::string> region_names;
  for (const auto& r : regions) {
    region_names.push_back(r.name);
    Require(!r.mask.empty() && r.mask.type() == CV_8UC1 && r.mask.rows == r.mask.cols,
            fmt::format("{}: region '{}' must be a square 8-bit mask", what, r.name));
  }
  unique(region_names, "region");
  unique(part_names, "part");
  Require(vertex_part.empty() || static_cast<int>(vertex_part.size()) == num_vertices(),
          fmt::format("{}: vertex_part has {} entries for {} vertices", what, vertex_part.size(), num_vertices()));
  for (size_t v = 0; v < vertex_part.size(); ++v) {
    Require(vertex_part[v] < part_names.size(),
            fmt::format("{}: vertex {} is in part {}, but the rig names {} parts", what, v, vertex_part[v],
                        part_names.size()));
  }
  Require(original_vertex.empty() || static_cast<int>(original_vertex.size()) == num_vertices(),
          fmt::format("{}: original_vertex has {} entries for {} vertices", what,
                      original_vertex.size(), num_vertices()));
}

// ---------------------------------------------------------------------------
// .crig I/O

namespace {

// memcpy for arrays that may be empty: an empty Eigen matrix or vector has a null
// data(), and memcpy from or to null is undefined even for 0 bytes (UBSan,
// fuzz/crig_fuzzer, issue 19).
void CopyBytes(void* dst, const char* src, size_t bytes) {
  if (bytes > 0) std::memcpy(dst, src, bytes);
}

constexpr char kMagic[8] = {'C', 'R', 'E', 'A', 'S', 'R', 'I', 'G'};

struct ArrayDesc {
  std::string name, dtype;
  std::vector<int64_t> shape;
  std::string encoding = "raw";  // or "zlib"
  uint64_t stored_bytes = 0;     // bytes in the file (zlib)
  double scale = 1.0;            // i16: value = integer · scale
  size_t element_size() const { return dtype == "f64" ? 8 : dtype == "u8" ? 1 : dtype == "i16" ? 2 : 4; }
  size_t bytes() const {
    size_t n = element_size();
    for (auto s : shape) n *= static_cast<size_t>(s);
    return n;
  }
};

// One array ready to write: its description and its bytes as stored.
struct StoredArray {
  ArrayDesc desc;
  std::string data;
};

template <class T>
std::string RawBytes(const T* data, size_t count) {
  static_assert(std::endian::native == std::endian::little, "crease files are little-endian");
  return std::string(reinterpret_cast<const char*>(data), count * sizeof(T));
}

// A basis (3·#V)×K as 16-bit steps of `quantum` mm (coarser when a delta would
// overflow), column-major like the float layout.
StoredArray QuantizedBasis(const std::string& name, const Eigen::MatrixXf& B, double quantum) {
  const double max_abs = B.size() ? static_cast<double>(B.cwiseAbs().maxCoeff()) : 0.0;
  const double scale = std::max(quantum, max_abs / 32767.0);
  std::vector<int16_t> q(static_cast<size_t>(B.size()));
  for (Eigen::Index i = 0; i < B.size(); ++i) q[i] = static_cast<int16_t>(std::lround(B.data()[i] / scale));
  StoredArray a{{name, "i16", {B.cols(), B.rows()}}, RawBytes(q.data(), q.size())};
  a.desc.scale = scale;
  return a;
}

std::string ZlibCompress(const std::string& raw, const std::string& what) {
  uLongf n = compressBound(static_cast<uLong>(raw.size()));
  std::string out(n, '\0');
  const int rc = compress2(reinterpret_cast<Bytef*>(out.data()), &n, reinterpret_cast<const Bytef*>(raw.data()),
                           static_cast<uLong>(raw.size()), 9);
  Require(rc == Z_OK, fmt::format("{}: zlib compression failed ({})", what, rc));
  out.resize(n);
  return out;
}

// Inflates exactly `expected` bytes. zlib cannot expand more than ~1032×, so a
// declared size beyond that is refused before anything is allocated.
std::string ZlibDecompress(const char* data, size_t stored, size_t expected, const std::string& what) {
  Require(expected <= 1100 * stored + 1024,
          fmt::format("{}: declared size {} bytes cannot come from {} compressed bytes", what, expected, stored));
  std::string out(expected, '\0');
  uLongf n = static_cast<uLongf>(expected);
  const int rc = uncompress(reinterpret_cast<Bytef*>(out.data()), &n, reinterpret_cast<const Bytef*>(data),
                            static_cast<uLong>(stored));
  Require(rc == Z_OK && n == expected, fmt::format("{}: corrupt compressed data (zlib {}, {} of {} bytes)", what, rc,
                                                   static_cast<size_t>(n), expected));
  return out;
}

}  // namespace

void WriteRig(const fs::path& path, const FaceRig& rig, const RigWriteOptions& options) {
  rig.Validate(path.string());
  CheckGt("RigWriteOptions", "quantum_mm", options.quantum_mm, 0.0);
  json header;
  header["format"] = "crease rig";
  header["source"] = rig.source;
  header["units"] = "mm";
  header["identity_names"] = rig.identity_names;
  header["expression_names"] = rig.expression_names;
  json lms = json::array();
  for (const auto& l : rig.landmarks) lms.push_back({{"name", l.name}, {"vertex", l.vertex}});
  header["landmarks"] = lms;
  header["part_names"] = rig.part_names;
  const int nv = rig.num_vertices(), nf = rig.neutral.num_faces();
  // Bases: column-major (3·#V)×K, each mode contiguous, matching the declared shape [K, 3·#V].
  auto float_basis = [&](const std::string& name, const Eigen::MatrixXf& B) {
    return StoredArray{{name, "f32", {B.cols(), 3LL * nv}}, RawBytes(B.data(), static_cast<size_t>(B.size()))};
  };
  std::vector<StoredArray> arrays;
  arrays.push_back({{"V", "f64", {nv, 3}}, RawBytes(rig.neutral.V.data(), rig.neutral.V.size())});
  arrays.push_back({{"F", "i32", {nf, 3}}, RawBytes(rig.neutral.F.data(), rig.neutral.F.size())});
  arrays.push_back({{"UV", "f64", {nv, 2}}, RawBytes(rig.neutral.UV.data(), rig.neutral.UV.size())});
  for (const auto& [name, B] : {std::pair<const char*, const Eigen::MatrixXf*>{"identity_basis", &rig.identity_basis},
                                {"expression_basis", &rig.expression_basis}}) {
    arrays.push_back(options.compact ? QuantizedBasis(name, *B, options.quantum_mm) : float_basis(name, *B));
  }
  arrays.push_back({{"original_vertex", "i32", {static_cast<int64_t>(rig.original_vertex.size())}},
                    RawBytes(rig.original_vertex.data(), rig.original_vertex.size())});
  arrays.push_back({{"vertex_part", "u8", {static_cast<int64_t>(rig.vertex_part.size())}},
                    RawBytes(rig.vertex_part.data(), rig.vertex_part.size())});
  for (const auto& r : rig.regions) {
    const cv::Mat m = r.mask.isContinuous() ? r.mask : r.mask.clone();
    arrays.push_back({{"region:" + r.name, "u8", {r.mask.rows, r.mask.cols}}, RawBytes(m.data, m.total())});
  }
  json arr = json::array();
  for (auto& a : arrays) {
    json d = {{"name", a.desc.name}, {"dtype", a.desc.dtype}, {"shape", a.desc.shape}};
    if (a.desc.dtype == "i16") d["scale"] = a.desc.scale;
    if (options.compact || options.compress) {
      a.data = ZlibCompress(a.data, path.string());
      d["encoding"] = "zlib";
      d["stored_bytes"] = a.data.size();
    }
    arr.push_back(d);
  }
  header["arrays"] = arr;
  const std::string header_text = header.dump();

  WriteFileAtomic(path, [&](std::ostream& out) {
    out.write(kMagic, 8);
    const uint32_t version = FaceRig::kFormatVersion;
    out.write(reinterpret_cast<const char*>(&version), 4);
    const uint64_t len = header_text.size();
    out.write(reinterpret_cast<const char*>(&len), 8);
    out.write(header_text.data(), static_cast<std::streamsize>(header_text.size()));
    for (const auto& a : arrays) out.write(a.data.data(), static_cast<std::streamsize>(a.data.size()));
  });
}

FaceRig ReadRig(const fs::path& path) {
  const std::string what = path.string();
  const std::string data = ReadFileToString(path);
  size_t pos = 0;
  auto take = [&](size_t n, const char* item) -> const char* {
    if (pos + n > data.size()) {
      throw Error(fmt::format("{}: truncated rig file (reading {}: need {} bytes at offset {}, file has {})",
                              what, item, n, pos, data.size()));
    }
    const char* p = data.data() + pos;
    pos += n;
    return p;
  };
  if (data.size() < 8 || std::memcmp(data.data(), kMagic, 8) != 0) {
    throw Error(fmt::format("{}: not a crease rig (.crig) file (bad magic number)", what));
  }
  pos = 8;
  uint32_t version;
  std::memcpy(&version, take(4, "version"), 4);
  if (version < 1 || version > FaceRig::kFormatVersion) {
    throw Error(fmt::format("{}: rig format version {} is not supported (this crease reads version {}); "
                            "re-create the rig with this version of crease",
                            what, version, FaceRig::kFormatVersion));
  }
  uint64_t len;
  std::memcpy(&len, take(8, "header length"), 8);
  if (len > data.size()) throw Error(fmt::format("{}: truncated rig file (header)", what));
  json header;
  try {
    header = json::parse(std::string(take(len, "header"), len));
  } catch (const json::exception& e) {
    throw Error(fmt::format("{}: malformed rig header: {}", what, e.what()));
  }
  FaceRig rig;
  try {
    rig.source = header.value("source", "");
    rig.identity_names = header.at("identity_names").get<std::vector<std::string>>();
    rig.expression_names = header.at("expression_names").get<std::vector<std::string>>();
    if (header.contains("part_names")) rig.part_names = header.at("part_names").get<std::vector<std::string>>();
    for (const auto& l : header.at("landmarks")) {
      rig.landmarks.push_back({l.at("name").get<std::string>(), l.at("vertex").get<int>()});
    }
    for (const auto& a : header.at("arrays")) {
      ArrayDesc d{a.at("name").get<std::string>(), a.at("dtype").get<std::string>(), {}};
      // Raw bytes must be in the file; zlib's can inflate at most ~1100× (ZlibDecompress).
      const uint64_t left = data.size() - pos;
      d.shape = ReadArrayShape(a.at("shape"), 1100 * left + 1024, d.element_size(), what, d.name);
      d.encoding = a.value("encoding", std::string("raw"));
      d.scale = a.value("scale", 1.0);
      std::string inflated;
      const char* p = nullptr;
      if (d.encoding == "zlib") {
        const uint64_t stored = a.at("stored_bytes").get<uint64_t>();
        const char* z = take(stored, d.name.c_str());
        inflated = ZlibDecompress(z, stored, d.bytes(), fmt::format("{}: array '{}'", what, d.name));
        p = inflated.data();
      } else if (d.encoding == "raw") {
        p = take(d.bytes(), d.name.c_str());
      } else {
        throw Error(fmt::format("{}: array '{}' has an unknown encoding '{}'", what, d.name, d.encoding));
      }
      auto dims = [&](size_t n) {
        if (d.shape.size() != n) throw Error(fmt::format("{}: array '{}' must have {} dimensions", what, d.name, n));
      };
      auto dtype = [&](const char* t) {
        if (d.dtype != t) throw Error(fmt::format("{}: array '{}' must be {}, is {}", what, d.name, t, d.dtype));
      };
      if (d.name == "V" || d.name == "UV") {
        dims(2);
        dtype("f64");
        MatX3d* dst3 = d.name == "V" ? &rig.neutral.V : nullptr;
        if (dst3) {
          if (d.shape[1] != 3) throw Error(fmt::format("{}: array V must be #V x 3", what));
          dst3->resize(d.shape[0], 3);
          CopyBytes(dst3->data(), p, d.bytes());
        } else {
          if (d.shape[1] != 2) throw Error(fmt::format("{}: array UV must be #V x 2", what));
          rig.neutral.UV.resize(d.shape[0], 2);
          CopyBytes(rig.neutral.UV.data(), p, d.bytes());
        }
      } else if (d.name == "F") {
        dims(2);
        dtype("i32");
        if (d.shape[1] != 3) throw Error(fmt::format("{}: array F must be #F x 3", what));
        rig.neutral.F.resize(d.shape[0], 3);
        CopyBytes(rig.neutral.F.data(), p, d.bytes());
      } else if (d.name == "identity_basis" || d.name == "expression_basis") {
        dims(2);
        Eigen::MatrixXf& B = d.name == "identity_basis" ? rig.identity_basis : rig.expression_basis;
        B.resize(d.shape[1], d.shape[0]);
        if (d.dtype == "i16") {
          if (!(std::isfinite(d.scale) && d.scale > 0)) {
            throw Error(fmt::format("{}: array '{}' has an invalid scale", what, d.name));
          }
          for (Eigen::Index i = 0; i < B.size(); ++i) {
            int16_t q;
            std::memcpy(&q, p + 2 * i, 2);
            B.data()[i] = static_cast<float>(q * d.scale);
          }
        } else {
          dtype("f32");
          CopyBytes(B.data(), p, d.bytes());
        }
      } else if (d.name == "original_vertex") {
        dims(1);
        dtype("i32");
        rig.original_vertex.resize(d.shape[0]);
        CopyBytes(rig.original_vertex.data(), p, d.bytes());
      } else if (d.name == "vertex_part") {
        dims(1);
        dtype("u8");
        rig.vertex_part.resize(d.shape[0]);
        CopyBytes(rig.vertex_part.data(), p, d.bytes());
      } else if (d.name.rfind("region:", 0) == 0) {
        dims(2);
        dtype("u8");
        cv::Mat m(static_cast<int>(d.shape[0]), static_cast<int>(d.shape[1]), CV_8UC1);
        CopyBytes(m.data, p, d.bytes());
        rig.regions.push_back({d.name.substr(7), m});
      }
      // Unknown arrays (a later minor addition) are skipped.
    }
  } catch (const json::exception& e) {
    throw Error(fmt::format("{}: malformed rig header: {}", what, e.what()));
  }
  // A basis with zero modes still needs the right row count for Validate.
  if (rig.identity_basis.cols() == 0) rig.identity_basis.resize(3 * rig.neutral.V.rows(), 0);
  if (rig.expression_basis.cols() == 0) rig.expression_basis.resize(3 * rig.neutral.V.rows(), 0);
  rig.Validate(what);
  return rig;
}

// ---------------------------------------------------------------------------
// Regions from the iBUG-68 landmarks.

std::vector<RegionMask> RegionsFromLandmarks(const FaceRig& rig, int size) {
  Require(size >= 16, "RegionsFromLandmarks: size must be >= 16");
  std::vector<Eigen::Vector2d> p(69);  // 1-based like the iBUG annotation
  for (int i = 1; i <= 68; ++i) {
    const int k = rig.LandmarkIndex(fmt::format("ibug_{}", i));
    Require(k >= 0, fmt::format("RegionsFromLandmarks: the rig has no landmark 'ibug_{}' "
                                "(the 68 iBUG landmarks are needed to derive region masks)", i));
    p[i] = rig.neutral.UV.row(rig.landmarks[k].vertex).transpose() * size;
  }
  auto mean = [&](std::initializer_list<int> ids) {
    Eigen::Vector2d m = Eigen::Vector2d::Zero();
    for (int i : ids) m += p[i];
    return Eigen::Vector2d(m / static_cast<double>(ids.size()));
  };
  // Face frame in UV: "up" from the chin to the nose bridge, "scale" the inter-ocular distance.
  const Eigen::Vector2d eye_r = mean({37, 38, 39, 40, 41, 42}), eye_l = mean({43, 44, 45, 46, 47, 48});
  const double iod = (eye_l - eye_r).norm();
  Require(iod > 1e-6 * size, "RegionsFromLandmarks: the eye landmarks coincide in UV");
  const Eigen::Vector2d up = (p[28] - p[9]).normalized();

  auto to_poly = [](const std::vector<Eigen::Vector2d>& pts) {
    std::vector<cv::Point> poly;
    for (const auto& q : pts) poly.emplace_back(cvRound(q.x()), cvRound(q.y()));
    return poly;
  };
  auto hull_mask = [&](std::vector<Eigen::Vector2d> pts, double grow) {
    Eigen::Vector2d c = Eigen::Vector2d::Zero();
    for (const auto& q : pts) c += q;
    c /= static_cast<double>(pts.size());
    for (auto& q : pts) q = c + grow * (q - c);
    std::vector<cv::Point> hull;
    cv::convexHull(to_poly(pts), hull);
    cv::Mat m = cv::Mat::zeros(size, size, CV_8UC1);
    cv::fillConvexPoly(m, hull, cv::Scalar(255));
    return m;
  };
  std::vector<RegionMask> out;
  auto brow_top = [&](int i) { return Eigen::Vector2d(p[i] + up * 0.9 * iod); };
  // Forehead: above the brows, up to about 0.9 inter-ocular distances.
  {
    std::vector<Eigen::Vector2d> pts;
    for (int i = 18; i <= 27; ++i) pts.push_back(p[i] + up * 0.12 * iod);
    for (int i = 18; i <= 27; ++i) pts.push_back(brow_top(i));
    out.push_back({"forehead", hull_mask(pts, 1.0)});
  }
  // Glabella: between the inner brow ends, from the nose bridge to above the brows.
  {
    const Eigen::Vector2d side = (p[23] - p[22]) * 0.5;
    std::vector<Eigen::Vector2d> pts = {p[22] - 0.3 * side, p[23] + 0.3 * side,
                                        p[28] + 0.1 * iod * up + 0.5 * side,
                                        p[28] + 0.1 * iod * up - 0.5 * side,
                                        p[22] + up * 0.35 * iod, p[23] + up * 0.35 * iod};
    out.push_back({"glabella", hull_mask(pts, 1.0)});
  }
  // Eyes with their surroundings (crow's feet outside the outer corner, under-eye lines below).
  auto eye_region = [&](std::initializer_list<int> eye, int outer, int inner) {
    std::vector<Eigen::Vector2d> pts;
    for (int i : eye) pts.push_back(p[i]);
    const Eigen::Vector2d out_dir = (p[outer] - p[inner]).normalized();
    pts.push_back(p[outer] + out_dir * 0.45 * iod);
    pts.push_back(p[outer] + out_dir * 0.4 * iod + up * 0.2 * iod);
    pts.push_back(p[outer] + out_dir * 0.4 * iod - up * 0.3 * iod);
    const Eigen::Vector2d c = mean(eye);
    pts.push_back(c - up * 0.35 * iod);
    pts.push_back(c + up * 0.12 * iod);
    return hull_mask(pts, 1.15);
  };
  // iBUG points 37–42 are the subject's right eye, 43–48 the left.
  out.push_back({"left_eye", eye_region({43, 44, 45, 46, 47, 48}, 46, 43)});
  out.push_back({"right_eye", eye_region({37, 38, 39, 40, 41, 42}, 37, 40)});
  // Cheeks: between lower eyelid, nose side, mouth corner and jaw line.
  auto cheek = [&](std::initializer_list<int> ids) {
    std::vector<Eigen::Vector2d> pts;
    for (int i : ids) pts.push_back(p[i]);
    return hull_mask(pts, 0.95);
  };
  out.push_back({"left_cheek", cheek({47, 48, 46, 17, 16, 15, 14, 13, 55, 36, 32})});
  out.push_back({"right_cheek", cheek({41, 42, 37, 1, 2, 3, 4, 5, 49, 32, 30})});
  {
    std::vector<Eigen::Vector2d> pts;
    for (int i = 28; i <= 36; ++i) pts.push_back(p[i]);
    out.push_back({"nose", hull_mask(pts, 1.25)});
  }
  {
    std::vector<Eigen::Vector2d> pts;
    for (int i = 49; i <= 60; ++i) pts.push_back(p[i]);
    out.push_back({"mouth", hull_mask(pts, 1.2)});
  }
  {
    std::vector<Eigen::Vector2d> pts;
    for (int i = 6; i <= 12; ++i) pts.push_back(p[i]);
    for (int i = 56; i <= 60; ++i) pts.push_back(p[i] - up * 0.08 * iod);
    out.push_back({"chin", hull_mask(pts, 1.0)});
  }
  return out;
}

MatX3i FaceChartTriangles(const FaceRig& rig) {
  const TriMesh& m = rig.neutral;
  const int face_part = rig.part_names.empty() ? -1 : rig.PartIndex("face");
  std::vector<int> keep;
  for (int f = 0; f < m.num_faces(); ++f) {
    bool ok = true;
    for (int k = 0; k < 3; ++k) {
      const int v = m.F(f, k);
      if (face_part >= 0) {
        ok = ok && rig.vertex_part[v] == face_part;
      } else {
        ok = ok && m.UV(v, 0) >= 0 && m.UV(v, 0) <= 1 && m.UV(v, 1) >= 0 && m.UV(v, 1) <= 1;
      }
    }
    if (ok) keep.push_back(f);
  }
  Require(!keep.empty(), "rig: no triangles in the face chart (UVs inside [0,1]² or part 'face')");
  MatX3i F(static_cast<int>(keep.size()), 3);
  for (size_t i = 0; i < keep.size(); ++i) F.row(static_cast<int>(i)) = m.F.row(keep[i]);
  return F;
}

}  // namespace crease
