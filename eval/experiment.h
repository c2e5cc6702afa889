// The experiment runner (issue 7): one YAML config per paper figure or ablation
// (experiments/*.yaml), expanded into runs (sweep point × seed), each run a chain of
// cached stages that are crease's own commands:
//
//   rig ─► scans ─► pairs ─► model ────┐            (pairs ─► loao: rung R0, optional;
//                                                     scans ─► scan-truth ─► pairs: truth_targets)
//    │                                 ├─► capture ─► eval      (per test actor)
//    ├─► tracker ──────────────────────┤
//    └─► actor ─► sequence ────────────┘            (model, sequence ─► truth-maps ─► capture: R1)
//
// Every stage is cached under cache/<stage>/<key>/, the key a hash of everything the
// stage depends on: its own options, the keys of the stages it reads and crease's
// version number (not the code: clear the cache, or set `cache_salt`, after changing
// the method). A stage folder is complete when its stage.json (the key, the command,
// the time it took) exists; an incomplete one is removed and rebuilt, so a rerun after
// a crash resumes where it stopped. A sweep over capture options trains once.
//
// The stages are run as subprocesses of the crease program itself, so every result
// carries the exact commands that made it and a researcher can rerun any one of them.
// Tests substitute a StageExecutor that does not spawn processes.
//
// Config (YAML; every key is checked, an unknown one is an error naming it):
//   name, title, paper, description    text for the report
//   seeds: N                           independent actor sets (training and test actors)
//   dataset: {...}                     ExperimentDataset below
//   rig / actor / test_actor / scans_studio / studio / training / tracker / capture / eval:
//                                      options of the stage by field name (the structs of
//                                      synth/procedural_rig.h, synth/actor.h, synth/studio.h,
//                                      pipeline/training/trainer.h, pipeline/capture/tracker_training.h,
//                                      pipeline/capture/capture.h, eval/capture_metrics.h)
//   sweep: {mode: none|list|grid, values: {section.field: [v, …], …}}
//       list: each key on its own, the others at their base value (a one-at-a-time
//       ablation); grid: the Cartesian product. A sweep key may also name a group
//       of `variants`, its values then the variants' labels.
//   variants: {GROUP: {LABEL: {section.field: v, …}, …}, …}
//       named bundles of settings swept as one value (the detail ladder's rungs:
//       `rung: [R1, R2, R3]`; image sizes that set the studio and the scans). A
//       label may start from another's settings with a YAML merge key, `{<<: *base,
//       …}` after `base: &base {…}` (core/options.cc; its own keys win).
//   profiles: {quick: {set: {section.field: v}, sweep: {section.field: [...]}, seeds: N}, paper: {...}}
//   table, figures, claims: passed to the report (reports/make_report.py) as they are.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/options.h"

namespace crease {

// ExperimentDataset::landmarks: the capture's landmark source (a `crease capture` flag).
// ground-truth-fit keeps the actor's personal deviations as model error (the
// refinement's control); ground-truth-surface is the true coarse surface (exact geometry).
enum class ExperimentLandmarks { kRegressor, kDlib, kGroundTruthPrior, kGroundTruthFit, kGroundTruthSurface };
constexpr std::array<const char*, 5> OptionEnumNames(ExperimentLandmarks) {
  return {"regressor", "dlib", "ground-truth-prior", "ground-truth-fit", "ground-truth-surface"};
}
// ExperimentDataset::patch_sites (see there).
enum class PatchSites { kOwn, kTruth };
constexpr std::array<const char*, 2> OptionEnumNames(PatchSites) { return {"own", "truth"}; }

// The studio data and the method's inputs of one run (section `dataset`).
struct ExperimentDataset {
  int training_actors = 4;           // scan-set actors (the paper: 4)
  int64_t training_seed = 100;       // first training actor seed (seed s adds 1000·(s−1))
  int scan_cameras = 3;              // cameras per scan
  std::vector<std::string> scan_lights = {"studio"};  // light rigs each scan is imaged under
  std::vector<std::string> scan_expressions;          // "name=w,…" per scan; empty: the studio's default 4
  int scan_expression_count = 0;     // > 0: only the first N of those (expressions per actor)
  int scan_samples = 2;              // anti-aliasing samples per pixel axis of the scan images
  bool capture = true;               // false: the run ends at the model (training-only experiments)
  int test_actors = 1;               // novel actors captured per run (metrics are averaged over them)
  int64_t test_seed = 5000;          // first test actor seed (seed s adds 1000·(s−1))
  std::string preset = "workout-talking";  // the studio sequence preset captured
  double seconds = 0.0;              // preset length (0: the preset's own)
  int frames = -1;                   // render at most this many frames (−1: all)
  std::string light;                 // light rig of the sequence when it keys none ("" = studio)
  ExperimentLandmarks landmarks = ExperimentLandmarks::kRegressor;  // regressor | dlib | ground-truth-prior | ground-truth-fit
  double landmark_noise_px = 0.0;    // ground-truth-prior noise, px
  int64_t tracker_seed = 1;          // seed of the landmark regressor's training (fixed across seeds)
  // Capture meshes written every N frames; 0 = none (eval rebuilds H^t itself, and
  // a paper-size capture writes ~0.5 GB of meshes otherwise).
  int mesh_every = 0;
  bool exclusive_capture = false;    // run the capture alone (nothing beside it): its timings are clean
  std::string cache_salt;            // change to invalidate the cache after changing the method
  std::string scan_size;             // scan image size WIDTHxHEIGHT ("" = the studio's default)
  // Rung R0 of the detail ladder (issue 17): a `loao` stage scores the patch
  // regression on each training actor held out (crease model loao).
  bool leave_one_actor_out = false;
  std::vector<std::string> loao_regressors = {"ferns", "ridge", "nearest"};
  // Where capture places its patches: "own" (the paper: its wrinkle map of the first
  // frames) or "truth" (rung R1: from the true detail D* of those frames, a
  // `truth-maps` stage; studio sequences only).
  PatchSites patch_sites = PatchSites::kOwn;
  // Rung R2-oracle (issue 17): D^t assembled from every frame's true D* on the
  // capture's own patches instead of regressed (capture detail_from_truth_maps, after
  // a `truth-maps` stage of all frames): what a perfect regressor would give.
  bool truth_detail = false;
  // Rung "true targets" (issue 17; not the method): each training scan's studio D*
  // with the extraction's G (a `scan-truth` stage, crease eval-extraction
  // --write-truth) as the regression targets instead of Sec. 4.1's D^j (training
  // training_targets = maps): the regressor learns the truth the capture is scored
  // against. Studio scan sets only.
  bool truth_targets = false;
  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct ExperimentSweep {
  std::string mode = "none";                                  // none | list | grid
  std::vector<std::pair<std::string, nlohmann::json>> values;  // key → JSON array, in config order
};

struct ExperimentConfig {
  std::string name, title, paper, description;
  std::filesystem::path source;  // the YAML file
  int seeds = 1;
  // Stage option sections by name, each a JSON object of field → value (validated).
  std::map<std::string, nlohmann::json> sections;
  ExperimentSweep sweep;
  nlohmann::json profiles = nlohmann::json::object();
  nlohmann::json variants = nlohmann::json::object();  // group → label → {section.field: value}
  nlohmann::json report = nlohmann::json::object();  // table, figures, claims
  // Batch resources per stage kind for `--executor slurm` (eval/slurm.h: {default|KIND:
  // {cpus, mem, time}}); never part of a cache key or of the results.
  nlohmann::json slurm = nlohmann::json::object();
};

// The option sections a config may hold, in stage order.
const std::vector<std::string>& ExperimentSections();

// Parses and validates a config (YAML text); `what` names it in errors.
ExperimentConfig ParseExperimentConfig(const std::string& yaml_text, const std::string& what);
ExperimentConfig ReadExperimentConfig(const std::filesystem::path& path);

// The configs (*.yaml) of an experiments folder (`crease experiment list`, `run
// all`): first those DIR/ORDER names (whitespace-separated names without .yaml; the
// README's order), then the others by file name. Throws Error when DIR is no folder.
std::vector<std::filesystem::path> ListExperimentConfigs(const std::filesystem::path& dir);

// `name` as a config: an existing file as it is, else DIR/NAME.yaml. Otherwise
// throws Error listing the known experiments.
std::filesystem::path ResolveExperimentConfig(const std::string& name, const std::filesystem::path& dir);

// Applies profile `profile` ("" = none; a name the config lacks is an error).
ExperimentConfig ApplyProfile(const ExperimentConfig& config, const std::string& profile);

// One run: a sweep point and a seed.
struct ExperimentRun {
  std::string id;              // e.g. "training.ferns.num_ferns=80_seed1"
  int seed = 1;
  nlohmann::json point;        // {section.field: value}
  ExperimentConfig resolved;   // config with the point applied
};

// The runs in a deterministic order (sweep points in config order, then seeds).
std::vector<ExperimentRun> ExpandRuns(const ExperimentConfig& config);

// Runs i, i + n, i + 2n, … of `runs` (shard i of n, 0-based i).
std::vector<ExperimentRun> ShardRuns(const std::vector<ExperimentRun>& runs, int shard, int num_shards);

// One cached stage: what it depends on and the command that makes it.
struct ExperimentStage {
  std::string kind;                 // rig, scans, pairs, model, loao, tracker, actor, sequence, truth-maps, capture, eval
  nlohmann::json key_inputs;        // everything the output depends on
  std::string key;                  // 16 hex digits of a 64-bit hash of key_inputs
  std::filesystem::path dir;        // cache/<kind>/<key>
  std::vector<std::string> argv;    // crease arguments (without the program)
  std::vector<std::string> depends; // keys of the stages it reads
  bool exclusive = false;           // runs with no other stage beside it (timed captures)
  nlohmann::json slurm = nlohmann::json::object();  // the config's `slurm` section (not in the key)
};

// A stage as JSON (the plan file a Slurm job runs, `crease experiment stage`) and back;
// `what` names the file in errors.
nlohmann::json StageToJson(const ExperimentStage& stage);
ExperimentStage StageFromJson(const nlohmann::json& j, const std::string& what);

// Whether the stage's folder holds the finished stage: a stage.json with its key inputs.
bool StageIsComplete(const ExperimentStage& stage);

// `s` as one POSIX shell word: in single quotes (inner ' as '\''), unless it is
// non-empty and only of characters the shell leaves alone and `always` is false.
std::string ShellQuote(const std::string& s, bool always = false);

// "crease ARG …" with the arguments shell-quoted where needed (re-runnable as printed).
std::string ExperimentCommandLine(const std::vector<std::string>& argv);

// A stable 64-bit FNV-1a hash of `j.dump()` (keys are sorted), as 16 hex digits.
std::string ExperimentKey(const nlohmann::json& j);

// The version each kind of stage puts into its cache key. A kind's version is the
// crease version at which the code its command runs last changed what the stage
// writes, so a release that changes only the eval re-runs only the eval stages
// against a cache of earlier captures, sequences and models (the keys of the stages
// a stage reads are in its key too, so a new capture version re-runs its evals).
struct StageVersions {
  std::string all;                             // the version of every kind not in by_kind
  std::map<std::string, std::string> by_kind;  // kind → version
  // Every kind at `version` (tests; what every key held before this table).
  static StageVersions Uniform(const std::string& version) { return {version, {}}; }
  // The kind's version; a kind without one (not in by_kind, `all` empty) throws Error.
  const std::string& Of(const std::string& kind) const;
};

// This build's table (kStageCodeVersions in experiment.cc), one entry per kind.
// Rule for whoever bumps crease's VERSION: set the entry of every kind whose command
// now writes different bytes; a change under core/ sets them all. Stage kinds and the
// code their commands run: rig (synth rig), scans (synth scans), pairs and model
// (train), loao (model eval-pairs), tracker (train-tracker), actor, sequence (synth),
// truth-maps, capture (pipeline/capture), eval (eval/capture_metrics).
StageVersions CurrentStageVersions();

// The stages of a run (deduplicated by key across runs by the caller), in order.
// Each key holds `versions.Of(kind)`.
std::vector<ExperimentStage> PlanRunStages(const ExperimentRun& run, const std::filesystem::path& cache,
                                           const StageVersions& versions);

// Runs `argv` (crease arguments) with stdout and stderr to `log`; returns the exit
// status (0 = success). The default spawns the crease program `program`. The stage
// process dies with the runner (Linux: SIGTERM when its parent exits, even by
// SIGKILL), so a killed `crease experiment run` leaves no stage writing into the
// cache that a rerun would start again beside it.
using StageExecutor = std::function<int(const std::vector<std::string>& argv, const std::filesystem::path& log)>;
StageExecutor SubprocessExecutor(const std::filesystem::path& program);

// Makes one stage: removes what an interrupted attempt left in its folder, runs its
// command through `executor` (log in the folder's log.txt) and, on success only,
// writes stage.json (kind, key, key inputs, command, seconds), which marks it
// complete. Returns the error, empty on success. Every executor makes its stage
// folders through this function (the Slurm jobs too, via `crease experiment stage`).
// All of it happens under an exclusive lock of StageLockFile (flock): two runners on
// one cache never make a stage twice. The second waits for the first, then finds the
// stage complete and returns "" without running anything.
std::string ExecuteStage(const ExperimentStage& stage, const StageExecutor& executor);
// cache/<kind>/<key>.lock, beside the stage's folder.
std::filesystem::path StageLockFile(const ExperimentStage& stage);

struct ExperimentRunnerOptions {
  std::filesystem::path out;       // experiment results folder
  std::filesystem::path cache;     // stage cache (shared between experiments)
  std::string profile;             // "" | quick | paper
  int seeds = 0;                   // > 0 overrides the config's
  int jobs = 1;                    // stages run at once
  int shard = 0, num_shards = 1;   // run only this slice of the runs
  std::string program_version;     // crease's version number (recorded; see build_description)
  StageVersions stage_versions;    // the cache keys' versions (CurrentStageVersions in the program)
  std::string build_description;   // recorded only (crease_version: version + git, fixed at build time)
  std::string command;             // the command line, recorded for the report
  std::function<void(const std::string&)> log;  // progress lines (may be empty)
  // Write out/stages.json, the experiment's stages and their folders, which
  // `crease experiment status` reads (the Slurm executor's runs set it).
  bool record_stages = false;
};

struct ExperimentSummary {
  int runs = 0, runs_ok = 0, runs_failed = 0;
  int stages = 0, stages_cached = 0, stages_run = 0, stages_failed = 0;
  double seconds = 0.0;
};

// The profile of the results already in the folder `out` (its experiment.json; "" for
// a run without --profile); nullopt when it holds none or they cannot be read. A run
// of the experiment with another profile replaces them (results.csv, experiment.json
// and run files of the same id), so the program warns before it does.
std::optional<std::string> ResultsProfile(const std::filesystem::path& out);

// Plans, runs (cached) and collects an experiment: out/runs/<id>.json per run,
// out/results.csv and out/experiment.json (what reports/make_report.py reads).
ExperimentSummary RunExperiment(const ExperimentConfig& config, const ExperimentRunnerOptions& options,
                                const StageExecutor& executor);

// Several experiments with one scheduler (`crease experiment run all`): their stages
// are deduplicated across experiments and run J at a time with no barrier between
// experiments. All jobs must share options.cache and options.jobs; the log of the
// first is used. One summary per job, in order.
struct ExperimentJob {
  ExperimentConfig config;
  ExperimentRunnerOptions options;
};
std::vector<ExperimentSummary> RunExperiments(const std::vector<ExperimentJob>& jobs, const StageExecutor& executor);

// What became of a stage that was not cached.
struct StageOutcome {
  bool done = false;   // complete (its stage.json written)
  std::string error;   // why not, when not done
};
// Makes the stages that are not cached. `stages`: every stage of the call,
// deduplicated by key, each after the stages it reads; `cached[i]`: stage i was
// complete before. Returns one outcome per stage (cached ones: done). The local
// backend runs them J at a time (options.jobs) through an executor; the Slurm
// backend (eval/slurm.h) submits them as batch jobs.
using StageBackend = std::function<std::vector<StageOutcome>(
    const std::vector<ExperimentStage>& stages, const std::vector<bool>& cached, const ExperimentRunnerOptions& options)>;
StageBackend LocalBackend(const StageExecutor& executor);
// Plans, makes the missing stages with `backend`, collects (as above).
std::vector<ExperimentSummary> RunExperiments(const std::vector<ExperimentJob>& jobs, const StageBackend& backend);

// Metrics of a finished run from its stage folders: model report (PCA energy,
// training time) and the mean over its eval.json files (tracking, displacement,
// surface, speed), flattened to dotted keys; curves: pca_energy and the first
// sequence's per-frame errors. Exposed for tests.
nlohmann::json CollectRunMetrics(const std::vector<ExperimentStage>& stages);

}  // namespace crease
