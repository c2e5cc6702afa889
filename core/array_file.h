// A versioned binary container for trained models (DESIGN.md "File formats"):
//
//   magic        8 bytes, names the kind of file (e.g. "CREASDML")
//   version      u32, the kind's format version
//   header size  u64
//   header       JSON text: {"arrays": [{"name", "dtype", "shape"}, …], …anything else}
//   arrays       raw little-endian data, in the order of header.arrays
//
// dtypes: "f32", "f64", "i32", "u16", "u8". A file of another kind or version is
// a clear error; arrays are read back by name. Written atomically.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

namespace crease {

struct ArrayEntry {
  std::string dtype;
  std::vector<int64_t> shape;
  std::string bytes;  // raw data
  size_t count() const;  // number of elements
};

class ArrayFileWriter {
 public:
  // `header_json`: a JSON object (text) written into the header beside "arrays".
  explicit ArrayFileWriter(std::string header_json = "{}") : header_json_(std::move(header_json)) {}
  void Add(const std::string& name, const float* data, std::vector<int64_t> shape);
  void Add(const std::string& name, const double* data, std::vector<int64_t> shape);
  void Add(const std::string& name, const int32_t* data, std::vector<int64_t> shape);
  void Add(const std::string& name, const uint16_t* data, std::vector<int64_t> shape);
  void Add(const std::string& name, const uint8_t* data, std::vector<int64_t> shape);
  // magic: exactly 8 characters.
  void Write(const std::filesystem::path& path, const char* magic, uint32_t version) const;

 private:
  void AddRaw(const std::string& name, const char* dtype, const void* data, size_t element_size,
              std::vector<int64_t> shape);
  std::string header_json_;
  std::vector<std::pair<std::string, ArrayEntry>> arrays_;
};

struct ArrayFile {
  std::string header_json;  // the whole header (JSON text)
  std::map<std::string, ArrayEntry> arrays;

  // The array `name` as a vector of T (dtype must match: float ↔ f32, double ↔
  // f64, int32_t ↔ i32, uint16_t ↔ u16, uint8_t ↔ u8) with `expected_count`
  // elements (−1 = any). Throws Error naming `what` and the array otherwise.
  template <class T>
  std::vector<T> Get(const std::string& name, int64_t expected_count, const std::string& what) const;
};

// An array's shape from its header entry `shape` (issue 19): a list of at most 8
// JSON integers (a float such as 1e72 would convert to int64_t with undefined
// behaviour), each in [0, 2^34), whose product times `element_size` is at most
// `max_bytes` (checked without overflow). Throws Error naming `what` and the array.
std::vector<int64_t> ReadArrayShape(const nlohmann::json& shape, uint64_t max_bytes, size_t element_size,
                                    const std::string& what, const std::string& name);

// Reads a container; `kind` names the file type in errors ("detail model").
// Throws Error for a missing file, another magic, another version, a truncated
// file or a malformed header.
ArrayFile ReadArrayFile(const std::filesystem::path& path, const char* magic, uint32_t version,
                        const std::string& kind);

}  // namespace crease
