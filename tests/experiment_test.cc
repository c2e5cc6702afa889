// The experiment runner (eval/experiment.h): config checking, sweeps, shards,
// cache keys, resume. Stages run through a fake executor that writes small,
// deterministic outputs (the real commands are exercised by cli_test.sh).
#include "eval/experiment.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <algorithm>
#include <chrono>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include "core/error.h"
#include "tests/test_util.h"
#include "core/json_io.h"
#include "core/options.h"
#include "pipeline/capture/capture.h"
#include "pipeline/training/trainer.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const char* kConfig = R"(
name: toy
title: A toy sweep
paper: Sec. 4.3
seeds: 2
dataset:
  training_actors: 2
  test_actors: 2
  frames: 12
training:
  ferns:
    num_ferns: 1280
sweep:
  mode: list
  values:
    training.ferns.num_ferns: [80, 320]
    capture.detail.wrinkle_frames: [5, 10]
profiles:
  quick:
    set:
      dataset.frames: 6
    sweep:
      training.ferns.num_ferns: [40]
    seeds: 1
claims:
  - id: c
    paper: something
    check: {less: [tracking.refined_px, tracking.coarse_px]}
)";

fs::path TempDir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("crease_experiment_test_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string OutputAfter(const std::vector<std::string>& argv, const std::string& flag) {
  for (size_t i = 0; i + 1 < argv.size(); ++i)
    if (argv[i] == flag) return argv[i + 1];
  return "";
}

// Writes what each stage's reader expects: the model report and eval.json, with
// numbers derived from the command (so a changed input changes the result).
int FakeExecute(const std::vector<std::string>& argv, const fs::path& log) {
  std::ofstream(log) << "fake " << argv.size() << " args\n";
  std::string all;  // the command without its paths (they name the cache folder)
  for (const auto& a : argv)
    if (a.find('/') == std::string::npos) all += a + " ";
  const double h = static_cast<double>(std::hash<std::string>{}(all) % 1000) / 1000.0;
  if (argv[0] == "train") {
    const fs::path report = OutputAfter(argv, "--report");
    fs::create_directories(report);
    if (OutputAfter(argv, "--pairs").empty()) {  // extraction only
      EXPECT_FALSE(OutputAfter(argv, "--save-pairs").empty());
      WriteJsonFile(report / "report.json", json{{"training_pairs", 100}, {"seconds", 50.0 + h}});
    } else {
      WriteJsonFile(report / "report.json", json{{"pca_energy", {0.5, 0.8, 0.9, 1.0}}, {"seconds", 1.5 + h}});
    }
  } else if (argv[0] == "model" && argv[1] == "loao") {
    WriteJsonFile(OutputAfter(argv, "--json"),
                  json{{"mean", {{"held_out", {{"ferns", {{"correlation", 0.3 + 0.1 * h}}}}}}}});
  } else if (argv[0] == "eval") {
    const fs::path out = OutputAfter(argv, "-o");
    std::ofstream(out / "error_vectors.png") << "png";
    WriteJsonFile(out / "eval.json",
                  json{{"tracking", {{"coarse_px", 6.0 + h}, {"refined_px", 5.0 + h}}},
                       {"per_frame", json::array({json{{"frame", 0}, {"refined_px", 1.0}}, json{{"frame", 1}, {"refined_px", nullptr}}})}});
  }
  return 0;
}

// A stage process dies with its runner, even when the runner is killed with
// SIGKILL (issue 19: a killed `crease experiment run` left its stage writing into
// the cache).
TEST(Experiment, AStageDiesWithItsRunner) {
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / ("stage_dies_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string pid_file = (dir / "pid").string();
  const pid_t runner = fork();
  ASSERT_GE(runner, 0);
  if (runner == 0) {  // the runner: waits on a stage that would sleep for a minute
    SubprocessExecutor("/bin/sh")({"-c", "echo $$ > " + pid_file + ".tmp && mv " + pid_file + ".tmp " + pid_file +
                                             " && exec sleep 60"},
                                  dir / "stage.log");
    _exit(0);
  }
  pid_t stage = 0;
  for (int i = 0; i < 500 && stage == 0; ++i) {
    std::ifstream in(pid_file);
    if (!(in >> stage)) stage = 0;
    if (stage == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_GT(stage, 0) << "the stage did not start";
  kill(runner, SIGKILL);
  waitpid(runner, nullptr, 0);
  // Gone, or a zombie waiting for init to reap it, within 5 s.
  auto alive = [&] {
    std::ifstream stat("/proc/" + std::to_string(stage) + "/stat");
    std::string pid, comm, state;
    if (!(stat >> pid >> comm >> state)) return false;
    return state != "Z" && state != "X";
  };
  for (int i = 0; i < 500 && alive(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const bool survived = alive();
  if (survived) kill(stage, SIGKILL);
  EXPECT_FALSE(survived) << "the stage outlived its runner";
  EXPECT_THROW(SubprocessExecutor(dir / "no-such-program")({}, dir / "x.log"), Error);
  std::filesystem::remove_all(dir);
}

TEST(Experiment, ParsesAConfigAndExpandsAListSweepOverSeeds) {
  const ExperimentConfig c = ParseExperimentConfig(kConfig, "toy.yaml");
  EXPECT_EQ(c.name, "toy");
  EXPECT_EQ(c.sweep.mode, "list");
  const auto runs = ExpandRuns(c);
  ASSERT_EQ(runs.size(), 8u);  // (2 + 2 points) × 2 seeds
  EXPECT_EQ(runs[0].id, "training.ferns.num_ferns=80_seed1");
  EXPECT_EQ(runs[1].id, "training.ferns.num_ferns=80_seed2");
  EXPECT_EQ(runs[4].id, "capture.detail.wrinkle_frames=5_seed1");
  // A list sweep varies one key at a time: the others keep their base value.
  EXPECT_EQ(runs[4].resolved.sections.at("training").at("ferns.num_ferns"), 1280);
  EXPECT_EQ(runs[0].resolved.sections.at("training").at("ferns.num_ferns"), 80);
}

// `crease experiment list` and `run NAME`: ORDER's names first (unknown ones
// skipped), then the other configs by name; a name resolves to DIR/NAME.yaml or an
// existing file, else the error lists the known names.
TEST(Experiment, ConfigsListInTheOrderFileThenByName) {
  const fs::path dir = testing::TestDir();
  for (const char* n : {"alpha", "beta", "gamma", "delta"}) testing::WriteText(dir / (std::string(n) + ".yaml"), "");
  testing::WriteText(dir / "README.md", "");
  testing::WriteText(dir / "ORDER", "gamma\nmissing alpha\n");
  const std::vector<fs::path> configs = ListExperimentConfigs(dir);
  const std::vector<fs::path> expected = {dir / "gamma.yaml", dir / "alpha.yaml", dir / "beta.yaml",
                                          dir / "delta.yaml"};
  EXPECT_EQ(configs, expected);
  EXPECT_EQ(ResolveExperimentConfig("beta", dir), dir / "beta.yaml");
  EXPECT_EQ(ResolveExperimentConfig((dir / "README.md").string(), dir), dir / "README.md");
  EXPECT_ERROR_HAS(ResolveExperimentConfig("omega", dir),
                   "experiment 'omega': no such config file or experiment (known: gamma, alpha, beta, delta, all)");
  EXPECT_ERROR_HAS(ListExperimentConfigs(dir / "none"), "no experiments folder");
}

// A results folder's profile, so that a run with another profile warns before it
// replaces those results: missing, unreadable or profile-less files give none.
TEST(Experiment, ResultsProfileReadsTheFoldersExperimentJson) {
  const fs::path dir = testing::TestDir() / "results_profile";
  fs::create_directories(dir);
  EXPECT_FALSE(ResultsProfile(dir).has_value());
  testing::WriteText(dir / "experiment.json", R"({"name": "x", "profile": "holds-r2"})");
  EXPECT_EQ(ResultsProfile(dir), std::optional<std::string>("holds-r2"));
  testing::WriteText(dir / "experiment.json", R"({"name": "x", "profile": ""})");
  EXPECT_EQ(ResultsProfile(dir), std::optional<std::string>(""));
  testing::WriteText(dir / "experiment.json", R"({"name": "x"})");
  EXPECT_FALSE(ResultsProfile(dir).has_value());
  testing::WriteText(dir / "experiment.json", "{not json");
  EXPECT_FALSE(ResultsProfile(dir).has_value());
}

TEST(Experiment, GridSweepIsTheCartesianProduct) {
  std::string yaml = kConfig;
  yaml.replace(yaml.find("mode: list"), 10, "mode: grid");
  const auto runs = ExpandRuns(ParseExperimentConfig(yaml, "grid.yaml"));
  ASSERT_EQ(runs.size(), 8u);  // 2 × 2 points × 2 seeds
  EXPECT_EQ(runs[0].id, "training.ferns.num_ferns=80_capture.detail.wrinkle_frames=5_seed1");
  EXPECT_EQ(runs[0].resolved.sections.at("capture").at("detail.wrinkle_frames"), 5);
}

TEST(Experiment, ProfilesOverrideValuesSweepsAndSeeds) {
  const ExperimentConfig c = ApplyProfile(ParseExperimentConfig(kConfig, "toy.yaml"), "quick");
  EXPECT_EQ(c.seeds, 1);
  EXPECT_EQ(c.sections.at("dataset").at("frames"), 6);
  const auto runs = ExpandRuns(c);
  ASSERT_EQ(runs.size(), 3u);  // num_ferns [40] + wrinkle_frames [5, 10]
  EXPECT_EQ(runs[0].id, "training.ferns.num_ferns=40_seed1");
  // "paper" is not in the config: the config's own values are the paper profile.
  EXPECT_EQ(ExpandRuns(ApplyProfile(ParseExperimentConfig(kConfig, "toy.yaml"), "paper")).size(), 8u);
  EXPECT_THROW(ApplyProfile(ParseExperimentConfig(kConfig, "toy.yaml"), "huge"), Error);
}

void ExpectErrorNaming(const std::string& yaml, const std::string& needle) {
  try {
    ParseExperimentConfig(yaml, "bad.yaml");
    FAIL() << "no error for a config that should name " << needle;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("bad.yaml"), std::string::npos) << e.what();
  }
}

TEST(Experiment, BadConfigsGiveErrorsNamingTheOption) {
  ExpectErrorNaming("name: x\ntraining: {num_fern: 3}\n", "num_fern");
  ExpectErrorNaming("name: x\ntrainnig: {num_ferns: 3}\n", "trainnig");
  ExpectErrorNaming("name: x\nsweep: {values: {training.nope: [1]}}\n", "nope");
  ExpectErrorNaming("name: x\nsweep: {values: {training.ferns.num_ferns: [-1]}}\n", "num_ferns");
  ExpectErrorNaming("name: x\nsweep: {values: {num_ferns: [1]}}\n", "SECTION.FIELD");
  ExpectErrorNaming("name: x\nsweep: {values: {training.ferns.num_ferns: []}}\n", "non-empty");
  ExpectErrorNaming("name: x\nsweep: {mode: diagonal}\n", "diagonal");
  ExpectErrorNaming("name: x\ndataset: {preset: dancing}\n", "dancing");
  ExpectErrorNaming("name: x\nprofiles: {quick: {set: {capture.bogus: 1}}}\n", "bogus");
  ExpectErrorNaming("title: no name\n", "name");
  ExpectErrorNaming("name: [unclosed\n", "YAML");
  // Issue 18: keys from before option sections name their new key, in a section and
  // in a sweep; a key set twice (nested and dotted) is refused.
  ExpectErrorNaming("name: x\ntraining: {pca_dimensions: 8}\n", "unknown option 'pca_dimensions': it is now 'pca.dimensions'");
  ExpectErrorNaming("name: x\nsweep: {values: {capture.fit_expression_prior_weight: [1]}}\n",
                    "it is now 'tracker.fit.expression_prior_weight'");
  ExpectErrorNaming("name: x\ncapture: {refinement: {lk_window: 15}, refinement.lk_window: 21}\n",
                    "option 'refinement.lk_window' is set twice");
  ExpectErrorNaming("name: x\ntraining: {ferns.num_ferns: 3}\ntraining: {ferns.depth: 3}\n", "key 'training' is set twice");
}

TEST(Experiment, ShardsTogetherEqualTheWhole) {
  const auto runs = ExpandRuns(ParseExperimentConfig(kConfig, "toy.yaml"));
  std::multiset<std::string> ids;
  for (int i = 0; i < 3; ++i)
    for (const auto& r : ShardRuns(runs, i, 3)) ids.insert(r.id);
  std::multiset<std::string> all;
  for (const auto& r : runs) all.insert(r.id);
  EXPECT_EQ(ids, all);
  EXPECT_EQ(ShardRuns(runs, 0, 3).size(), 3u);
  EXPECT_EQ(ShardRuns(runs, 2, 3).size(), 2u);
  EXPECT_THROW(ShardRuns(runs, 3, 3), Error);
}

std::map<std::string, std::string> KeysByKind(const std::vector<ExperimentStage>& stages) {
  std::map<std::string, std::string> keys;
  for (const auto& s : stages) keys[s.kind] += s.key + ";";
  return keys;
}

TEST(Experiment, CacheKeysChangeExactlyWithTheirInputs) {
  const ExperimentConfig c = ParseExperimentConfig(kConfig, "toy.yaml");
  const auto runs = ExpandRuns(c);
  const fs::path cache = "/tmp/cache";
  const StageVersions v1 = StageVersions::Uniform("1");
  // Same inputs → same keys (and the plan is deterministic).
  EXPECT_EQ(KeysByKind(PlanRunStages(runs[0], cache, v1)), KeysByKind(PlanRunStages(runs[0], cache, v1)));
  // A capture option (run 4: wrinkle_frames=5 at base num_ferns) vs the base of run
  // 0's sweep key: a different training (num_ferns 80 vs 1280) changes the model,
  // capture and eval, never the rig, scans, tracker, actors or sequences.
  const auto a = KeysByKind(PlanRunStages(runs[0], cache, v1));
  const auto b = KeysByKind(PlanRunStages(runs[4], cache, v1));
  for (const char* same : {"rig", "scans", "pairs", "tracker", "actor", "sequence"})
    EXPECT_EQ(a.at(same), b.at(same)) << same;
  for (const char* diff : {"model", "capture", "eval"}) EXPECT_NE(a.at(diff), b.at(diff)) << diff;
  // Two capture settings share everything up to the capture.
  const auto c5 = KeysByKind(PlanRunStages(runs[4], cache, v1));
  const auto c10 = KeysByKind(PlanRunStages(runs[6], cache, v1));
  for (const char* same : {"rig", "scans", "model", "tracker", "actor", "sequence"})
    EXPECT_EQ(c5.at(same), c10.at(same)) << same;
  EXPECT_NE(c5.at("capture"), c10.at("capture"));
  // Another seed: other actors, so other scans, model, actors, sequences; same rig and tracker.
  const auto s2 = KeysByKind(PlanRunStages(runs[1], cache, v1));
  EXPECT_EQ(a.at("rig"), s2.at("rig"));
  EXPECT_EQ(a.at("tracker"), s2.at("tracker"));
  EXPECT_NE(a.at("scans"), s2.at("scans"));
  EXPECT_NE(a.at("sequence"), s2.at("sequence"));
  // crease's version enters every key.
  const auto v2 = KeysByKind(PlanRunStages(runs[0], cache, StageVersions::Uniform("2")));
  for (const auto& [kind, key] : a) EXPECT_NE(key, v2.at(kind)) << kind;
  // The studio's options reach the sequence, not the training scans.
  ExperimentConfig lit = c;
  lit.sections["studio"] = json{{"light", "raking-above"}};
  const auto l = KeysByKind(PlanRunStages(ExpandRuns(lit)[0], cache, v1));
  EXPECT_EQ(a.at("model"), l.at("model"));
  EXPECT_NE(a.at("sequence"), l.at("sequence"));
  // Two test actors per run: two actors, sequences, captures and evals.
  EXPECT_EQ(std::count(a.at("eval").begin(), a.at("eval").end(), ';'), 2);
  // An option set to its default is the same stage as leaving it unset (the paper's
  // K in a sweep of F), and a non-default value is not.
  ExperimentConfig explicit_default = c;
  const json training_defaults = json::parse(OptionsToJson(TrainingOptions()));
  const json capture_defaults = json::parse(OptionsToJson(CaptureOptions()));
  explicit_default.sections["training"]["ferns.depth"] = training_defaults.at("ferns.depth");
  explicit_default.sections["capture"]["detail.wrinkle_frames"] = capture_defaults.at("detail.wrinkle_frames");
  const auto e = KeysByKind(PlanRunStages(ExpandRuns(explicit_default)[0], cache, v1));
  EXPECT_EQ(a, e);
  explicit_default.sections["training"]["ferns.depth"] = training_defaults.at("ferns.depth").get<int>() + 1;
  const auto e1 = KeysByKind(PlanRunStages(ExpandRuns(explicit_default)[0], cache, v1));
  EXPECT_NE(a.at("model"), e1.at("model"));
}

const char* kLadder = R"(
name: ladder
dataset: {leave_one_actor_out: true, test_actors: 1}
variants:
  rung:
    R0b: {training.training_targets: truth, dataset.capture: false}
    R1: {dataset.landmarks: ground-truth-surface, dataset.patch_sites: truth}
    R3: {dataset.landmarks: regressor}
  size:
    small: {studio.width: 320, studio.height: 240}
    big: {studio.width: 1280, studio.height: 720, dataset.scan_size: 1280x720}
sweep:
  mode: grid
  values:
    size: [small, big]
    rung: [R0b, R1, R3]
)";

const ExperimentStage* FindStage(const std::vector<ExperimentStage>& stages, const std::string& kind) {
  for (const auto& s : stages)
    if (s.kind == kind) return &s;
  return nullptr;
}

// "0.4.10" → {0, 4, 10}.
std::vector<int> VersionNumbers(const std::string& v) {
  std::vector<int> n;
  std::stringstream ss(v);
  for (std::string part; std::getline(ss, part, '.');) n.push_back(std::stoi(part));
  return n;
}

// Rung "true targets" (dataset.truth_targets): a scan-truth stage writes each training
// scan's D*, and the pairs are cut with it as their targets; the scans are shared.
const char* kTrueTargets = R"(
name: targets
dataset: {landmarks: ground-truth-surface, test_actors: 1}
training: {detail.lowpass_bandwidth_mm: 1.0}
variants:
  targets:
    extracted: {}
    truth: {dataset.truth_targets: true}
sweep:
  mode: grid
  values:
    targets: [extracted, truth]
)";

TEST(Experiment, TheTrueTargetsRungCutsThePairsWithEachScansTruth) {
  const auto runs = ExpandRuns(ParseExperimentConfig(kTrueTargets, "targets.yaml"));
  ASSERT_EQ(runs.size(), 2u);
  const fs::path cache = "/tmp/cache";
  const StageVersions v1 = StageVersions::Uniform("1");
  const auto extracted = PlanRunStages(runs[0], cache, v1);
  const auto truth = PlanRunStages(runs[1], cache, v1);
  EXPECT_EQ(FindStage(extracted, "scan-truth"), nullptr);
  const ExperimentStage* maps = FindStage(truth, "scan-truth");
  ASSERT_NE(maps, nullptr);
  EXPECT_EQ(maps->argv.front(), "eval-extraction");
  EXPECT_NE(std::find(maps->argv.begin(), maps->argv.end(), "detail.lowpass_bandwidth_mm=1.0"), maps->argv.end());
  EXPECT_NE(std::find(maps->depends.begin(), maps->depends.end(), FindStage(truth, "scans")->key), maps->depends.end());
  const ExperimentStage* pairs = FindStage(truth, "pairs");
  ASSERT_NE(pairs, nullptr);
  EXPECT_NE(std::find(pairs->depends.begin(), pairs->depends.end(), maps->key), pairs->depends.end());
  EXPECT_NE(std::find(pairs->argv.begin(), pairs->argv.end(), "training_targets=maps"), pairs->argv.end());
  EXPECT_NE(std::find(pairs->argv.begin(), pairs->argv.end(), "target_maps=" + (maps->dir / "maps").string()),
            pairs->argv.end());
  EXPECT_EQ(FindStage(truth, "scans")->key, FindStage(extracted, "scans")->key);
  EXPECT_EQ(FindStage(truth, "sequence")->key, FindStage(extracted, "sequence")->key);
  EXPECT_NE(pairs->key, FindStage(extracted, "pairs")->key);
  EXPECT_NE(FindStage(truth, "model")->key, FindStage(extracted, "model")->key);
}

TEST(Experiment, EachStageKindKeysItsOwnCodeVersion) {
  const auto toy = ExpandRuns(ParseExperimentConfig(kConfig, "toy.yaml"));
  const auto ladder = ExpandRuns(ParseExperimentConfig(kLadder, "ladder.yaml"));
  const auto targets = ExpandRuns(ParseExperimentConfig(kTrueTargets, "targets.yaml"));
  const fs::path cache = "/tmp/cache";
  // A new eval version re-keys the evals alone; a new capture version the captures
  // and, through their keys, the evals that read them.
  StageVersions v = StageVersions::Uniform("1");
  const auto base = KeysByKind(PlanRunStages(toy[0], cache, v));
  v.by_kind["eval"] = "2";
  const auto new_eval = KeysByKind(PlanRunStages(toy[0], cache, v));
  v.by_kind["capture"] = "2";
  const auto new_capture = KeysByKind(PlanRunStages(toy[0], cache, v));
  for (const auto& [kind, key] : base) {
    EXPECT_EQ(key == new_eval.at(kind), kind != "eval") << kind;
    EXPECT_EQ(key == new_capture.at(kind), kind != "eval" && kind != "capture") << kind;
  }
  // This build's table names every kind a plan can hold (the ladder's loao and
  // truth-maps too), none after crease's own version; a kind it lacks is an error.
  const StageVersions current = CurrentStageVersions();
  std::set<std::string> kinds;
  for (const auto* runs : {&toy, &ladder, &targets})
    for (const auto& r : *runs)
      for (const auto& s : PlanRunStages(r, cache, current)) kinds.insert(s.kind);
  for (const char* kind : {"rig", "scans", "pairs", "model", "loao", "tracker", "actor", "sequence", "truth-maps",
                           "capture", "eval", "scan-truth"})
    EXPECT_TRUE(kinds.count(kind)) << kind;
  for (const auto& [kind, version] : current.by_kind)
    EXPECT_LE(VersionNumbers(version), VersionNumbers(CREASE_VERSION)) << kind;
  EXPECT_EQ(current.by_kind.size(), kinds.size());
  EXPECT_THROW(current.Of("no-such-kind"), Error);
}

// Rung R2-oracle (dataset.truth_detail): a truth-maps stage of every frame feeds the
// capture, which assembles D^t from it; the capture is keyed apart from the
// regressing one of the same sequence and model.
TEST(Experiment, TheOracleRungAssemblesDetailFromEveryFramesTruth) {
  const char* config = R"(
name: oracle
dataset: {landmarks: ground-truth-surface, test_actors: 1}
variants:
  detail:
    regressed: {}
    oracle: {dataset.truth_detail: true}
sweep:
  mode: grid
  values:
    detail: [regressed, oracle]
)";
  const auto runs = ExpandRuns(ParseExperimentConfig(config, "oracle.yaml"));
  ASSERT_EQ(runs.size(), 2u);
  const fs::path cache = "/tmp/cache";
  const StageVersions v1 = StageVersions::Uniform("1");
  const auto regressed = PlanRunStages(runs[0], cache, v1);
  const auto oracle = PlanRunStages(runs[1], cache, v1);
  EXPECT_EQ(FindStage(regressed, "truth-maps"), nullptr);
  const ExperimentStage* maps = FindStage(oracle, "truth-maps");
  ASSERT_NE(maps, nullptr);
  const auto frames = std::find(maps->argv.begin(), maps->argv.end(), "--frames");
  ASSERT_NE(frames, maps->argv.end());
  EXPECT_EQ(*std::next(frames), "-1");  // every frame, not only the wrinkle frames
  const ExperimentStage* capture = FindStage(oracle, "capture");
  ASSERT_NE(capture, nullptr);
  EXPECT_NE(std::find(capture->depends.begin(), capture->depends.end(), maps->key), capture->depends.end());
  const std::string truth_detail = "detail_from_truth_maps=" + (maps->dir / "maps").string();
  EXPECT_NE(std::find(capture->argv.begin(), capture->argv.end(), truth_detail), capture->argv.end());
  EXPECT_EQ(FindStage(oracle, "sequence")->key, FindStage(regressed, "sequence")->key);
  EXPECT_EQ(FindStage(oracle, "model")->key, FindStage(regressed, "model")->key);
  EXPECT_NE(capture->key, FindStage(regressed, "capture")->key);
}

TEST(Experiment, VariantsSweepBundlesOfSettingsAndTheLadderPlansItsRungs) {
  const auto runs = ExpandRuns(ParseExperimentConfig(kLadder, "ladder.yaml"));
  ASSERT_EQ(runs.size(), 6u);
  EXPECT_EQ(runs[0].id, "size=small_rung=R0b_seed1");
  EXPECT_EQ(runs[0].point.at("rung"), "R0b");
  EXPECT_EQ(runs[4].resolved.sections.at("studio").at("width"), 1280);
  EXPECT_EQ(runs[4].resolved.sections.at("dataset").at("patch_sites"), "truth");
  EXPECT_EQ(runs[4].resolved.sections.at("dataset").at("scan_size"), "1280x720");
  const fs::path cache = "/tmp/cache";
  const StageVersions v1 = StageVersions::Uniform("1");
  // R0b: the pairs with the wrinkle layer as targets, the loao stage, no capture.
  const auto r0 = PlanRunStages(runs[0], cache, v1);
  ASSERT_NE(FindStage(r0, "loao"), nullptr);
  EXPECT_EQ(FindStage(r0, "loao")->depends, std::vector<std::string>{FindStage(r0, "pairs")->key});
  EXPECT_EQ(FindStage(r0, "capture"), nullptr);
  // R1: the truth maps of the wrinkle frames feed the capture's wrinkle map.
  const auto r1 = PlanRunStages(runs[1], cache, v1);
  const ExperimentStage* maps = FindStage(r1, "truth-maps");
  ASSERT_NE(maps, nullptr);
  const ExperimentStage* capture = FindStage(r1, "capture");
  ASSERT_NE(capture, nullptr);
  EXPECT_NE(std::find(capture->depends.begin(), capture->depends.end(), maps->key), capture->depends.end());
  const std::string wrinkle_maps = "wrinkle_map_from_maps=" + (maps->dir / "maps").string();
  EXPECT_NE(std::find(capture->argv.begin(), capture->argv.end(), wrinkle_maps), capture->argv.end());
  EXPECT_NE(std::find(capture->argv.begin(), capture->argv.end(), "--ground-truth-surface"), capture->argv.end());
  // R3: the tracker, no truth maps; its loao stage is R1's (same pairs, same options).
  const auto r3 = PlanRunStages(runs[2], cache, v1);
  EXPECT_EQ(FindStage(r3, "truth-maps"), nullptr);
  EXPECT_NE(FindStage(r3, "tracker"), nullptr);
  EXPECT_EQ(FindStage(r3, "loao")->key, FindStage(r1, "loao")->key);
  EXPECT_NE(FindStage(r0, "loao")->key, FindStage(r1, "loao")->key);
  // The big size renders the scans at its size too: other scans than the small one's.
  const auto big = PlanRunStages(runs[4], cache, v1);
  EXPECT_NE(FindStage(big, "scans")->key, FindStage(r1, "scans")->key);
  const auto& scan_argv = FindStage(big, "scans")->argv;
  EXPECT_NE(std::find(scan_argv.begin(), scan_argv.end(), "1280x720"), scan_argv.end());
  // Run through the runner: the loao stage's means reach every run of its pairs as
  // r0.*, and the experiment records its variants.
  const fs::path root = TempDir("ladder");
  ExperimentRunnerOptions o;
  o.out = root / "out";
  o.cache = root / "cache";
  o.program_version = "1";
  o.stage_versions = v1;
  const ExperimentSummary sum = RunExperiment(ParseExperimentConfig(kLadder, "ladder.yaml"), o, FakeExecute);
  EXPECT_EQ(sum.runs_ok, 6);
  const json run = ReadJsonFile(o.out / "runs" / "size=small_rung=R1_seed1.json");
  EXPECT_TRUE(run.at("metrics").contains("r0.held_out.ferns.correlation")) << run.dump();
  EXPECT_EQ(ReadJsonFile(o.out / "experiment.json").at("variants").at("rung").size(), 3u);
  fs::remove_all(root);
  // A label the group lacks, or a variant setting that is not an option, is an error.
  ExpectErrorNaming(std::string(kLadder) + "profiles: {quick: {sweep: {rung: [R9]}}}\n", "R9");
  std::string bad = kLadder;
  bad.replace(bad.find("studio.width: 320"), 17, "studio.wdth: 320");
  ExpectErrorNaming(bad, "wdth");
}

// A section's options may be nested or dotted; both are the same runs and stages.
TEST(Experiment, NestedAndDottedSectionsAreTheSameConfig) {
  const ExperimentConfig nested = ParseExperimentConfig(
      "name: x\ncapture: {refinement: {lk_window: 15}, tracker: {fit: {max_iterations: 4}}}\n", "nested.yaml");
  const ExperimentConfig dotted = ParseExperimentConfig(
      "name: x\ncapture: {refinement.lk_window: 15, tracker.fit.max_iterations: 4}\n", "dotted.yaml");
  EXPECT_EQ(nested.sections.at("capture"), dotted.sections.at("capture"));
  EXPECT_EQ(dotted.sections.at("capture").at("refinement.lk_window"), 15);
  const fs::path cache = "/tmp/cache";
  const StageVersions v1 = StageVersions::Uniform("1");
  EXPECT_EQ(KeysByKind(PlanRunStages(ExpandRuns(nested)[0], cache, v1)),
            KeysByKind(PlanRunStages(ExpandRuns(dotted)[0], cache, v1)));
}

// Every key of the nested option structs is registered once (issue 18: the landmark
// fit's and the refinement's expression prior shared one key until crease 0.4.1).
TEST(Experiment, StageOptionsRegisterEachKeyOnce) {
  EXPECT_NO_THROW(OptionFieldNames<CaptureOptions>());
  EXPECT_NO_THROW(OptionFieldNames<TrainingOptions>());
  EXPECT_NO_THROW(OptionFieldNames<ExperimentDataset>());
  CaptureOptions o;
  SetOptionsFromJson(R"({"tracker.fit.expression_prior_weight": 2, "refinement.expression_prior_weight": 7})", "capture", &o);
  EXPECT_EQ(o.tracker.fit.fit_expression_prior_weight, 2.0);
  EXPECT_EQ(o.refinement.fit_expression_prior_weight, 7.0);
}

json RunJsonWithoutTimes(const fs::path& file) {
  json j = ReadJsonFile(file);
  j.erase("stage_seconds");
  j.erase("commands");  // they and the images' paths name the cache folder
  j.erase("images");
  return j;
}

TEST(Experiment, ARunResumedAfterAFailureEqualsAnUninterruptedOne) {
  const ExperimentConfig c = ParseExperimentConfig(kConfig, "toy.yaml");
  const fs::path root = TempDir("resume");
  ExperimentRunnerOptions o;
  o.program_version = "test";
  o.stage_versions = StageVersions::Uniform("test");
  o.jobs = 2;

  o.out = root / "whole";
  o.cache = root / "cache_whole";
  int calls_whole = 0;
  const ExperimentSummary whole = RunExperiment(c, o, [&](const auto& argv, const auto& log) {
    ++calls_whole;
    return FakeExecute(argv, log);
  });
  EXPECT_EQ(whole.runs_ok, 8);
  EXPECT_EQ(whole.stages_failed, 0);

  // Interrupted: every capture fails (as if the machine died there).
  o.out = root / "resumed";
  o.cache = root / "cache_resumed";
  const ExperimentSummary broken = RunExperiment(c, o, [&](const auto& argv, const auto& log) {
    if (argv[0] == "capture") return 1;
    return FakeExecute(argv, log);
  });
  EXPECT_EQ(broken.runs_ok, 0);
  EXPECT_GT(broken.stages_failed, 0);
  const json failed = ReadJsonFile(o.out / "runs" / "training.ferns.num_ferns=80_seed1.json");
  EXPECT_EQ(failed.at("status"), "failed");
  EXPECT_NE(failed.at("error").get<std::string>().find("capture stage failed"), std::string::npos);

  // The rerun only runs what is missing: captures and evals.
  int calls = 0;
  const ExperimentSummary resumed = RunExperiment(c, o, [&](const auto& argv, const auto& log) {
    ++calls;
    EXPECT_TRUE(argv[0] == "capture" || argv[0] == "eval") << argv[0];
    return FakeExecute(argv, log);
  });
  EXPECT_EQ(resumed.runs_ok, 8);
  EXPECT_EQ(resumed.stages_cached + resumed.stages_run, resumed.stages);
  EXPECT_EQ(calls, resumed.stages_run);
  EXPECT_LT(calls, calls_whole);
  for (const auto& e : fs::directory_iterator(root / "whole" / "runs"))
    EXPECT_EQ(RunJsonWithoutTimes(e.path()), RunJsonWithoutTimes(o.out / "runs" / e.path().filename()))
        << e.path().filename();

  // A third run is all cache.
  const ExperimentSummary again = RunExperiment(c, o, [&](const auto&, const auto&) -> int {
    ADD_FAILURE() << "a cached stage ran again";
    return 1;
  });
  EXPECT_EQ(again.stages_cached, again.stages);

  // What the report reads.
  const json e = ReadJsonFile(o.out / "experiment.json");
  EXPECT_EQ(e.at("runs").size(), 8u);
  EXPECT_EQ(e.at("sweep").at("keys"), json::array({"training.ferns.num_ferns", "capture.detail.wrinkle_frames"}));
  EXPECT_EQ(e.at("baseline").at("training.ferns.num_ferns"), 1280);
  EXPECT_EQ(e.at("claims").size(), 1u);
  const json run = ReadJsonFile(o.out / "runs" / "capture.detail.wrinkle_frames=5_seed1.json");
  EXPECT_EQ(run.at("metrics").at("model.pca_dims_85"), 3);
  EXPECT_EQ(run.at("metrics").at("pairs.training_pairs"), 100);
  EXPECT_GT(run.at("metrics").at("tracking.coarse_px").get<double>(), 6.0);
  EXPECT_EQ(run.at("curves").at("per_frame.refined_px"), json::array({1.0, nullptr}));
  EXPECT_TRUE(fs::exists(run.at("images").at("error_vectors").get<std::string>()));
  std::ifstream csv(o.out / "results.csv");
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header.rfind("run_id,seed,status,training.ferns.num_ferns,capture.detail.wrinkle_frames,", 0), 0u) << header;
  fs::remove_all(root);
}

TEST(Experiment, ExperimentsRunTogetherShareTheirStages) {
  const ExperimentConfig a = ParseExperimentConfig(kConfig, "toy.yaml");
  ExperimentConfig b = ParseExperimentConfig(
      "name: other\nseeds: 2\ndataset: {training_actors: 2, test_actors: 2, frames: 12}\ntraining: {ferns.num_ferns: 1280}\n",
      "other.yaml");
  const fs::path root = TempDir("together");
  ExperimentRunnerOptions o;
  o.program_version = "test";
  o.stage_versions = StageVersions::Uniform("test");
  o.cache = root / "cache";
  o.jobs = 2;
  std::vector<ExperimentJob> jobs = {{a, o}, {b, o}};
  jobs[0].options.out = root / "toy";
  jobs[1].options.out = root / "other";
  std::map<std::string, int> runs_of_stage;
  std::mutex m;
  const auto summaries = RunExperiments(jobs, [&](const auto& argv, const auto& log) {
    {
      std::lock_guard<std::mutex> lock(m);
      std::string all;
      for (const auto& x : argv) all += x + " ";
      ++runs_of_stage[all];
    }
    return FakeExecute(argv, log);
  });
  ASSERT_EQ(summaries.size(), 2u);
  EXPECT_EQ(summaries[0].runs_ok, 8);
  EXPECT_EQ(summaries[1].runs_ok, 2);
  // Every command ran once, although "other" is toy's base configuration (its stages
  // are all shared with toy's wrinkle_frames runs, up to the capture).
  for (const auto& [cmd, n] : runs_of_stage) EXPECT_EQ(n, 1) << cmd;
  EXPECT_TRUE(fs::exists(root / "other" / "runs" / "base_seed1.json"));
  fs::remove_all(root);
}

TEST(Experiment, AnExclusiveCaptureRunsAlone) {
  std::string yaml = kConfig;
  yaml.replace(yaml.find("  frames: 12"), 12, "  frames: 12\n  exclusive_capture: true");
  const ExperimentConfig c = ParseExperimentConfig(yaml, "toy.yaml");
  const fs::path root = TempDir("exclusive");
  ExperimentRunnerOptions o;
  o.program_version = "test";
  o.stage_versions = StageVersions::Uniform("test");
  o.cache = root / "cache";
  o.out = root / "out";
  o.jobs = 2;
  std::mutex m;
  int running = 0, max_beside_capture = 0, max_running = 0;
  bool capture_running = false;
  const ExperimentSummary s = RunExperiment(c, o, [&](const auto& argv, const auto& log) {
    const bool capture = argv[0] == "capture";
    {
      std::lock_guard<std::mutex> lock(m);
      ++running;
      max_running = std::max(max_running, running);
      if (capture) capture_running = true;
      if (capture_running) max_beside_capture = std::max(max_beside_capture, running);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    const int rc = FakeExecute(argv, log);
    {
      std::lock_guard<std::mutex> lock(m);
      --running;
      if (capture) capture_running = false;
    }
    return rc;
  });
  EXPECT_EQ(s.runs_ok, 8);
  EXPECT_EQ(max_beside_capture, 1);  // nothing ran beside a capture
  EXPECT_EQ(max_running, 2);         // the other stages still ran two at a time
  fs::remove_all(root);
}

// Two runners on one cache (two `crease experiment run` with the local executor)
// make every stage once: the second waits on the stage's lock, then finds it
// complete (issue 20). Both collect the same results.
TEST(Experiment, TwoRunnersOnOneCacheMakeEachStageOnce) {
  const ExperimentConfig c = ParseExperimentConfig(kConfig, "toy.yaml");
  const fs::path root = TempDir("two_runners");
  ExperimentRunnerOptions o;
  o.program_version = "test";
  o.stage_versions = StageVersions::Uniform("test");
  o.cache = root / "cache";
  o.jobs = 2;
  std::map<std::string, int> made;  // command → times its executor ran
  std::mutex m;
  const StageExecutor count = [&](const std::vector<std::string>& argv, const fs::path& log) {
    std::string all;
    for (const auto& x : argv) all += x + " ";
    {
      std::lock_guard<std::mutex> lock(m);
      ++made[all];
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(3));  // let the runners overlap
    return FakeExecute(argv, log);
  };
  ExperimentSummary first, second;
  ExperimentRunnerOptions o1 = o, o2 = o;
  o1.out = root / "first";
  o2.out = root / "second";
  std::thread t([&] { first = RunExperiment(c, o1, count); });
  second = RunExperiment(c, o2, count);
  t.join();
  EXPECT_EQ(first.runs_ok, 8);
  EXPECT_EQ(second.runs_ok, 8);
  EXPECT_EQ(static_cast<int>(made.size()), first.stages);
  for (const auto& [cmd, n] : made) EXPECT_EQ(n, 1) << cmd;
  EXPECT_TRUE(fs::exists(o.cache / "rig"));
  for (const auto& e : fs::directory_iterator(o1.out / "runs"))
    EXPECT_EQ(RunJsonWithoutTimes(e.path()), RunJsonWithoutTimes(o2.out / "runs" / e.path().filename()))
        << e.path().filename();
  fs::remove_all(root);
}

}  // namespace
}  // namespace crease
