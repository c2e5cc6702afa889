#include "core/mesh_io.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iterator>
#include <optional>
#include <string_view>
#include <system_error>
#include <fmt/format.h>

#include "core/error.h"
#include "core/file_util.h"

namespace crease {
namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------------------
// Text helpers
// ---------------------------------------------------------------------------

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// Splits `s` at blanks (not newlines; callers pass one line).
void Tokenize(std::string_view s, std::vector<std::string_view>* tokens) {
  tokens->clear();
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && IsBlank(s[i])) ++i;
    size_t j = i;
    while (j < s.size() && !IsBlank(s[j])) ++j;
    if (j > i) tokens->push_back(s.substr(i, j - i));
    i = j;
  }
}

// Whole-token parses; a leading '+' is accepted. Out-of-range values fail.
bool ParseDouble(std::string_view s, double* out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

bool ParseInt(std::string_view s, int64_t* out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

// Appends to `buf`, writing it to `out` whenever it grows beyond 1 MiB so that
// large meshes do not need a second full copy in memory.
void FlushIfLarge(fmt::memory_buffer& buf, std::ostream& out, bool force = false) {
  if (force || buf.size() > (size_t{1} << 20)) {
    out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    buf.clear();
  }
}

// ---------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------

bool IsIgnoredObjStatement(std::string_view key) {
  static constexpr std::string_view kIgnored[] = {
      "vn",  "o",          "g",         "s",     "usemtl",   "mtllib",   "l",      "p",
      "vp",  "lod",        "shadow_obj", "trace_obj", "bevel", "c_interp", "d_interp", "usemap",
      "maplib", "mg",      "ctech",     "stech"};
  return std::find(std::begin(kIgnored), std::end(kIgnored), key) != std::end(kIgnored);
}

bool IsFreeFormObjStatement(std::string_view key) {
  static constexpr std::string_view kFreeForm[] = {"cstype", "deg",  "bmat", "step", "curv",
                                                   "curv2",  "surf", "parm", "trim", "hole",
                                                   "scrv",   "sp",   "end",  "con"};
  return std::find(std::begin(kFreeForm), std::end(kFreeForm), key) != std::end(kFreeForm);
}

// ---------------------------------------------------------------------------
// PLY
// ---------------------------------------------------------------------------

enum class PlyType : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

std::optional<PlyType> ParsePlyType(std::string_view s) {
  if (s == "char" || s == "int8") return PlyType::kInt8;
  if (s == "uchar" || s == "uint8") return PlyType::kUint8;
  if (s == "short" || s == "int16") return PlyType::kInt16;
  if (s == "ushort" || s == "uint16") return PlyType::kUint16;
  if (s == "int" || s == "int32") return PlyType::kInt32;
  if (s == "uint" || s == "uint32") return PlyType::kUint32;
  if (s == "float" || s == "float32") return PlyType::kFloat32;
  if (s == "double" || s == "float64") return PlyType::kFloat64;
  return std::nullopt;
}

size_t PlySize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUint8: return 1;
    case PlyType::kInt16:
    case PlyType::kUint16: return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
  }
  return 0;
}

bool IsIntegral(PlyType t) { return t != PlyType::kFloat32 && t != PlyType::kFloat64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat64;  // the item type for lists
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
};

struct PlyElement {
  std::string name;
  int64_t count = 0;
  std::vector<PlyProperty> properties;
};

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  size_t data_offset = 0;  // first byte after the end_header line
  int data_line = 0;       // line number of the first data line (ascii)
};

PlyHeader ParsePlyHeader(const std::string& bytes, const std::string& file) {
  size_t pos = 0;
  int line_no = 0;
  auto next_line = [&](std::string_view* line) {
    if (pos >= bytes.size()) return false;
    size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) end = bytes.size();
    *line = std::string_view(bytes).substr(pos, end - pos);
    if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
    pos = std::min(end + 1, bytes.size());
    ++line_no;
    return true;
  };
  auto fail = [&](const std::string& what) {
    return Error(fmt::format("{}:{}: {}", file, line_no, what));
  };

  std::string_view line;
  if (!next_line(&line) || line != "ply") {
    throw Error(fmt::format("{}: not a PLY file (the first line must be 'ply')", file));
  }
  PlyHeader header;
  bool has_format = false;
  std::vector<std::string_view> tokens;
  while (true) {
    if (!next_line(&line)) {
      throw Error(fmt::format("{}: PLY header has no 'end_header' line (file truncated?)", file));
    }
    Tokenize(line, &tokens);
    if (tokens.empty()) continue;
    const std::string_view key = tokens[0];
    if (key == "comment" || key == "obj_info") continue;
    if (key == "end_header") break;
    if (key == "format") {
      if (tokens.size() != 3) throw fail("expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
      if (tokens[1] == "ascii") {
        header.format = PlyFormat::kAscii;
      } else if (tokens[1] == "binary_little_endian") {
        header.format = PlyFormat::kBinaryLittleEndian;
      } else if (tokens[1] == "binary_big_endian") {
        header.format = PlyFormat::kBinaryBigEndian;
      } else {
        throw fail(fmt::format("unsupported PLY format '{}' (expected ascii, binary_little_endian "
                               "or binary_big_endian)", tokens[1]));
      }
      has_format = true;
    } else if (key == "element") {
      int64_t count = 0;
      if (tokens.size() != 3 || !ParseInt(tokens[2], &count) || count < 0) {
        throw fail("expected 'element <name> <count>' with a count >= 0");
      }
      header.elements.push_back({std::string(tokens[1]), count, {}});
    } else if (key == "property") {
      if (header.elements.empty()) throw fail("property before any 'element' line");
      PlyProperty prop;
      if (tokens.size() >= 2 && tokens[1] == "list") {
        if (tokens.size() != 5) throw fail("expected 'property list <count type> <item type> <name>'");
        const auto count_type = ParsePlyType(tokens[2]);
        const auto item_type = ParsePlyType(tokens[3]);
        if (!count_type) throw fail(fmt::format("unknown property type '{}'", tokens[2]));
        if (!item_type) throw fail(fmt::format("unknown property type '{}'", tokens[3]));
        if (!IsIntegral(*count_type)) {
          throw fail(fmt::format("list count type '{}' is not an integer type", tokens[2]));
        }
        prop.is_list = true;
        prop.count_type = *count_type;
        prop.type = *item_type;
        prop.name = std::string(tokens[4]);
      } else {
        if (tokens.size() != 3) throw fail("expected 'property <type> <name>'");
        const auto type = ParsePlyType(tokens[1]);
        if (!type) throw fail(fmt::format("unknown property type '{}'", tokens[1]));
        prop.type = *type;
        prop.name = std::string(tokens[2]);
      }
      header.elements.back().properties.push_back(std::move(prop));
    } else {
      throw fail(fmt::format("unexpected PLY header line '{}'", line));
    }
  }
  if (!has_format) throw Error(fmt::format("{}: PLY header has no 'format' line", file));
  header.data_offset = pos;
  header.data_line = line_no + 1;
  return header;
}

template <class T>
T LoadScalar(const char* p, bool swap) {
  char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

// Binary data cursor. Read() returns false at the end of the data.
class PlyBinaryInput {
 public:
  PlyBinaryInput(const std::string& bytes, size_t offset, bool swap)
      : p_(bytes.data() + offset), end_(bytes.data() + bytes.size()), swap_(swap) {}

  bool Read(PlyType t, double* out) {
    const size_t n = PlySize(t);
    if (static_cast<size_t>(end_ - p_) < n) return false;
    switch (t) {
      case PlyType::kInt8: *out = LoadScalar<int8_t>(p_, swap_); break;
      case PlyType::kUint8: *out = LoadScalar<uint8_t>(p_, swap_); break;
      case PlyType::kInt16: *out = LoadScalar<int16_t>(p_, swap_); break;
      case PlyType::kUint16: *out = LoadScalar<uint16_t>(p_, swap_); break;
      case PlyType::kInt32: *out = LoadScalar<int32_t>(p_, swap_); break;
      case PlyType::kUint32: *out = LoadScalar<uint32_t>(p_, swap_); break;
      case PlyType::kFloat32: *out = LoadScalar<float>(p_, swap_); break;
      case PlyType::kFloat64: *out = LoadScalar<double>(p_, swap_); break;
    }
    p_ += n;
    return true;
  }

  // Rejects element counts the remaining bytes cannot hold before anything is
  // allocated for them.
  void CheckFits(const PlyElement& e, const std::string& file) const {
    size_t min_bytes = 0;
    for (const PlyProperty& p : e.properties) min_bytes += PlySize(p.is_list ? p.count_type : p.type);
    const size_t left = static_cast<size_t>(end_ - p_);
    if (min_bytes > 0 && static_cast<uint64_t>(e.count) > left / min_bytes) {
      throw Error(fmt::format("{}: data ends early: element '{}' declares {} entries (at least {} "
                              "bytes) but only {} bytes are left (file truncated?)",
                              file, e.name, e.count, static_cast<uint64_t>(e.count) * min_bytes, left));
    }
  }

  std::string Failure(const std::string& file) const {
    return fmt::format("{}: data ends early (file truncated?)", file);
  }

 private:
  const char* p_;
  const char* end_;
  bool swap_;
};

// Ascii data cursor: whitespace-separated tokens, line numbers tracked for errors.
class PlyAsciiInput {
 public:
  PlyAsciiInput(const std::string& bytes, size_t offset, int first_line)
      : p_(bytes.data() + offset), end_(bytes.data() + bytes.size()), line_(first_line) {}

  bool Read(PlyType t, double* out) {
    while (p_ < end_ && (IsBlank(*p_) || *p_ == '\n')) {
      if (*p_ == '\n') ++line_;
      ++p_;
    }
    if (p_ == end_) {
      at_end_ = true;
      return false;
    }
    const char* q = p_;
    while (q < end_ && !IsBlank(*q) && *q != '\n') ++q;
    token_ = std::string_view(p_, static_cast<size_t>(q - p_));
    p_ = q;
    if (IsIntegral(t)) {
      int64_t v = 0;
      if (!ParseInt(token_, &v)) return false;
      *out = static_cast<double>(v);
      return true;
    }
    return ParseDouble(token_, out);
  }

  void CheckFits(const PlyElement& e, const std::string& file) const {
    const size_t left = static_cast<size_t>(end_ - p_);
    if (!e.properties.empty() && static_cast<uint64_t>(e.count) > left) {
      throw Error(fmt::format("{}: data ends early: element '{}' declares {} entries but only {} "
                              "bytes are left (file truncated?)", file, e.name, e.count, left));
    }
  }

  std::string Failure(const std::string& file) const {
    if (at_end_) return fmt::format("{}:{}: data ends early (file truncated?)", file, line_);
    return fmt::format("{}:{}: bad number '{}'", file, line_, token_);
  }

 private:
  const char* p_;
  const char* end_;
  int line_;
  bool at_end_ = false;
  std::string_view token_;
};

// Vertex property roles.
enum PlyRole { kX, kY, kZ, kNx, kNy, kNz, kU, kV, kNumRoles };

int VertexRole(const std::string& name) {
  if (name == "x") return kX;
  if (name == "y") return kY;
  if (name == "z") return kZ;
  if (name == "nx") return kNx;
  if (name == "ny") return kNy;
  if (name == "nz") return kNz;
  if (name == "u" || name == "s" || name == "texture_u" || name == "texture_s") return kU;
  if (name == "v" || name == "t" || name == "texture_v" || name == "texture_t") return kV;
  return -1;
}

template <class Input>
TriMesh ReadPlyBody(Input& in, const PlyHeader& header, const std::string& file) {
  const PlyElement* vertex_element = nullptr;
  for (const PlyElement& e : header.elements) {
    if (e.name == "vertex" && vertex_element == nullptr) vertex_element = &e;
  }
  if (vertex_element == nullptr) throw Error(fmt::format("{}: PLY file has no 'vertex' element", file));
  if (vertex_element->count > INT_MAX) {
    throw Error(fmt::format("{}: {} vertices are more than crease supports", file, vertex_element->count));
  }
  const int64_t num_vertices = vertex_element->count;

  TriMesh mesh;
  std::vector<int> triangles;
  std::vector<int> polygon;
  for (const PlyElement& e : header.elements) {
    const bool is_vertex = &e == vertex_element;
    const bool is_face = e.name == "face";
    const int np = static_cast<int>(e.properties.size());
    std::vector<int> role(static_cast<size_t>(np), -1);
    int index_list = -1;  // face property holding the vertex indices
    bool has_normals = false, has_uv = false;
    if (is_vertex) {
      bool present[kNumRoles] = {};
      for (int p = 0; p < np; ++p) {
        const int r = VertexRole(e.properties[p].name);
        if (r < 0) continue;
        if (e.properties[p].is_list) {
          throw Error(fmt::format("{}: vertex property '{}' is a list, expected a number", file,
                                  e.properties[p].name));
        }
        role[p] = r;
        present[r] = true;
      }
      for (int r : {kX, kY, kZ}) {
        if (!present[r]) {
          throw Error(fmt::format("{}: element 'vertex' has no property '{}'", file,
                                  r == kX ? "x" : r == kY ? "y" : "z"));
        }
      }
      has_normals = present[kNx] && present[kNy] && present[kNz];
      has_uv = present[kU] && present[kV];
      for (int p = 0; p < np; ++p) {
        if ((!has_normals && role[p] >= kNx && role[p] <= kNz) || (!has_uv && role[p] >= kU)) {
          role[p] = -1;
        }
      }
    } else if (is_face) {
      for (int p = 0; p < np; ++p) {
        const PlyProperty& prop = e.properties[p];
        if (prop.name == "vertex_indices" || prop.name == "vertex_index") {
          if (!prop.is_list || !IsIntegral(prop.type)) {
            throw Error(fmt::format("{}: face property '{}' must be a list of integers", file, prop.name));
          }
          index_list = p;
          break;
        }
      }
      if (index_list < 0) {
        throw Error(fmt::format("{}: element 'face' has no 'vertex_indices' or 'vertex_index' list",
                                file));
      }
      if (e.count > INT_MAX) {
        throw Error(fmt::format("{}: {} faces are more than crease supports", file, e.count));
      }
    }
    in.CheckFits(e, file);
    if (is_vertex) {
      mesh.V.resize(num_vertices, 3);
      if (has_normals) mesh.N.resize(num_vertices, 3);
      if (has_uv) mesh.UV.resize(num_vertices, 2);
    }

    auto read = [&](PlyType t, double* value, int64_t i, int p) {
      if (!in.Read(t, value)) {
        throw Error(fmt::format("{} (element '{}' {} of {}, property '{}')", in.Failure(file), e.name,
                                i, e.count, e.properties[p].name));
      }
    };
    double values[kNumRoles] = {};
    for (int64_t i = 0; i < e.count; ++i) {
      for (int p = 0; p < np; ++p) {
        const PlyProperty& prop = e.properties[p];
        double value = 0.0;
        if (!prop.is_list) {
          read(prop.type, &value, i, p);
          if (role[p] >= 0) values[role[p]] = value;
          continue;
        }
        double length = 0.0;
        read(prop.count_type, &length, i, p);
        if (length < 0) {
          throw Error(fmt::format("{}: element '{}' {} has a list '{}' of negative length {}", file,
                                  e.name, i, prop.name, length));
        }
        const bool keep = is_face && p == index_list;
        if (keep) polygon.clear();
        for (int64_t j = 0; j < static_cast<int64_t>(length); ++j) {
          read(prop.type, &value, i, p);
          if (!keep) continue;
          if (value < 0 || value >= static_cast<double>(num_vertices)) {
            throw Error(fmt::format("{}: face {} references vertex {}, but the file has {} vertices "
                                    "(index out of range)", file, i, value, num_vertices));
          }
          polygon.push_back(static_cast<int>(value));
        }
        if (keep) {
          if (polygon.size() < 3) {
            throw Error(fmt::format("{}: face {} has {} vertices, needs at least 3", file, i,
                                    polygon.size()));
          }
          for (size_t k = 1; k + 1 < polygon.size(); ++k) {  // fan from the first corner
            triangles.insert(triangles.end(), {polygon[0], polygon[k], polygon[k + 1]});
          }
        }
      }
      if (is_vertex) {
        const Eigen::Index r = static_cast<Eigen::Index>(i);
        mesh.V.row(r) << values[kX], values[kY], values[kZ];
        if (has_normals) mesh.N.row(r) << values[kNx], values[kNy], values[kNz];
        if (has_uv) mesh.UV.row(r) << values[kU], values[kV];
      }
    }
  }
  mesh.F = Eigen::Map<const MatX3i>(triangles.data(), static_cast<Eigen::Index>(triangles.size() / 3), 3);
  ValidateMesh(mesh, file);
  return mesh;
}

template <class T>
void AppendLittleEndian(fmt::memory_buffer& buf, T value) {
  char b[sizeof(T)];
  std::memcpy(b, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
  buf.append(b, b + sizeof(T));
}

}  // namespace

// ---------------------------------------------------------------------------
// OBJ polygons
// ---------------------------------------------------------------------------

PolygonMesh ReadObjPolygons(const fs::path& path) {
  const std::string text = ReadFileToString(path);
  const std::string file = path.string();

  std::vector<double> positions, uvs;
  int64_t num_positions = 0, num_uvs = 0, num_normals = 0;
  PolygonMesh out;
  int uv_mode = -1;        // -1: no face yet, 0: faces without vt, 1: faces with vt
  int uv_mode_line = 0;    // line of the face that set uv_mode
  struct ForwardReference {
    int line;
    int64_t index;  // 1-based, beyond the count at the time of reading
    int kind;       // 0 position, 1 uv, 2 normal
  };
  std::vector<ForwardReference> forward;
  std::vector<std::string_view> tokens;
  std::vector<int> face_positions, face_uvs;
  int line_no = 0;
  size_t begin = 0;
  auto fail = [&](const std::string& what) { return Error(fmt::format("{}:{}: {}", file, line_no, what)); };
  static constexpr const char* kKindName[] = {"position", "texture coordinate", "normal"};
  static constexpr const char* kKindStatement[] = {"v", "vt", "vn"};

  // Resolves a 1-based or negative relative index to 0-based.
  auto resolve = [&](std::string_view token, int64_t count, int kind) {
    int64_t index = 0;
    if (!ParseInt(token, &index)) throw fail(fmt::format("bad {} index '{}' in face", kKindName[kind], token));
    if (index == 0) throw fail(fmt::format("{} index 0 in face (OBJ indices start at 1)", kKindName[kind]));
    if (index < 0) {
      if (count + index < 0) {
        throw fail(fmt::format("relative {} index {} out of range: only {} '{}' lines before this face",
                               kKindName[kind], index, count, kKindStatement[kind]));
      }
      return static_cast<int>(count + index);
    }
    if (index > INT_MAX) throw fail(fmt::format("{} index {} out of range", kKindName[kind], index));
    if (index > count) forward.push_back({line_no, index, kind});
    return static_cast<int>(index - 1);
  };

  while (begin < text.size()) {
    size_t end = text.find('\n', begin);
    if (end == std::string::npos) end = text.size();
    ++line_no;
    std::string_view line(text.data() + begin, end - begin);
    begin = end + 1;
    if (const size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    Tokenize(line, &tokens);
    if (tokens.empty()) continue;
    const std::string_view key = tokens[0];

    if (key == "v" || key == "vt") {
      const bool is_position = key == "v";
      const size_t needed = is_position ? 3 : 1;
      if (tokens.size() - 1 < needed) {
        throw fail(is_position ? "'v' needs 3 coordinates" : "'vt' needs at least 1 coordinate");
      }
      double xyz[3] = {0.0, 0.0, 0.0};
      const size_t used = is_position ? 3 : 2;
      for (size_t k = 0; k < used && k + 1 < tokens.size(); ++k) {
        if (!ParseDouble(tokens[k + 1], &xyz[k])) {
          throw fail(fmt::format("bad number '{}' in '{}'", tokens[k + 1], key));
        }
        if (!std::isfinite(xyz[k])) {
          throw fail(fmt::format("non-finite coordinate '{}' in '{}'", tokens[k + 1], key));
        }
      }
      if (is_position) {
        positions.insert(positions.end(), xyz, xyz + 3);
        ++num_positions;
      } else {
        uvs.insert(uvs.end(), xyz, xyz + 2);
        ++num_uvs;
      }
    } else if (key == "vn") {
      ++num_normals;
    } else if (key == "f") {
      const size_t corners = tokens.size() - 1;
      if (corners < 3) throw fail(fmt::format("face has {} corners, needs at least 3", corners));
      face_positions.clear();
      face_uvs.clear();
      int with_uv = -1;
      for (size_t k = 1; k < tokens.size(); ++k) {
        const std::string_view token = tokens[k];
        std::string_view parts[3];
        int num_parts = 0;
        size_t start = 0;
        while (true) {
          const size_t slash = token.find('/', start);
          if (num_parts == 3) throw fail(fmt::format("bad face corner '{}' (expected v, v/vt, v/vt/vn or v//vn)", token));
          parts[num_parts++] = token.substr(start, slash == std::string_view::npos ? slash : slash - start);
          if (slash == std::string_view::npos) break;
          start = slash + 1;
        }
        if (parts[0].empty() || (num_parts == 2 && parts[1].empty()) ||
            (num_parts == 3 && parts[2].empty())) {
          throw fail(fmt::format("bad face corner '{}' (expected v, v/vt, v/vt/vn or v//vn)", token));
        }
        const int corner_has_uv = num_parts >= 2 && !parts[1].empty() ? 1 : 0;
        if (with_uv >= 0 && corner_has_uv != with_uv) {
          throw fail("face mixes corners with and without texture coordinates");
        }
        with_uv = corner_has_uv;
        face_positions.push_back(resolve(parts[0], num_positions, 0));
        if (corner_has_uv) face_uvs.push_back(resolve(parts[1], num_uvs, 1));
        if (num_parts == 3) resolve(parts[2], num_normals, 2);
      }
      if (uv_mode < 0) {
        uv_mode = with_uv;
        uv_mode_line = line_no;
      } else if (uv_mode != with_uv) {
        throw fail(fmt::format("face {} texture coordinates, but the face on line {} {} (all faces must "
                               "agree)", with_uv ? "has" : "has no", uv_mode_line,
                               uv_mode ? "has them" : "has none"));
      }
      for (size_t a = 0; a < face_positions.size(); ++a) {
        for (size_t b = a + 1; b < face_positions.size(); ++b) {
          if (face_positions[a] == face_positions[b]) {
            throw fail(fmt::format("face uses vertex {} twice", face_positions[a] + 1));
          }
        }
      }
      out.corner_position.insert(out.corner_position.end(), face_positions.begin(), face_positions.end());
      out.corner_uv.insert(out.corner_uv.end(), face_uvs.begin(), face_uvs.end());
      if (out.corner_position.size() > static_cast<size_t>(INT_MAX)) throw fail("too many face corners");
      out.face_offsets.push_back(static_cast<int>(out.corner_position.size()));
    } else if (IsFreeFormObjStatement(key)) {
      throw fail(fmt::format("free-form geometry ('{}') is not supported", key));
    } else if (!IsIgnoredObjStatement(key)) {
      throw fail(fmt::format("unknown statement '{}'", key));
    }
  }

  const int64_t totals[3] = {num_positions, num_uvs, num_normals};
  for (const ForwardReference& r : forward) {
    if (r.index > totals[r.kind]) {
      throw Error(fmt::format("{}:{}: {} index {} out of range: the file has {} '{}' lines", file,
                              r.line, kKindName[r.kind], r.index, totals[r.kind], kKindStatement[r.kind]));
    }
  }
  if (num_positions > INT_MAX || num_uvs > INT_MAX) {
    throw Error(fmt::format("{}: too many vertices", file));
  }
  out.positions = Eigen::Map<const MatX3d>(positions.data(), static_cast<Eigen::Index>(num_positions), 3);
  out.uvs = Eigen::Map<const MatX2d>(uvs.data(), static_cast<Eigen::Index>(num_uvs), 2);
  return out;
}

TriangulatedMesh TriangulateAndSplitSeams(const PolygonMesh& shape, const std::string& what) {
  const int num_positions = static_cast<int>(shape.positions.rows());
  const int num_uvs = static_cast<int>(shape.uvs.rows());
  const int num_corners = shape.num_corners();
  const bool with_uv = shape.has_corner_uv();
  Require(!shape.face_offsets.empty() && shape.face_offsets.front() == 0 &&
              shape.face_offsets.back() == num_corners,
          fmt::format("{}: face_offsets must start at 0 and end at the number of corners ({})", what,
                      num_corners));
  Require(!with_uv || static_cast<int>(shape.corner_uv.size()) == num_corners,
          fmt::format("{}: {} corner UV indices for {} corners", what, shape.corner_uv.size(), num_corners));
  int num_triangles = 0;
  for (int f = 0; f < shape.num_faces(); ++f) {
    const int k = shape.face_offsets[f + 1] - shape.face_offsets[f];
    Require(k >= 3, fmt::format("{}: face {} has {} corners, needs at least 3", what, f, k));
    num_triangles += k - 2;
  }
  for (int c = 0; c < num_corners; ++c) {
    const int p = shape.corner_position[c];
    Require(p >= 0 && p < num_positions,
            fmt::format("{}: corner {} references position {}, but there are {} positions", what, c, p,
                        num_positions));
    if (with_uv) {
      const int t = shape.corner_uv[c];
      Require(t >= 0 && t < num_uvs, fmt::format("{}: corner {} references UV {}, but there are {} UVs",
                                                 what, c, t, num_uvs));
    }
  }

  // Stable counting sort of the corners by position: the corners of position p, in
  // corner order, are order[start[p] .. start[p + 1]).
  std::vector<int> start(static_cast<size_t>(num_positions) + 1, 0);
  for (int c = 0; c < num_corners; ++c) ++start[shape.corner_position[c] + 1];
  for (int p = 0; p < num_positions; ++p) start[p + 1] += start[p];
  std::vector<int> order(static_cast<size_t>(num_corners));
  {
    std::vector<int> next(start.begin(), start.end() - 1);
    for (int c = 0; c < num_corners; ++c) order[next[shape.corner_position[c]]++] = c;
  }

  // One output vertex per distinct (position, uv) pair, by position then first use.
  TriangulatedMesh out;
  std::vector<int> vertex_uv;
  std::vector<int> corner_vertex(static_cast<size_t>(num_corners));
  for (int p = 0; p < num_positions; ++p) {
    const int first = static_cast<int>(out.original_vertex.size());
    for (int k = start[p]; k < start[p + 1]; ++k) {
      const int c = order[k];
      const int t = with_uv ? shape.corner_uv[c] : -1;
      int v = -1;
      for (int w = first; w < static_cast<int>(vertex_uv.size()); ++w) {
        // Equal coordinates under two "vt" indices are one UV (exporters repeat them).
        if (vertex_uv[w] == t || (t >= 0 && shape.uvs.row(vertex_uv[w]) == shape.uvs.row(t))) {
          v = w;
          break;
        }
      }
      if (v < 0) {
        v = static_cast<int>(vertex_uv.size());
        out.original_vertex.push_back(p);
        vertex_uv.push_back(t);
      }
      corner_vertex[c] = v;
    }
  }

  const int num_vertices = static_cast<int>(out.original_vertex.size());
  TriMesh& mesh = out.mesh;
  mesh.V.resize(num_vertices, 3);
  for (int v = 0; v < num_vertices; ++v) mesh.V.row(v) = shape.positions.row(out.original_vertex[v]);
  if (with_uv) {
    mesh.UV.resize(num_vertices, 2);
    for (int v = 0; v < num_vertices; ++v) mesh.UV.row(v) = shape.uvs.row(vertex_uv[v]);
  }
  mesh.F.resize(num_triangles, 3);
  int t = 0;
  for (int f = 0; f < shape.num_faces(); ++f) {
    const int c0 = shape.face_offsets[f];
    for (int c = c0 + 1; c + 1 < shape.face_offsets[f + 1]; ++c) {  // fan from the first corner
      mesh.F.row(t++) << corner_vertex[c0], corner_vertex[c], corner_vertex[c + 1];
    }
  }
  return out;
}

MatX3d GatherPositions(const PolygonMesh& shape, const std::vector<int>& original_vertex) {
  const int num_positions = static_cast<int>(shape.positions.rows());
  MatX3d V(static_cast<Eigen::Index>(original_vertex.size()), 3);
  for (size_t i = 0; i < original_vertex.size(); ++i) {
    const int p = original_vertex[i];
    Require(p >= 0 && p < num_positions,
            fmt::format("GatherPositions: vertex {} maps to position {}, but the shape has {} positions",
                        i, p, num_positions));
    V.row(static_cast<Eigen::Index>(i)) = shape.positions.row(p);
  }
  return V;
}

bool SameTopology(const PolygonMesh& a, const PolygonMesh& b) {
  return a.positions.rows() == b.positions.rows() && a.uvs.rows() == b.uvs.rows() &&
         a.face_offsets == b.face_offsets && a.corner_position == b.corner_position &&
         a.corner_uv == b.corner_uv;
}

// ---------------------------------------------------------------------------
// PLY
// ---------------------------------------------------------------------------

TriMesh ReadPly(const fs::path& path) {
  const std::string bytes = ReadFileToString(path);
  const std::string file = path.string();
  const PlyHeader header = ParsePlyHeader(bytes, file);
  if (header.format == PlyFormat::kAscii) {
    PlyAsciiInput in(bytes, header.data_offset, header.data_line);
    return ReadPlyBody(in, header, file);
  }
  const bool file_big_endian = header.format == PlyFormat::kBinaryBigEndian;
  const bool host_big_endian = std::endian::native == std::endian::big;
  PlyBinaryInput in(bytes, header.data_offset, file_big_endian != host_big_endian);
  return ReadPlyBody(in, header, file);
}

void WritePly(const fs::path& path, const TriMesh& mesh, const PlyWriteOptions& options) {
  ValidateMesh(mesh, path.string(), {.non_empty = false});
  WriteFileAtomic(path, [&](std::ostream& out) {
    const char* type = options.double_precision ? "double" : "float";
    fmt::memory_buffer buf;
    auto it = std::back_inserter(buf);
    fmt::format_to(it, "ply\nformat {} 1.0\ncomment written by crease\nelement vertex {}\n",
        options.binary ? "binary_little_endian" : "ascii", mesh.num_vertices());
    fmt::format_to(it, "property {0} x\nproperty {0} y\nproperty {0} z\n", type);
    if (mesh.has_normals()) fmt::format_to(it, "property {0} nx\nproperty {0} ny\nproperty {0} nz\n", type);
    if (mesh.has_uv()) fmt::format_to(it, "property {0} u\nproperty {0} v\n", type);
    fmt::format_to(it, "element face {}\nproperty list uchar int vertex_indices\nend_header\n", mesh.num_faces());

    auto number = [&](double x) {
      if (options.binary) {
        if (options.double_precision) {
          AppendLittleEndian(buf, x);
        } else {
          AppendLittleEndian(buf, static_cast<float>(x));
        }
      } else if (options.double_precision) {
        fmt::format_to(it, "{} ", x);
      } else {
        fmt::format_to(it, "{} ", static_cast<float>(x));
      }
    };
    for (int i = 0; i < mesh.num_vertices(); ++i) {
      for (int k = 0; k < 3; ++k) number(mesh.V(i, k));
      if (mesh.has_normals()) {
        for (int k = 0; k < 3; ++k) number(mesh.N(i, k));
      }
      if (mesh.has_uv()) {
        for (int k = 0; k < 2; ++k) number(mesh.UV(i, k));
      }
      if (!options.binary) buf[buf.size() - 1] = '\n';  // replaces the last separator
      FlushIfLarge(buf, out);
    }
    for (int f = 0; f < mesh.num_faces(); ++f) {
      if (options.binary) {
        AppendLittleEndian(buf, uint8_t{3});
        for (int k = 0; k < 3; ++k) AppendLittleEndian(buf, static_cast<int32_t>(mesh.F(f, k)));
      } else {
        fmt::format_to(it, "3 {} {} {}\n", mesh.F(f, 0), mesh.F(f, 1), mesh.F(f, 2));
      }
      FlushIfLarge(buf, out);
    }
    FlushIfLarge(buf, out, /*force=*/true);
  });
}

// ---------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------

TriMesh ReadObj(const fs::path& path) {
  const PolygonMesh shape = ReadObjPolygons(path);
  TriangulatedMesh split = TriangulateAndSplitSeams(shape, path.string());
  ValidateMesh(split.mesh, path.string());
  return std::move(split.mesh);
}

void WriteObj(const fs::path& path, const TriMesh& mesh) {
  ValidateMesh(mesh, path.string(), {.non_empty = false});
  WriteFileAtomic(path, [&](std::ostream& out) {
    fmt::memory_buffer buf;
    auto it = std::back_inserter(buf);
    fmt::format_to(it, "# written by crease: {} vertices, {} triangles\n", mesh.num_vertices(), mesh.num_faces());
    for (int i = 0; i < mesh.num_vertices(); ++i) {
      fmt::format_to(it, "v {} {} {}\n", mesh.V(i, 0), mesh.V(i, 1), mesh.V(i, 2));
      FlushIfLarge(buf, out);
    }
    for (int i = 0; i < (mesh.has_uv() ? mesh.num_vertices() : 0); ++i) {
      fmt::format_to(it, "vt {} {}\n", mesh.UV(i, 0), mesh.UV(i, 1));
      FlushIfLarge(buf, out);
    }
    for (int i = 0; i < (mesh.has_normals() ? mesh.num_vertices() : 0); ++i) {
      fmt::format_to(it, "vn {} {} {}\n", mesh.N(i, 0), mesh.N(i, 1), mesh.N(i, 2));
      FlushIfLarge(buf, out);
    }
    for (int f = 0; f < mesh.num_faces(); ++f) {
      buf.push_back('f');
      for (int k = 0; k < 3; ++k) {
        const int v = mesh.F(f, k) + 1;
        if (mesh.has_uv() && mesh.has_normals()) {
          fmt::format_to(it, " {0}/{0}/{0}", v);
        } else if (mesh.has_uv()) {
          fmt::format_to(it, " {0}/{0}", v);
        } else if (mesh.has_normals()) {
          fmt::format_to(it, " {0}//{0}", v);
        } else {
          fmt::format_to(it, " {}", v);
        }
      }
      buf.push_back('\n');
      FlushIfLarge(buf, out);
    }
    FlushIfLarge(buf, out, /*force=*/true);
  });
}

// ---------------------------------------------------------------------------
// Dispatch
// ---------------------------------------------------------------------------

namespace {
Error UnsupportedMeshExtension(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  return Error(fmt::format("{}: unsupported mesh file extension '{}' (supported: .ply, .obj; .vtp is "
                           "handled by core/vtk_io.h: ReadVtp/WriteVtp or ReadAnyMesh/WriteAnyMesh)",
                           path.string(), ext.empty() ? "(none)" : ext));
}
}  // namespace

TriMesh ReadMesh(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  if (ext == ".ply") return ReadPly(path);
  if (ext == ".obj") return ReadObj(path);
  throw UnsupportedMeshExtension(path);
}

void WriteMesh(const fs::path& path, const TriMesh& mesh) {
  const std::string ext = LowerExtension(path);
  if (ext == ".ply") return WritePly(path, mesh);
  if (ext == ".obj") return WriteObj(path, mesh);
  throw UnsupportedMeshExtension(path);
}

}  // namespace crease
