#include "core/options.h"

#include <cmath>
#include <limits>
#include <set>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include "core/error.h"

namespace crease {
namespace internal {
namespace {

using nlohmann::json;

// Collects the field names, for the unknown-key check and its message.
class NameCollector final : public OptionVisitor {
 public:
  std::vector<std::string> names;
  void Field(const char* n, bool&) override { names.emplace_back(n); }
  void Field(const char* n, int&) override { names.emplace_back(n); }
  void Field(const char* n, int64_t&) override { names.emplace_back(n); }
  void Field(const char* n, uint64_t&) override { names.emplace_back(n); }
  void Field(const char* n, float&) override { names.emplace_back(n); }
  void Field(const char* n, double&) override { names.emplace_back(n); }
  void Field(const char* n, std::string&) override { names.emplace_back(n); }
  void Field(const char* n, std::vector<int>&) override { names.emplace_back(n); }
  void Field(const char* n, std::vector<double>&) override { names.emplace_back(n); }
  void Field(const char* n, std::vector<std::string>&) override { names.emplace_back(n); }
};

// The names of `visit`'s fields; two fields under one name (nested option structs
// that both register it, so that one key would set both) are an error (issue 18).
std::vector<std::string> UniqueFieldNames(void* options, void (*visit)(void*, OptionVisitor&),
                                          const std::string& what) {
  NameCollector c;
  visit(options, c);
  std::set<std::string> seen;
  for (const auto& n : c.names)
    Require(seen.insert(n).second,
            fmt::format("{}: two options register the key '{}' (a crease bug: one key would set both)", what, n));
  return c.names;
}

class JsonReader final : public OptionVisitor {
 public:
  JsonReader(const json& j, const std::string& what) : j_(j), what_(what) {}

  void Field(const char* n, bool& v) override {
    if (const json* x = Find(n)) {
      Expect(x->is_boolean(), n, "true or false");
      v = x->get<bool>();
    }
  }
  void Field(const char* n, int& v) override { Integer(n, v); }
  void Field(const char* n, int64_t& v) override { Integer(n, v); }
  void Field(const char* n, uint64_t& v) override { Integer(n, v); }
  void Field(const char* n, float& v) override {
    if (const json* x = Find(n)) {
      // A finite double beyond float's range has no float (undefined behaviour, issue 19).
      const double d = Number(n, *x);
      Expect(!std::isfinite(d) || std::abs(d) <= std::numeric_limits<float>::max(), n, "a number in float's range");
      v = static_cast<float>(d);
    }
  }
  void Field(const char* n, double& v) override {
    if (const json* x = Find(n)) v = Number(n, *x);
  }
  void Field(const char* n, std::string& v) override {
    if (const json* x = Find(n)) {
      Expect(x->is_string(), n, "a string");
      v = x->get<std::string>();
    }
  }
  void Field(const char* n, std::vector<int>& v) override { List(n, v); }
  void Field(const char* n, std::vector<double>& v) override { List(n, v); }
  void Field(const char* n, std::vector<std::string>& v) override { List(n, v); }

 private:
  const json* Find(const char* n) const {
    auto it = j_.find(n);
    return it == j_.end() ? nullptr : &*it;
  }
  void Expect(bool ok, const char* n, const char* expected) const {
    if (!ok) {
      throw Error(fmt::format("{}: option '{}' must be {}, got {}", what_, n, expected,
                              j_.at(n).dump()));
    }
  }
  double Number(const char* n, const json& x) const {
    Expect(x.is_number(), n, "a number");
    return x.get<double>();
  }
  template <class T>
  void Integer(const char* n, T& v) const {
    const json* x = Find(n);
    if (!x) return;
    Expect(x->is_number_integer() || (x->is_number_float() && std::floor(x->get<double>()) == x->get<double>()),
           n, "an integer");
    if (x->is_number_unsigned()) {
      const uint64_t u = x->get<uint64_t>();
      Expect(u <= static_cast<uint64_t>(std::numeric_limits<T>::max()), n, "an integer in range");
      v = static_cast<T>(u);
    } else {
      // max() + 1 is a power of two, exact as a double; int64's max() itself rounds up
      // to 2^63, which "<=" let through into an undefined conversion (issue 19).
      const double d = x->get<double>();
      Expect(d >= static_cast<double>(std::numeric_limits<T>::lowest()) &&
                 d < static_cast<double>(std::numeric_limits<T>::max()) + 1.0,
             n, "an integer in range");
      v = x->is_number_integer() ? static_cast<T>(x->get<int64_t>()) : static_cast<T>(d);
    }
  }
  template <class T>
  void List(const char* n, std::vector<T>& v) const {
    const json* x = Find(n);
    if (!x) return;
    Expect(x->is_array(), n, "a list");
    std::vector<T> out;
    for (const json& e : *x) {
      if constexpr (std::is_same_v<T, std::string>) {
        Expect(e.is_string(), n, "a list of strings");
        out.push_back(e.get<std::string>());
      } else if constexpr (std::is_same_v<T, int>) {
        Expect(e.is_number_integer() && e.get<int64_t>() >= std::numeric_limits<int>::lowest() &&
                   (e.is_number_unsigned() ? e.get<uint64_t>() <= static_cast<uint64_t>(std::numeric_limits<int>::max())
                                           : e.get<int64_t>() <= std::numeric_limits<int>::max()),
               n, "a list of integers in int's range");
        out.push_back(e.get<int>());
      } else {
        Expect(e.is_number(), n, "a list of numbers");
        out.push_back(e.get<T>());
      }
    }
    v = std::move(out);
  }
  const json& j_;
  const std::string& what_;
};

class JsonWriter final : public OptionVisitor {
 public:
  json j = json::object();
  void Field(const char* n, bool& v) override { j[n] = v; }
  void Field(const char* n, int& v) override { j[n] = v; }
  void Field(const char* n, int64_t& v) override { j[n] = v; }
  void Field(const char* n, uint64_t& v) override { j[n] = v; }
  void Field(const char* n, float& v) override { j[n] = v; }
  void Field(const char* n, double& v) override { j[n] = v; }
  void Field(const char* n, std::string& v) override { j[n] = v; }
  void Field(const char* n, std::vector<int>& v) override { j[n] = v; }
  void Field(const char* n, std::vector<double>& v) override { j[n] = v; }
  void Field(const char* n, std::vector<std::string>& v) override { j[n] = v; }
};

void SetFromJson(const json& j, const std::string& what, void* options,
                 void (*visit)(void*, OptionVisitor&)) {
  if (!j.is_object()) {
    throw Error(fmt::format("{}: expected a mapping of option names to values, got {}", what,
                            j.type_name()));
  }
  const std::vector<std::string> names = UniqueFieldNames(options, visit, what);
  const std::set<std::string> known(names.begin(), names.end());
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (!known.count(it.key())) {
      std::string list;
      for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
      throw Error(fmt::format("{}: unknown option '{}' (known options: {})", what, it.key(), list));
    }
  }
  JsonReader reader(j, what);
  visit(options, reader);
}

// The most nodes a YAML document may expand to, an alias counting again at every
// use. A few lines of nested aliases ("a: &a [x,x,...]", "b: &b [*a,*a,...]", ...)
// expand to 9^9 nodes and gigabytes; crease's largest configs have a few hundred.
constexpr size_t kMaxYamlNodes = 100'000;

// YAML scalars carry no type; convert them the way a person reads them. `count`
// counts the nodes expanded so far (see kMaxYamlNodes).
template <class Json>
Json YamlToJson(const YAML::Node& node, const std::string& what, size_t* count) {
  if (++*count > kMaxYamlNodes) {
    throw Error(fmt::format("{}: the YAML expands to more than {} nodes (nested aliases?)", what,
                            kMaxYamlNodes));
  }
  switch (node.Type()) {
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined:
      return nullptr;
    case YAML::NodeType::Scalar: {
      const std::string s = node.Scalar();
      if (node.Tag() == "!") return s;  // quoted: always a string
      if (s == "true" || s == "True" || s == "false" || s == "False") return s[0] == 't' || s[0] == 'T';
      try {
        size_t pos = 0;
        const long long i = std::stoll(s, &pos);
        if (pos == s.size()) return i;
      } catch (...) {
      }
      try {
        size_t pos = 0;
        const double d = std::stod(s, &pos);
        if (pos == s.size()) return d;
      } catch (...) {
      }
      return s;
    }
    case YAML::NodeType::Sequence: {
      Json a = Json::array();
      for (const auto& e : node) a.push_back(YamlToJson<Json>(e, what, count));
      return a;
    }
    case YAML::NodeType::Map: {
      Json o = Json::object();
      for (const auto& kv : node) {
        // A list or mapping as a key ("[a]: 1") was yaml-cpp's bad conversion, an
        // internal error (issue 19).
        if (!kv.first.IsScalar() && !kv.first.IsNull()) {
          throw Error(fmt::format("{}:{}:{}: a key must be a plain name, not a list or mapping", what,
                                  kv.first.Mark().line + 1, kv.first.Mark().column + 1));
        }
        o[kv.first.as<std::string>()] = YamlToJson<Json>(kv.second, what, count);
      }
      return o;
    }
  }
  return nullptr;
}

template <class Json = json>
Json LoadYaml(const std::string& yaml_text, const std::string& what) {
  YAML::Node node;
  try {
    node = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    throw Error(fmt::format("{}: malformed YAML: {}", what, e.what()));
  }
  size_t count = 0;
  Json j = YamlToJson<Json>(node, what, &count);
  // Bytes that are not UTF-8 became JSON strings that nlohmann refuses to write:
  // type_error 316, an internal error (issue 19). They come from the text, or from
  // yaml-cpp itself on valid UTF-8 holding a NUL byte (fuzz/regressions/
  // experiment_yaml_fuzzer/nul_byte.yaml). Writing the result once finds them.
  try {
    (void)j.dump();
  } catch (const nlohmann::json::type_error& e) {
    throw Error(fmt::format("{}: the YAML holds a string that is not UTF-8 ({})", what, e.what()));
  }
  return j;
}

}  // namespace

void SetFieldsFromJsonText(const std::string& json_text, const std::string& what, void* options,
                           void (*visit)(void*, OptionVisitor&)) {
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for 1e400 (issue 19)
    throw Error(fmt::format("{}: malformed JSON: {}", what, e.what()));
  }
  SetFromJson(j, what, options, visit);
}

void SetFieldsFromYamlText(const std::string& yaml_text, const std::string& what, void* options,
                           void (*visit)(void*, OptionVisitor&)) {
  json j = LoadYaml(yaml_text, what);
  if (j.is_null()) j = json::object();  // an empty document sets nothing
  SetFromJson(j, what, options, visit);
}

std::vector<std::string> FieldNames(void* options, void (*visit)(void*, OptionVisitor&)) {
  return UniqueFieldNames(options, visit, "options");
}

std::string YamlTextToJsonText(const std::string& yaml_text, const std::string& what) {
  return LoadYaml<nlohmann::ordered_json>(yaml_text, what).dump();
}

std::string FieldsToJsonText(void* options, void (*visit)(void*, OptionVisitor&), int indent) {
  JsonWriter w;
  visit(options, w);
  return w.j.dump(indent);
}

}  // namespace internal

std::string YamlToJsonText(const std::string& yaml_text, const std::string& what) {
  return internal::YamlTextToJsonText(yaml_text, what);
}

namespace {
[[noreturn]] void Fail(const char* owner, const char* field, double value, const char* op,
                       double bound) {
  throw Error(fmt::format("{}.{} = {} must be {} {}", owner, field, value, op, bound));
}
}  // namespace

void CheckGt(const char* o, const char* f, double v, double b) { if (!(v > b)) Fail(o, f, v, ">", b); }
void CheckGe(const char* o, const char* f, double v, double b) { if (!(v >= b)) Fail(o, f, v, ">=", b); }
void CheckLt(const char* o, const char* f, double v, double b) { if (!(v < b)) Fail(o, f, v, "<", b); }
void CheckLe(const char* o, const char* f, double v, double b) { if (!(v <= b)) Fail(o, f, v, "<=", b); }

void CheckOneOf(const char* owner, const char* field, const std::string& value,
                const std::vector<std::string>& allowed) {
  for (const auto& a : allowed) {
    if (a == value) return;
  }
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  throw Error(fmt::format("{}.{} = '{}' must be one of: {}", owner, field, value, list));
}

}  // namespace crease
