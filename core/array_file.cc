#include "core/array_file.h"

#include <bit>
#include <cstring>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_util.h"

namespace crease {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

size_t ElementSize(const std::string& dtype) {
  if (dtype == "f64") return 8;
  if (dtype == "f32" || dtype == "i32") return 4;
  if (dtype == "u16") return 2;
  if (dtype == "u8") return 1;
  return 0;
}

template <class T>
constexpr const char* DtypeOf() {
  if constexpr (std::is_same_v<T, float>) return "f32";
  if constexpr (std::is_same_v<T, double>) return "f64";
  if constexpr (std::is_same_v<T, int32_t>) return "i32";
  if constexpr (std::is_same_v<T, uint16_t>) return "u16";
  if constexpr (std::is_same_v<T, uint8_t>) return "u8";
}

}  // namespace

size_t ArrayEntry::count() const {
  size_t n = 1;
  for (auto s : shape) n *= static_cast<size_t>(s);
  return n;
}

void ArrayFileWriter::AddRaw(const std::string& name, const char* dtype, const void* data, size_t element_size,
                             std::vector<int64_t> shape) {
  static_assert(std::endian::native == std::endian::little, "crease files are little-endian");
  ArrayEntry e;
  e.dtype = dtype;
  e.shape = std::move(shape);
  e.bytes.assign(static_cast<const char*>(data), e.count() * element_size);
  arrays_.emplace_back(name, std::move(e));
}

void ArrayFileWriter::Add(const std::string& name, const float* data, std::vector<int64_t> shape) {
  AddRaw(name, "f32", data, 4, std::move(shape));
}
void ArrayFileWriter::Add(const std::string& name, const double* data, std::vector<int64_t> shape) {
  AddRaw(name, "f64", data, 8, std::move(shape));
}
void ArrayFileWriter::Add(const std::string& name, const int32_t* data, std::vector<int64_t> shape) {
  AddRaw(name, "i32", data, 4, std::move(shape));
}
void ArrayFileWriter::Add(const std::string& name, const uint16_t* data, std::vector<int64_t> shape) {
  AddRaw(name, "u16", data, 2, std::move(shape));
}
void ArrayFileWriter::Add(const std::string& name, const uint8_t* data, std::vector<int64_t> shape) {
  AddRaw(name, "u8", data, 1, std::move(shape));
}

void ArrayFileWriter::Write(const fs::path& path, const char* magic, uint32_t version) const {
  Require(std::strlen(magic) == 8, "ArrayFileWriter: the magic must have 8 characters");
  json header = json::parse(header_json_);
  json arr = json::array();
  for (const auto& [name, e] : arrays_) arr.push_back({{"name", name}, {"dtype", e.dtype}, {"shape", e.shape}});
  header["arrays"] = arr;
  const std::string text = header.dump();
  WriteFileAtomic(path, [&](std::ostream& out) {
    out.write(magic, 8);
    out.write(reinterpret_cast<const char*>(&version), 4);
    const uint64_t len = text.size();
    out.write(reinterpret_cast<const char*>(&len), 8);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    for (const auto& [name, e] : arrays_) out.write(e.bytes.data(), static_cast<std::streamsize>(e.bytes.size()));
  });
}

std::vector<int64_t> ReadArrayShape(const nlohmann::json& shape, uint64_t max_bytes, size_t element_size,
                                    const std::string& what, const std::string& name) {
  Require(shape.is_array() && shape.size() <= 8,
          fmt::format("{}: array '{}' has an invalid shape (expected a list of at most 8 sizes)", what, name));
  std::vector<int64_t> dims;
  uint64_t elements = 1;
  const uint64_t limit = max_bytes / element_size;
  for (const json& d : shape) {
    Require(d.is_number_integer(), fmt::format("{}: array '{}' has a shape entry that is not an integer", what, name));
    const int64_t s = d.get<int64_t>();
    Require(s >= 0 && s < (int64_t{1} << 34), fmt::format("{}: array '{}' has an invalid shape", what, name));
    dims.push_back(s);
    if (s == 0) elements = 0;
    Require(elements == 0 || static_cast<uint64_t>(s) <= limit / elements,
            fmt::format("{}: truncated file (array '{}' needs more than the {} bytes it can have)", what, name,
                        max_bytes));
    elements *= static_cast<uint64_t>(s);
  }
  return dims;
}

ArrayFile ReadArrayFile(const fs::path& path, const char* magic, uint32_t version, const std::string& kind) {
  const std::string what = path.string();
  RequireReadableFile(path);
  const std::string data = ReadFileToString(path);
  size_t pos = 0;
  auto take = [&](size_t n, const std::string& item) -> const char* {
    Require(pos + n <= data.size(), fmt::format("{}: truncated {} file (reading {}: need {} bytes at offset {}, "
                                                "file has {})",
                                                what, kind, item, n, pos, data.size()));
    const char* p = data.data() + pos;
    pos += n;
    return p;
  };
  Require(data.size() >= 8 && std::memcmp(data.data(), magic, 8) == 0,
          fmt::format("{}: not a crease {} file (bad magic number)", what, kind));
  pos = 8;
  uint32_t file_version;
  std::memcpy(&file_version, take(4, "version"), 4);
  Require(file_version == version,
          fmt::format("{}: {} format version {} is not supported (this crease reads version {}); re-create it "
                      "with this version of crease",
                      what, kind, file_version, version));
  uint64_t len;
  std::memcpy(&len, take(8, "header length"), 8);
  Require(len <= data.size(), fmt::format("{}: truncated {} file (header)", what, kind));
  ArrayFile file;
  file.header_json = std::string(take(len, "header"), len);
  try {
    const json header = json::parse(file.header_json);
    for (const auto& a : header.at("arrays")) {
      ArrayEntry e;
      const std::string name = a.at("name").get<std::string>();
      e.dtype = a.at("dtype").get<std::string>();
      const size_t es = ElementSize(e.dtype);
      Require(es > 0, fmt::format("{}: array '{}' has an unknown dtype '{}'", what, name, e.dtype));
      e.shape = ReadArrayShape(a.at("shape"), data.size() - pos, es, what, name);
      const size_t bytes = e.count() * es;
      e.bytes.assign(take(bytes, "array " + name), bytes);
      file.arrays[name] = std::move(e);
    }
  } catch (const json::exception& e) {
    throw Error(fmt::format("{}: malformed {} header: {}", what, kind, e.what()));
  }
  return file;
}

template <class T>
std::vector<T> ArrayFile::Get(const std::string& name, int64_t expected_count, const std::string& what) const {
  const auto it = arrays.find(name);
  Require(it != arrays.end(), fmt::format("{}: array '{}' is missing", what, name));
  const ArrayEntry& e = it->second;
  Require(e.dtype == DtypeOf<T>(),
          fmt::format("{}: array '{}' must be {}, is {}", what, name, DtypeOf<T>(), e.dtype));
  Require(expected_count < 0 || static_cast<int64_t>(e.count()) == expected_count,
          fmt::format("{}: array '{}' has {} elements, expected {}", what, name, e.count(), expected_count));
  std::vector<T> out(e.count());
  if (!out.empty()) std::memcpy(out.data(), e.bytes.data(), e.bytes.size());
  return out;
}

template std::vector<float> ArrayFile::Get(const std::string&, int64_t, const std::string&) const;
template std::vector<double> ArrayFile::Get(const std::string&, int64_t, const std::string&) const;
template std::vector<int32_t> ArrayFile::Get(const std::string&, int64_t, const std::string&) const;
template std::vector<uint16_t> ArrayFile::Get(const std::string&, int64_t, const std::string&) const;
template std::vector<uint8_t> ArrayFile::Get(const std::string&, int64_t, const std::string&) const;

}  // namespace crease
