// Options by key. Every stage's `XxxOptions` struct
//   * gives each field a default equal to the paper's value, commented with its
//     unit and paper symbol (`int num_ferns = 1280;  // K, Sec. 4.3`),
//   * lists its fields once in `void VisitFields(OptionVisitor& v)`
//     (`v.Field("num_ferns", num_ferns);` — the key is the field name, without a
//     prefix that only repeated its section: MesoscopicOptions::meso_scale is
//     `scale`), and its nested Options structs as sections
//     (`v.Section("pca", pca);` — their keys become `pca.dimensions`, …, as COLMAP's
//     `SiftExtraction.max_num_features`; sections nest: `tracker.fit.max_iterations`),
//   * takes a mode (one of a fixed set of strings) as an enum with
//     `OptionEnumNames` beside it (see `ToString` / `FromString` below),
//   * rejects invalid values in `void Check() const` by throwing crease::Error with a
//     message naming the field and the violated bound (use the CheckXX helpers below).
// Experiments and the CLI then fill any Options from JSON or YAML with
// `SetOptionsFromJson` / `SetOptionsFromYaml`.
//
// Keys in files. The canonical form of a key is dotted (`refinement.lk_window`), which
// is what OptionsToJson writes, what `--set` and experiment sweeps take, and what
// cache keys hash. A file may also write a section as a nested mapping
// (`refinement: {lk_window: 15}`), or mix both; it is flattened to dotted keys first.
// Refused, naming the key and the file: a key set twice (twice in one mapping, or
// once nested and once dotted), an unknown key, and a key from before sections
// (`fit_expression_prior_weight`), whose error names its new key (the table of
// renamed keys is RenamedOptionKeys in options.cc). Two fields of one struct that
// register the same key are a crease bug, refused whenever the struct is visited.
// This header stays light: JSON and YAML parsing live in options.cc.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace crease {

// An enum option E has, beside it, `constexpr std::array<const char*, N>
// OptionEnumNames(E)` naming its values 0 … N−1 in order (found by argument lookup).
template <class E>
concept OptionEnum = std::is_enum_v<E> && requires(E e) { OptionEnumNames(e); };

namespace internal {
// Throws Error("<what> = '<text>' must be one of: a, b, c").
[[noreturn]] void ThrowNotOneOf(const std::string& what, const std::string& text,
                                const std::vector<std::string>& allowed);
}  // namespace internal

// The names of an enum option's values, in order.
template <OptionEnum E>
std::vector<std::string> EnumNames() {
  const auto names = OptionEnumNames(E{});
  return {names.begin(), names.end()};
}

// An enum option's value as its config string.
template <OptionEnum E>
std::string ToString(E value) {
  const auto names = OptionEnumNames(E{});
  const auto i = static_cast<size_t>(value);
  return i < names.size() ? names[i] : "?";
}

// The value named `text`; any other text throws Error naming `what` and listing the
// allowed values.
template <OptionEnum E>
E FromString(const std::string& text, const std::string& what) {
  const auto names = OptionEnumNames(E{});
  for (size_t i = 0; i < names.size(); ++i)
    if (text == names[i]) return static_cast<E>(i);
  internal::ThrowNotOneOf(what, text, EnumNames<E>());
}

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

  // An enum field, read and written as one of its names.
  template <OptionEnum E>
  void Field(const char* name, E& value) {
    std::string text = ToString(value);
    EnumField(name, text, EnumNames<E>());
    value = FromString<E>(text, Key(name));
  }

  // A nested Options struct: its keys become "<name>.<key>".
  template <class Options>
  void Section(const char* name, Options& options) {
    const size_t size = prefix_.size();
    prefix_ += name;
    prefix_ += '.';
    options.VisitFields(*this);
    prefix_.resize(size);
  }

 protected:
  // The full key of field `name` in the current section.
  std::string Key(const char* name) const { return prefix_ + name; }
  // An enum field as its name; readers refuse a name not in `allowed`.
  virtual void EnumField(const char* name, std::string& value, const std::vector<std::string>& allowed) {
    (void)allowed;
    Field(name, value);
  }

 private:
  std::string prefix_;  // "section.subsection." while visiting a section
};

namespace internal {
// Type-erased entry points (implemented in options.cc).
void SetFieldsFromJsonText(const std::string& json_text, const std::string& what,
                           void* options, void (*visit)(void*, OptionVisitor&));
void SetFieldsFromYamlText(const std::string& yaml_text, const std::string& what,
                           void* options, void (*visit)(void*, OptionVisitor&));
std::string FieldsToJsonText(void* options, void (*visit)(void*, OptionVisitor&), int indent);
std::vector<std::string> FieldNames(void* options, void (*visit)(void*, OptionVisitor&));
std::string UpgradeOldKeys(const std::string& json_text, const std::string& what,
                           const std::vector<std::string>& known);
template <class Options>
void Visit(void* options, OptionVisitor& v) {
  static_cast<Options*>(options)->VisitFields(v);
}
}  // namespace internal

// Sets the fields named in a JSON object (text) on `options`, then calls
// options->Check(). Keys that are not fields (old keys with their new name), keys
// set twice, and values of the wrong type, throw Error naming `what` (a file name
// or "--set") and the key. Sections may be nested objects or dotted keys. Fields not named keep
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

// The keys of an Options struct (below).
template <class Options>
std::vector<std::string> OptionFieldNames();

// SetOptionsFromJson for options crease wrote itself (model and training-pair files):
// a key from before option sections is read as its new key, so files written before
// keep loading.
template <class Options>
void SetOptionsFromStoredJson(const std::string& json_text, const std::string& what, Options* options) {
  SetOptionsFromJson(internal::UpgradeOldKeys(json_text, what, OptionFieldNames<Options>()), what, options);
}

// All fields as a JSON object (text) with dotted keys, for reports and cache keys.
template <class Options>
std::string OptionsToJson(const Options& options, int indent = 2) {
  Options copy = options;
  return internal::FieldsToJsonText(&copy, &internal::Visit<Options>, indent);
}

// The keys of an Options struct (dotted), in visiting order; two fields under one
// key throw Error.
template <class Options>
std::vector<std::string> OptionFieldNames() {
  Options o;
  return internal::FieldNames(&o, &internal::Visit<Options>);
}

// A YAML document as JSON text (scalars typed the way a person reads them; quoted
// scalars stay strings; mappings keep their order). Malformed YAML throws Error
// naming `what`.
std::string YamlToJsonText(const std::string& yaml_text, const std::string& what);

// A JSON object of options (text) with its sections flattened to dotted keys
// (`{"fit": {"seed": 1}}` → `{"fit.seed": 1}`); a key set twice throws Error naming
// `what` and the key.
std::string FlattenOptionKeys(const std::string& json_text, const std::string& what);

// One "NAME=VALUE" item of a command line or a spec: the name and the finite number
// after the first '='. Errors read "<what> '<item>': expected NAME=<value_word>" and
// "<what> '<item>': '<value>' is not a number".
std::pair<std::string, double> ParseNameValue(const std::string& item, const std::string& what,
                                              const std::string& value_word);

// Check helpers for Check(): throw Error("<struct>.<field> = <value> must be <bound>").
void CheckGt(const char* owner, const char* field, double value, double bound);
void CheckGe(const char* owner, const char* field, double value, double bound);
void CheckLt(const char* owner, const char* field, double value, double bound);
void CheckLe(const char* owner, const char* field, double value, double bound);
void CheckOneOf(const char* owner, const char* field, const std::string& value,
                const std::vector<std::string>& allowed);

}  // namespace crease
