#include "core/options.h"

#include <algorithm>
#include <array>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/test_util.h"

#include "core/error.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::TestDir;
using testing::WriteText;

// An Options struct written the way every stage writes one.
struct ExampleOptions {
  int num_ferns = 1280;      // K, Sec. 4.3
  double beta = 1000.0;      // shrinkage, Eq. 4
  float alpha = 0.005f;      // wrinkle threshold, Sec. 4.2
  bool parallel = true;
  std::string solver = "ldlt";
  std::vector<int> kernels = {6, 8};
  std::vector<double> weights;
  std::vector<std::string> regions = {"forehead"};
  uint64_t seed = 7;

  void VisitFields(OptionVisitor& v) {
    v.Field("num_ferns", num_ferns);
    v.Field("beta", beta);
    v.Field("alpha", alpha);
    v.Field("parallel", parallel);
    v.Field("solver", solver);
    v.Field("kernels", kernels);
    v.Field("weights", weights);
    v.Field("regions", regions);
    v.Field("seed", seed);
  }
  void Check() const {
    CheckGt("ExampleOptions", "num_ferns", num_ferns, 0);
    CheckGe("ExampleOptions", "beta", beta, 0.0);
    CheckOneOf("ExampleOptions", "solver", solver, {"ldlt", "cholmod"});
  }
};


TEST(Options, JsonSetsFieldsByName) {
  ExampleOptions o;
  SetOptionsFromJson(R"({"num_ferns": 80, "beta": 0, "solver": "cholmod", "kernels": [3, 9],
                         "regions": ["a", "b"], "seed": 18446744073709551615, "alpha": 0.01})",
                     "test.json", &o);
  EXPECT_EQ(o.num_ferns, 80);
  EXPECT_EQ(o.beta, 0.0);
  EXPECT_EQ(o.solver, "cholmod");
  EXPECT_EQ(o.kernels, (std::vector<int>{3, 9}));
  EXPECT_EQ(o.regions, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(o.seed, 18446744073709551615ULL);
  EXPECT_FLOAT_EQ(o.alpha, 0.01f);
  EXPECT_TRUE(o.parallel);  // untouched
}

TEST(Options, YamlSetsFieldsByName) {
  ExampleOptions o;
  SetOptionsFromYaml("num_ferns: 640\nparallel: false\nweights: [0.5, 1]\nsolver: \"ldlt\"\n", "cfg.yaml", &o);
  EXPECT_EQ(o.num_ferns, 640);
  EXPECT_FALSE(o.parallel);
  EXPECT_EQ(o.weights, (std::vector<double>{0.5, 1.0}));
  SetOptionsFromYaml("", "empty.yaml", &o);  // an empty document changes nothing
  EXPECT_EQ(o.num_ferns, 640);
}

TEST(Options, UnknownKeysAndWrongTypesAreRejectedByName) {
  ExampleOptions o;
  std::string e = ErrorOf([&] { SetOptionsFromJson(R"({"num_fern": 3})", "exp.json", &o); });
  EXPECT_NE(e.find("exp.json: unknown option 'num_fern'"), std::string::npos) << e;
  EXPECT_NE(e.find("num_ferns"), std::string::npos) << e;  // lists the known ones
  e = ErrorOf([&] { SetOptionsFromYaml("beta: lots\n", "exp.yaml", &o); });
  EXPECT_NE(e.find("option 'beta' must be a number"), std::string::npos) << e;
  e = ErrorOf([&] { SetOptionsFromJson(R"({"num_ferns": 2.5})", "x", &o); });
  EXPECT_NE(e.find("'num_ferns' must be an integer"), std::string::npos) << e;
  e = ErrorOf([&] { SetOptionsFromJson(R"({"num_ferns": 1e12})", "x", &o); });
  EXPECT_NE(e.find("in range"), std::string::npos) << e;
  e = ErrorOf([&] { SetOptionsFromJson(R"([1, 2])", "x", &o); });
  EXPECT_NE(e.find("expected a mapping"), std::string::npos) << e;
  e = ErrorOf([&] { SetOptionsFromJson(R"({"num_ferns": )", "bad.json", &o); });
  EXPECT_NE(e.find("bad.json: malformed JSON"), std::string::npos) << e;
}

// Issue 19: nested aliases ("billion laughs") expand to 9^9 nodes; the expansion
// stops at a limit with an error naming the file instead of allocating gigabytes.
TEST(Options, YamlAliasBombIsRefused) {
  std::string yaml = "a: &a [x, x, x, x, x, x, x, x, x]\n";
  for (char level = 'b'; level <= 'i'; ++level) {
    const char prev = static_cast<char>(level - 1);
    yaml += fmt::format("{}: &{} [", level, level);
    for (int k = 0; k < 9; ++k) yaml += fmt::format("{}*{}", k ? ", " : "", prev);
    yaml += "]\n";
  }
  const std::string e = ErrorOf([&] { YamlToJsonText(yaml, "bomb.yaml"); });
  EXPECT_NE(e.find("bomb.yaml: the YAML expands to more than"), std::string::npos) << e;
  // yaml-cpp loads an alias inside its own anchor as a cycle; converting it overflowed
  // the stack (a segmentation fault in `crease experiment run`) before the depth limit.
  for (const char* cycle : {"a: &a [1, *a]\n", "a: &a {x: 1, <<: *a}\n"}) {
    const std::string c = ErrorOf([&] { YamlToJsonText(cycle, "cycle.yaml"); });
    EXPECT_NE(c.find("cycle.yaml: the YAML nests deeper than 64 levels"), std::string::npos) << c;
  }
}

// YAML 1.1 merge keys (yaml-cpp leaves them to its users): "<<" adds the keys of the
// aliased mapping(s) that the map does not set itself, the first in a list winning;
// a quoted "<<" is an ordinary key, and anything but mappings is refused.
TEST(Options, YamlMergeKeysShareSettings) {
  const std::string yaml =
      "base: &b {x: 1, y: 2}\n"
      "other: &o {y: 5, z: 6}\n"
      "one: {<<: *b, y: 3}\n"
      "two:\n  <<: [*b, *o]\n  w: 0\n"
      "quoted: {\"<<\": 7}\n";
  const auto j = nlohmann::json::parse(YamlToJsonText(yaml, "m.yaml"));
  EXPECT_EQ(j["one"], nlohmann::json::parse(R"({"x": 1, "y": 3})"));
  EXPECT_EQ(j["two"], nlohmann::json::parse(R"({"w": 0, "x": 1, "y": 2, "z": 6})"));
  EXPECT_EQ(j["quoted"], nlohmann::json::parse(R"({"<<": 7})"));
  EXPECT_NE(ErrorOf([&] { YamlToJsonText("a: {<<: 3}\n", "s.yaml"); })
                .find("s.yaml:1:5: '<<' must name a mapping or a list of mappings"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { YamlToJsonText("b: &b {x: 1}\na: {<<: [*b, 2]}\n", "l.yaml"); })
                .find("l.yaml:2:5: '<<' must name a mapping"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { YamlToJsonText("b: &b {x: 1}\na:\n  <<: *b\n  <<: *b\n", "t.yaml"); })
                .find("key '<<' is set twice"),
            std::string::npos);
}

// Issue 19 (fuzz/options_yaml_fuzzer, fuzz/experiment_yaml_fuzzer): a list or mapping
// as a key was yaml-cpp's bad conversion (an internal error); numbers beyond a field's
// type were undefined conversions (UBSan in the sanitizer build). All name the file.
TEST(Options, KeysAndNumbersBeyondTheirTypesAreRefused) {
  ExampleOptions o;
  EXPECT_NE(ErrorOf([&] { SetOptionsFromYaml("beta: 1\n[num_ferns]: 3\n", "k.yaml", &o); })
                .find("k.yaml:2:1: a key must be a plain name, not a list or mapping"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromYaml("alpha: 1e300\n", "f.yaml", &o); })
                .find("f.yaml: option 'alpha' must be a number in float's range"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromYaml("seed: 18446744073709551616\n", "u.yaml", &o); })
                .find("u.yaml: option 'seed' must be an integer in range"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromYaml("kernels: [1, 4294967296]\n", "l.yaml", &o); })
                .find("l.yaml: option 'kernels' must be a list of integers in int's range"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromYaml("solver: \"\xC9\"\n", "u8.yaml", &o); })
                .find("u8.yaml: the YAML holds a string that is not UTF-8"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { YamlToJsonText("a: \x9B\n", "u8.yaml"); }).find("u8.yaml: the YAML holds a string that is not UTF-8"),
            std::string::npos);
  SetOptionsFromYaml("alpha: 3e38\nseed: 18446744073709549568\n", "ok.yaml", &o);
  EXPECT_EQ(o.alpha, 3e38f);
  EXPECT_EQ(o.seed, 18446744073709549568ull);
}

// Two nested option structs registering one key (issue 18: one YAML key silently
// set two weights) are refused, naming the key, whatever reads the options.
struct Colliding {
  ExampleOptions a, b;
  void VisitFields(OptionVisitor& v) {
    a.VisitFields(v);
    v.Field("other", b.beta);
    v.Field("beta", b.beta);
  }
  void Check() const {}
};

TEST(Options, TwoFieldsUnderOneKeyAreABug) {
  Colliding c;
  EXPECT_NE(ErrorOf([&] { SetOptionsFromJson(R"({"beta": 2})", "colliding", &c); }).find("'beta'"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { OptionFieldNames<Colliding>(); }).find("'beta'"), std::string::npos);
  EXPECT_NO_THROW(OptionFieldNames<ExampleOptions>());
}

TEST(Options, CheckIsCalledAndNamesTheField) {
  ExampleOptions o;
  std::string e = ErrorOf([&] { SetOptionsFromJson(R"({"num_ferns": 0})", "x", &o); });
  EXPECT_EQ(e, "ExampleOptions.num_ferns = 0 must be > 0");
  e = ErrorOf([&] { SetOptionsFromJson(R"({"solver": "qr"})", "x", &o); });
  EXPECT_EQ(e, "ExampleOptions.solver = 'qr' must be one of: ldlt, cholmod");
}

// Options with sections (issue 18): two nested structs that share field names, each
// under its own section, and a mode as an enum.
enum class Mode { kFast, kExact };
constexpr std::array<const char*, 2> OptionEnumNames(Mode) { return {"fast", "exact"}; }

struct FitOptions {
  double expression_prior_weight = 1.0;
  int max_iterations = 10;
  Mode mode = Mode::kFast;
  void VisitFields(OptionVisitor& v) {
    v.Field("expression_prior_weight", expression_prior_weight);
    v.Field("max_iterations", max_iterations);
    v.Field("mode", mode);
  }
  void Check() const {}
};

struct StageOptions {
  FitOptions fit, refinement;
  ExampleOptions inner;
  bool refine = true;
  void VisitFields(OptionVisitor& v) {
    v.Section("fit", fit);
    v.Section("refinement", refinement);
    v.Section("deep", inner);  // a section of a struct that is not a section itself
    v.Field("refine", refine);
  }
  void Check() const {}
};

TEST(Options, SectionsPrefixTheirKeysAndRoundTrip) {
  const std::vector<std::string> keys = OptionFieldNames<StageOptions>();
  EXPECT_EQ(keys.front(), "fit.expression_prior_weight");
  EXPECT_NE(std::find(keys.begin(), keys.end(), "refinement.mode"), keys.end());
  EXPECT_NE(std::find(keys.begin(), keys.end(), "deep.num_ferns"), keys.end());
  EXPECT_EQ(keys.back(), "refine");
  StageOptions a;
  a.fit.expression_prior_weight = 5.0;
  a.refinement.expression_prior_weight = 0.25;
  a.refinement.mode = Mode::kExact;
  a.inner.num_ferns = 3;
  const std::string text = OptionsToJson(a);
  EXPECT_NE(text.find(R"("refinement.mode": "exact")"), std::string::npos) << text;
  StageOptions b;
  SetOptionsFromJson(text, "roundtrip", &b);
  EXPECT_EQ(OptionsToJson(b), text);
  EXPECT_EQ(b.fit.expression_prior_weight, 5.0);
  EXPECT_EQ(b.refinement.expression_prior_weight, 0.25);
  EXPECT_EQ(b.refinement.mode, Mode::kExact);
  EXPECT_EQ(b.inner.num_ferns, 3);
}

TEST(Options, ASectionMayBeNestedOrDotted) {
  StageOptions nested, dotted, mixed;
  SetOptionsFromYaml("fit:\n  max_iterations: 3\nrefinement: {expression_prior_weight: 5, mode: exact}\n"
                     "deep: {num_ferns: 7}\n", "nested.yaml", &nested);
  SetOptionsFromYaml("fit.max_iterations: 3\nrefinement.expression_prior_weight: 5\nrefinement.mode: exact\n"
                     "deep.num_ferns: 7\n", "dotted.yaml", &dotted);
  SetOptionsFromJson(R"({"fit": {"max_iterations": 3}, "refinement.expression_prior_weight": 5,
                         "refinement": {"mode": "exact"}, "deep.num_ferns": 7})", "mixed.json", &mixed);
  EXPECT_EQ(OptionsToJson(nested), OptionsToJson(dotted));
  EXPECT_EQ(OptionsToJson(mixed), OptionsToJson(dotted));
  EXPECT_EQ(dotted.fit.max_iterations, 3);
  EXPECT_EQ(dotted.fit.expression_prior_weight, 1.0);  // the other section's field is untouched
  EXPECT_EQ(dotted.refinement.expression_prior_weight, 5.0);
  EXPECT_EQ(FlattenOptionKeys(R"({"a": {"b": {"c": 1}}, "d": 2})", "x"), R"({"a.b.c":1,"d":2})");
}

TEST(Options, AKeySetTwiceInAFileIsRefused) {
  StageOptions o;
  EXPECT_NE(ErrorOf([&] { SetOptionsFromYaml("fit:\n  max_iterations: 3\nfit.max_iterations: 4\n", "twice.yaml", &o); })
                .find("twice.yaml: option 'fit.max_iterations' is set twice"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromYaml("refine: true\nrefine: false\n", "same.yaml", &o); })
                .find("same.yaml:2:1: key 'refine' is set twice"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromJson(R"({"refine": true, "refine": false})", "same.json", &o); })
                .find("same.json: option 'refine' is set twice"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromJson(R"({"fit": {"mode": "fast"}, "fit.mode": "exact"})", "mix.json", &o); })
                .find("mix.json: option 'fit.mode' is set twice"),
            std::string::npos);
  EXPECT_EQ(o.fit.max_iterations, 10);  // unchanged on error
}

TEST(Options, UnknownAndOldKeysAreRefusedByName) {
  StageOptions o;
  std::string e = ErrorOf([&] { SetOptionsFromJson(R"({"fit.nope": 1})", "u.json", &o); });
  EXPECT_NE(e.find("u.json: unknown option 'fit.nope' (known options: fit.expression_prior_weight,"), std::string::npos) << e;
  // A key of a section given without it (as before sections) names the new key.
  e = ErrorOf([&] { SetOptionsFromJson(R"({"num_ferns": 1})", "old.json", &o); });
  EXPECT_EQ(e, "old.json: unknown option 'num_ferns': it is now 'deep.num_ferns'");
  e = ErrorOf([&] { SetOptionsFromJson(R"({"max_iterations": 1})", "old.json", &o); });
  EXPECT_EQ(e, "old.json: unknown option 'max_iterations': it is now 'fit.max_iterations' or 'refinement.max_iterations'");
  // A renamed key (RenamedOptionKeys): the old flat name with its hand-made prefix.
  e = ErrorOf([&] { SetOptionsFromJson(R"({"fit_expression_prior_weight": 1})", "old.yaml", &o); });
  EXPECT_EQ(e, "old.yaml: unknown option 'fit_expression_prior_weight': it is now 'fit.expression_prior_weight'");
  e = ErrorOf([&] { SetOptionsFromJson(R"({"refine_expression_prior_weight": 1})", "old.yaml", &o); });
  EXPECT_EQ(e, "old.yaml: unknown option 'refine_expression_prior_weight': it is now 'refinement.expression_prior_weight'");
  // Files crease wrote itself read old keys as their new ones.
  SetOptionsFromStoredJson(R"({"fit_expression_prior_weight": 7, "refine": false})", "model", &o);
  EXPECT_EQ(o.fit.expression_prior_weight, 7.0);
  EXPECT_FALSE(o.refine);
}

TEST(Options, AnEnumTakesItsNamesAndListsThemOnError) {
  EXPECT_EQ(ToString(Mode::kExact), "exact");
  EXPECT_EQ(FromString<Mode>("fast", "mode"), Mode::kFast);
  EXPECT_EQ(EnumNames<Mode>(), (std::vector<std::string>{"fast", "exact"}));
  EXPECT_EQ(ErrorOf([] { FromString<Mode>("slow", "fit.mode"); }), "fit.mode = 'slow' must be one of: fast, exact");
  StageOptions o;
  EXPECT_EQ(ErrorOf([&] { SetOptionsFromYaml("refinement: {mode: slow}\n", "m.yaml", &o); }),
            "m.yaml: option 'refinement.mode' must be one of: fast, exact, got \"slow\"");
  EXPECT_EQ(ErrorOf([&] { SetOptionsFromYaml("fit.mode: 3\n", "m.yaml", &o); }),
            "m.yaml: option 'fit.mode' must be one of: fast, exact, got 3");
}

TEST(Options, ToJsonRoundTrips) {
  ExampleOptions a;
  a.num_ferns = 5;
  a.weights = {0.1, 0.2};
  ExampleOptions b;
  SetOptionsFromJson(OptionsToJson(a), "roundtrip", &b);
  EXPECT_EQ(OptionsToJson(a), OptionsToJson(b));
  EXPECT_EQ(b.weights, a.weights);
}

// NAME=VALUE items (`--expression`, `--identity`, synth's expression specs): the
// first '=' splits, the value must be a whole finite number.
TEST(Options, NameValueItemsSplitAtTheFirstEqualsAndNeedAFiniteNumber) {
  EXPECT_EQ(ParseNameValue("jawOpen=0.25", "expression", "WEIGHT"), std::make_pair(std::string("jawOpen"), 0.25));
  EXPECT_EQ(ParseNameValue("3=-1e-3", "--identity", "VALUE"), std::make_pair(std::string("3"), -1e-3));
  const auto error = [](const std::string& item) {
    return ErrorOf([&] { ParseNameValue(item, "--expression", "VALUE"); });
  };
  EXPECT_EQ(error("jawOpen"), "--expression 'jawOpen': expected NAME=VALUE");
  EXPECT_EQ(error("a=b=2"), "--expression 'a=b=2': 'b=2' is not a number");
  EXPECT_EQ(error("a=0.5x"), "--expression 'a=0.5x': '0.5x' is not a number");
  EXPECT_EQ(error("a=inf"), "--expression 'a=inf': 'inf' is not a number");
  EXPECT_EQ(error("a="), "--expression 'a=': '' is not a number");
}

}  // namespace
}  // namespace crease
