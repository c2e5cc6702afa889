#include "core/options.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <limits>
#include <optional>
#include <set>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include "core/error.h"

namespace crease {
namespace internal {
namespace {

using nlohmann::json;

// Collects the keys, for the unknown-key check and its message.
class NameCollector final : public OptionVisitor {
 public:
  std::vector<std::string> names;
  void Field(const char* n, bool&) override { names.push_back(Key(n)); }
  void Field(const char* n, int&) override { names.push_back(Key(n)); }
  void Field(const char* n, int64_t&) override { names.push_back(Key(n)); }
  void Field(const char* n, uint64_t&) override { names.push_back(Key(n)); }
  void Field(const char* n, float&) override { names.push_back(Key(n)); }
  void Field(const char* n, double&) override { names.push_back(Key(n)); }
  void Field(const char* n, std::string&) override { names.push_back(Key(n)); }
  void Field(const char* n, std::vector<int>&) override { names.push_back(Key(n)); }
  void Field(const char* n, std::vector<double>&) override { names.push_back(Key(n)); }
  void Field(const char* n, std::vector<std::string>&) override { names.push_back(Key(n)); }
};

// The keys of `visit`'s fields; two fields under one key (two nested option structs
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

// Keys renamed when options got sections (issue 18): old flat key → the end of its
// new key. A field that only moved into a section, its name unchanged
// (`lk_window` → `refinement.lk_window`), needs no entry.
const std::map<std::string, std::string>& RenamedOptionKeys() {
  static const std::map<std::string, std::string> renamed = {
      {"pca_dimensions", "pca.dimensions"},
      {"patch_size", "patch.size"},
      {"patch_density", "patch.density"},
      {"patch_max_outside_fraction", "patch.max_outside_fraction"},
      {"fern_depth", "ferns.depth"},
      {"fern_seed", "ferns.seed"},
      {"fern_threshold_rule", "ferns.threshold_rule"},
      {"fern_threshold_range", "ferns.threshold_range"},
      {"fern_pair_selection", "ferns.pair_selection"},
      {"fern_texture_normalization", "ferns.texture_normalization"},
      {"fit_seed", "fit.seed"},
      {"fit_expression_prior_weight", "fit.expression_prior_weight"},
      {"fit_temporal_expression_weight", "fit.temporal_expression_weight"},
      {"fit_temporal_rotation_weight", "fit.temporal_rotation_weight"},
      {"fit_temporal_translation_weight", "fit.temporal_translation_weight"},
      {"fit_temporal_depth_weight", "fit.temporal_depth_weight"},
      {"fit_identity_prior_weight", "fit.identity_prior_weight"},
      {"fit_max_iterations", "fit.max_iterations"},
      {"fit_initial_max_iterations", "fit.initial_max_iterations"},
      {"fit_function_tolerance", "fit.function_tolerance"},
      {"fit_linear_solver", "fit.linear_solver"},
      {"refine_expression_prior_weight", "refinement.expression_prior_weight"},
      {"fill_resolution", "fill.resolution"},
      {"fill_boundary", "fill.boundary"},
      {"fill_smoothing_sweeps", "fill.smoothing_sweeps"},
      {"fill_band_texels", "fill.band_texels"},
      {"meso_small_kernel", "mesoscopic.small_kernel"},
      {"meso_large_kernel", "mesoscopic.large_kernel"},
      {"meso_scale", "mesoscopic.scale"},
      {"meso_reference_resolution", "mesoscopic.reference_resolution"},
      {"hifi_mesh_resolution", "hifi.resolution"},
      {"appearance_ceiling", "appearance.enabled"},
      {"appearance_window", "appearance.window"},
      {"appearance_window_step", "appearance.window_step"},
      {"appearance_stride", "appearance.stride"},
      {"appearance_ridge", "appearance.ridge"},
      {"appearance_reference_frames", "appearance.reference_frames"},
      {"appearance_block", "appearance.block"},
  };
  return renamed;
}

bool EndsWithKey(const std::string& key, const std::string& tail) {
  return key == tail || (key.size() > tail.size() && key.ends_with(tail) && key[key.size() - tail.size() - 1] == '.');
}

// Whether `key` is what renamed key `tail` ("section.leaf") became: a key ending in
// it, or "leaf" alone in the section's own struct (AppearanceCeilingOptions' `enabled`).
bool IsRenamedTo(const std::string& key, const std::string& tail) {
  return EndsWithKey(key, tail) || key == tail.substr(tail.find('.') + 1);
}

// The known keys an old flat key became: those ending in its renamed tail or in
// the old key itself (a field moved into a section).
std::vector<std::string> NewKeysOf(const std::string& old_key, const std::vector<std::string>& known) {
  const auto it = RenamedOptionKeys().find(old_key);
  std::vector<std::string> out;
  for (const auto& k : known)
    if ((it != RenamedOptionKeys().end() && IsRenamedTo(k, it->second)) || EndsWithKey(k, old_key)) out.push_back(k);
  return out;
}

[[noreturn]] void ThrowUnknownKey(const std::string& key, const std::vector<std::string>& known,
                                  const std::string& what) {
  const std::vector<std::string> now = NewKeysOf(key, known);
  if (!now.empty())
    throw Error(fmt::format("{}: unknown option '{}': it is now '{}'", what, key, fmt::join(now, "' or '")));
  throw Error(fmt::format("{}: unknown option '{}' (known options: {})", what, key, fmt::join(known, ", ")));
}

// `j`'s sections (nested objects) as dotted keys into `out`; a key set twice throws.
void FlattenInto(const json& j, const std::string& prefix, const std::string& what, json* out) {
  for (const auto& [k, v] : j.items()) {
    const std::string key = prefix + k;
    if (v.is_object()) {
      FlattenInto(v, key + ".", what, out);
      continue;
    }
    Require(!out->contains(key), fmt::format("{}: option '{}' is set twice (nested and dotted?)", what, key));
    (*out)[key] = v;
  }
}

json Flatten(const json& j, const std::string& what) {
  json out = json::object();
  FlattenInto(j, "", what, &out);
  return out;
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

 protected:
  void EnumField(const char* n, std::string& v, const std::vector<std::string>& allowed) override {
    const json* x = Find(n);
    if (!x) return;
    const bool ok = x->is_string() && std::find(allowed.begin(), allowed.end(), x->get<std::string>()) != allowed.end();
    Expect(ok, n, fmt::format("one of: {}", fmt::join(allowed, ", ")).c_str());
    v = x->get<std::string>();
  }

 private:
  // `j_` has dotted keys (Flatten); `n` is a field of the current section.
  const json* Find(const char* n) const {
    auto it = j_.find(Key(n));
    return it == j_.end() ? nullptr : &*it;
  }
  void Expect(bool ok, const char* n, const char* expected) const {
    if (!ok) {
      throw Error(fmt::format("{}: option '{}' must be {}, got {}", what_, Key(n), expected,
                              j_.at(Key(n)).dump()));
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
  json j = json::object();  // dotted keys
  void Field(const char* n, bool& v) override { j[Key(n)] = v; }
  void Field(const char* n, int& v) override { j[Key(n)] = v; }
  void Field(const char* n, int64_t& v) override { j[Key(n)] = v; }
  void Field(const char* n, uint64_t& v) override { j[Key(n)] = v; }
  void Field(const char* n, float& v) override { j[Key(n)] = v; }
  void Field(const char* n, double& v) override { j[Key(n)] = v; }
  void Field(const char* n, std::string& v) override { j[Key(n)] = v; }
  void Field(const char* n, std::vector<int>& v) override { j[Key(n)] = v; }
  void Field(const char* n, std::vector<double>& v) override { j[Key(n)] = v; }
  void Field(const char* n, std::vector<std::string>& v) override { j[Key(n)] = v; }
};

void SetFromJson(const json& nested, const std::string& what, void* options,
                 void (*visit)(void*, OptionVisitor&)) {
  if (!nested.is_object()) {
    throw Error(fmt::format("{}: expected a mapping of option names to values, got {}", what,
                            nested.type_name()));
  }
  const json j = Flatten(nested, what);
  const std::vector<std::string> names = UniqueFieldNames(options, visit, what);
  const std::set<std::string> known(names.begin(), names.end());
  for (auto it = j.begin(); it != j.end(); ++it)
    if (!known.count(it.key())) ThrowUnknownKey(it.key(), names, what);
  JsonReader reader(j, what);
  visit(options, reader);
}

// Parses JSON text; a key twice in one object throws Error naming it (nlohmann
// keeps the last silently).
json ParseJsonOnceEach(const std::string& text, const std::string& what) {
  std::vector<std::set<std::string>> open;  // keys seen in each open object
  const json::parser_callback_t check = [&](int, json::parse_event_t event, json& parsed) {
    if (event == json::parse_event_t::object_start) open.emplace_back();
    if (event == json::parse_event_t::object_end) open.pop_back();
    if (event == json::parse_event_t::key && !open.back().insert(parsed.get<std::string>()).second)
      throw Error(fmt::format("{}: option '{}' is set twice", what, parsed.get<std::string>()));
    return true;
  };
  return json::parse(text, check);
}

// The most nodes a YAML document may expand to, an alias counting again at every
// use. A few lines of nested aliases ("a: &a [x,x,...]", "b: &b [*a,*a,...]", ...)
// expand to 9^9 nodes and gigabytes; crease's largest configs have a few hundred.
constexpr size_t kMaxYamlNodes = 100'000;
// The deepest a YAML document may nest. yaml-cpp loads an alias inside its own anchor
// ("a: &a [1, *a]") as a cycle, which no node count stops before the stack overflows.
constexpr int kMaxYamlDepth = 64;

template <class Json>
Json YamlToJson(const YAML::Node& node, const std::string& what, size_t* count, int depth);

// YAML 1.1's merge key, which yaml-cpp leaves to its users: "<<: *base" (or a list of
// aliases) adds each key of the named mapping(s) that `o` does not set itself, the
// first mapping in the list winning. Configs use it to share settings between
// variants (experiments/detail-levers.yaml). `at` is the "<<" key, for the message.
template <class Json>
void MergeYamlKeys(Json* o, const YAML::Node& merge, const YAML::Node& at, const std::string& what,
                   size_t* count, int depth) {
  const auto fail = [&] {
    throw Error(fmt::format("{}:{}:{}: '<<' must name a mapping or a list of mappings", what,
                            at.Mark().line + 1, at.Mark().column + 1));
  };
  std::vector<YAML::Node> maps;
  if (merge.IsMap()) maps.push_back(merge);
  else if (merge.IsSequence()) for (const auto& m : merge) maps.push_back(m);
  else fail();
  for (const auto& m : maps) {
    if (!m.IsMap()) fail();
    const Json base = YamlToJson<Json>(m, what, count, depth);
    for (auto it = base.begin(); it != base.end(); ++it) {
      if (!o->contains(it.key())) (*o)[it.key()] = it.value();
    }
  }
}

// YAML scalars carry no type; convert them the way a person reads them. `count`
// counts the nodes expanded so far (see kMaxYamlNodes), `depth` the node's nesting.
template <class Json>
Json YamlToJson(const YAML::Node& node, const std::string& what, size_t* count, int depth) {
  if (++*count > kMaxYamlNodes) {
    throw Error(fmt::format("{}: the YAML expands to more than {} nodes (nested aliases?)", what,
                            kMaxYamlNodes));
  }
  if (depth > kMaxYamlDepth) {
    throw Error(fmt::format("{}: the YAML nests deeper than {} levels (an alias inside its own anchor?)", what,
                            kMaxYamlDepth));
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
      for (const auto& e : node) a.push_back(YamlToJson<Json>(e, what, count, depth + 1));
      return a;
    }
    case YAML::NodeType::Map: {
      Json o = Json::object();
      // "<<" and what it names, merged after the map's own keys. std::optional: a
      // yaml-cpp Node's operator= writes through to the node it refers to.
      std::optional<std::pair<YAML::Node, YAML::Node>> merge;
      for (const auto& kv : node) {
        // A list or mapping as a key ("[a]: 1") was yaml-cpp's bad conversion, an
        // internal error (issue 19).
        if (!kv.first.IsScalar() && !kv.first.IsNull()) {
          throw Error(fmt::format("{}:{}:{}: a key must be a plain name, not a list or mapping", what,
                                  kv.first.Mark().line + 1, kv.first.Mark().column + 1));
        }
        const std::string key = kv.first.as<std::string>();
        const bool is_merge = key == "<<" && kv.first.Tag() != "!";  // a quoted "<<" is a plain key
        if (is_merge && !merge) {
          merge.emplace(kv.first, kv.second);
          continue;
        }
        if (o.contains(key) || is_merge) {
          throw Error(fmt::format("{}:{}:{}: key '{}' is set twice", what, kv.first.Mark().line + 1,
                                  kv.first.Mark().column + 1, key));
        }
        o[key] = YamlToJson<Json>(kv.second, what, count, depth + 1);
      }
      if (merge) MergeYamlKeys(&o, merge->second, merge->first, what, count, depth + 1);
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
  Json j = YamlToJson<Json>(node, what, &count, 0);
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
    j = ParseJsonOnceEach(json_text, what);
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

std::string UpgradeOldKeys(const std::string& json_text, const std::string& what,
                           const std::vector<std::string>& known) {
  const std::set<std::string> current(known.begin(), known.end());
  json out = json::object();
  const json stored = Flatten(ParseJsonOnceEach(json_text, what), what);
  for (const auto& [k, v] : stored.items()) {
    const std::vector<std::string> now = current.count(k) ? std::vector<std::string>{} : NewKeysOf(k, known);
    out[now.size() == 1 ? now[0] : k] = v;
  }
  return out.dump();
}

std::vector<std::string> FieldNames(void* options, void (*visit)(void*, OptionVisitor&)) {
  return UniqueFieldNames(options, visit, "options");
}

std::string FlattenOptionKeysText(const std::string& json_text, const std::string& what) {
  return Flatten(json::parse(json_text), what).dump();
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

std::string FlattenOptionKeys(const std::string& json_text, const std::string& what) {
  return internal::FlattenOptionKeysText(json_text, what);
}

namespace {
[[noreturn]] void Fail(const char* owner, const char* field, double value, const char* op,
                       double bound) {
  throw Error(fmt::format("{}.{} = {} must be {} {}", owner, field, value, op, bound));
}
}  // namespace

std::pair<std::string, double> ParseNameValue(const std::string& item, const std::string& what,
                                              const std::string& value_word) {
  const size_t eq = item.find('=');
  Require(eq != std::string::npos, fmt::format("{} '{}': expected NAME={}", what, item, value_word));
  const std::string text = item.substr(eq + 1);
  try {
    size_t used = 0;
    const double value = std::stod(text, &used);
    if (used == text.size() && std::isfinite(value)) return {item.substr(0, eq), value};
  } catch (const std::exception&) {
  }
  throw Error(fmt::format("{} '{}': '{}' is not a number", what, item, text));
}

void CheckGt(const char* o, const char* f, double v, double b) { if (!(v > b)) Fail(o, f, v, ">", b); }
void CheckGe(const char* o, const char* f, double v, double b) { if (!(v >= b)) Fail(o, f, v, ">=", b); }
void CheckLt(const char* o, const char* f, double v, double b) { if (!(v < b)) Fail(o, f, v, "<", b); }
void CheckLe(const char* o, const char* f, double v, double b) { if (!(v <= b)) Fail(o, f, v, "<=", b); }

void CheckOneOf(const char* owner, const char* field, const std::string& value,
                const std::vector<std::string>& allowed) {
  for (const auto& a : allowed) {
    if (a == value) return;
  }
  internal::ThrowNotOneOf(fmt::format("{}.{}", owner, field), value, allowed);
}

namespace internal {
void ThrowNotOneOf(const std::string& what, const std::string& text, const std::vector<std::string>& allowed) {
  throw Error(fmt::format("{} = '{}' must be one of: {}", what, text, fmt::join(allowed, ", ")));
}
}  // namespace internal

}  // namespace crease
