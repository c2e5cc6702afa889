// Options by field name. Every stage's `XxxOptions` struct
//   * gives each field a default equal to the paper's value, commented with its
//     unit and paper symbol (`int num_ferns = 1280;  // K, Sec. 4.3`),
//   * lists its fields once in `void VisitFields(OptionVisitor& v)`
//     (`v.Field("num_ferns", num_ferns);` — the key equals the field name),
//   * rejects invalid values in `void Check() const` by throwing crease::Error with a
//     message naming the field and the violated bound (use the CheckXX helpers below).
// Experiments and the CLI then fill any Options from JSON or YAML with
// `SetOptionsFromJson` / `SetOptionsFromYaml`; unknown keys are rejected by name.
// This header stays light: JSON and YAML parsing live in options.cc.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace crease {

class OptionVisitor {
 public:
  virtual ~OptionVisitor() = default;
  virtual void Field(const char* name, bool& value) = 0;
  virtual void Field(const char* name, int& value) = 0;
  virtual void Field(const char* name, int64_t& value) = 0;
  virtual void Field(const char* name, uint64_t& value) = 0;
  virtual void Field(const char* name, float& value) = 0;
  virtual void Field(const char* name, double& value) = 0;
  virtual void Field(const char* name, std::string& value) = 0;
  virtual void Field(const char* name, std::vector<int>& value) = 0;
  virtual void Field(const char* name, std::vector<double>& value) = 0;
  virtual void Field(const char* name, std::vector<std::string>& value) = 0;
};

namespace internal {
// Type-erased entry points (implemented in options.cc).
void SetFieldsFromJsonText(const std::string& json_text, const std::string& what,
                           void* options, void (*visit)(void*, OptionVisitor&));
void SetFieldsFromYamlText(const std::string& yaml_text, const std::string& what,
                           void* options, void (*visit)(void*, OptionVisitor&));
std::string FieldsToJsonText(void* options, void (*visit)(void*, OptionVisitor&), int indent);
std::vector<std::string> FieldNames(void* options, void (*visit)(void*, OptionVisitor&));
template <class Options>
void Visit(void* options, OptionVisitor& v) {
  static_cast<Options*>(options)->VisitFields(v);
}
}  // namespace internal

// Sets the fields named in a JSON object (text) on `options`, then calls
// options->Check(). Keys that are not fields, and values of the wrong type, throw
// Error naming `what` (a file name or "--set") and the key. Fields not named keep
// their current values. On error `options` is left unchanged.
template <class Options>
void SetOptionsFromJson(const std::string& json_text, const std::string& what, Options* options) {
  Options copy = *options;  // on any error `options` stays unchanged
  internal::SetFieldsFromJsonText(json_text, what, &copy, &internal::Visit<Options>);
  copy.Check();
  *options = std::move(copy);
}

// Same for a YAML mapping.
template <class Options>
void SetOptionsFromYaml(const std::string& yaml_text, const std::string& what, Options* options) {
  Options copy = *options;  // on any error `options` stays unchanged
  internal::SetFieldsFromYamlText(yaml_text, what, &copy, &internal::Visit<Options>);
  copy.Check();
  *options = std::move(copy);
}

// All fields as a JSON object (text), for reports and cache keys.
template <class Options>
std::string OptionsToJson(const Options& options, int indent = 2) {
  Options copy = options;
  return internal::FieldsToJsonText(&copy, &internal::Visit<Options>, indent);
}

// The field names of an Options struct, in visiting order.
template <class Options>
std::vector<std::string> OptionFieldNames() {
  Options o;
  return internal::FieldNames(&o, &internal::Visit<Options>);
}

// A YAML document as JSON text (scalars typed the way a person reads them; quoted
// scalars stay strings; mappings keep their order). Malformed YAML throws Error
// naming `what`.
std::string YamlToJsonText(const std::string& yaml_text, const std::string& what);

// Check helpers for Check(): throw Error("<struct>.<field> = <value> must be <bound>").
void CheckGt(const char* owner, const char* field, double value, double bound);
void CheckGe(const char* owner, const char* field, double value, double bound);
void CheckLt(const char* owner, const char* field, double value, double bound);
void CheckLe(const char* owner, const char* field, double value, double bound);
void CheckOneOf(const char* owner, const char* field, const std::string& value,
                const std::vector<std::string>& allowed);

}  // namespace crease
