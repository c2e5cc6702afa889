// `crease experiment list|run|stage|status` (the runner of eval/experiment.h, and its
// Slurm executor, eval/slurm.h, issue 20) and `crease report` (reports/make_report.py
// over a results folder), issue 7.
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "apps/crease/commands.h"
#include "crease_build_version.h"  // generated: CREASE_BUILD_DESCRIPTION
#include "core/error.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "eval/experiment.h"
#include "eval/slurm.h"

namespace crease::app {

namespace fs = std::filesystem;

namespace {

fs::path SourceDir() {
  if (const char* env = std::getenv("CREASE_SOURCE_DIR")) return env;
  return CREASE_SOURCE_DIR;
}

fs::path ExperimentsDir() { return SourceDir() / "experiments"; }

std::vector<fs::path> ListConfigs() { return ListExperimentConfigs(ExperimentsDir()); }

fs::path ResolveConfig(const std::string& name) { return ResolveExperimentConfig(name, ExperimentsDir()); }

fs::path SelfPath() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  Require(!ec, "cannot find the crease program (/proc/self/exe)");
  return p;
}

}  // namespace

namespace {

// The options of `crease experiment run`.
struct RunArgs {
  std::string name, profile, out, cache, shard, executor = "local", slurm_args, slurm_arrays = "on";
  int seeds = 0, jobs = 1;
  double slurm_poll = 5.0;
  bool dry_run = false;
};

ExperimentRunnerOptions RunnerOptions(const RunArgs& a) {
  ExperimentRunnerOptions o;
  o.profile = a.profile;
  o.seeds = a.seeds;
  o.jobs = a.jobs;
  if (!a.shard.empty()) {
    const auto slash = a.shard.find('/');
    try {
      Require(slash != std::string::npos, "no /");
      o.shard = std::stoi(a.shard.substr(0, slash)) - 1;
      o.num_shards = std::stoi(a.shard.substr(slash + 1));
    } catch (const std::exception&) {
      throw Error(fmt::format("--shard '{}': expected I/N, e.g. 1/4", a.shard));
    }
  }
  // Absolute: the commands recorded with the results run from anywhere.
  o.out = fs::absolute(a.out.empty() ? fs::path("out/experiments") : fs::path(a.out));
  o.cache = fs::absolute(a.cache.empty() ? o.out / "cache" : fs::path(a.cache));
  o.program_version = CREASE_VERSION;
  o.stage_versions = CurrentStageVersions();
  o.build_description = CREASE_BUILD_DESCRIPTION;  // fixed when this program was built
  o.log = [](const std::string& line) {
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  };
  return o;
}

void PrintDryRun(const std::vector<ExperimentConfig>& parsed, const RunArgs& a, const ExperimentRunnerOptions& o) {
  for (const auto& c0 : parsed) {
    ExperimentConfig c = ApplyProfile(c0, a.profile);
    if (a.seeds > 0) c.seeds = a.seeds;
    const auto runs = ShardRuns(ExpandRuns(c), o.shard, o.num_shards);
    std::printf("%s: %zu runs\n", c.name.c_str(), runs.size());
    std::set<std::string> unique;       // keys of the stages (runs share some)
    size_t cached = 0;
    std::map<std::string, int> to_run;  // kind → stages not in the cache
    for (const auto& r : runs) {
      std::printf("  %s\n", r.id.c_str());
      for (const auto& s : PlanRunStages(r, o.cache, o.stage_versions)) {
        const bool done = StageIsComplete(s);
        std::printf("    [%s %s%s] %s\n", s.kind.c_str(), s.key.c_str(), done ? " cached" : "",
                    ExperimentCommandLine(s.argv).c_str());
        if (!unique.insert(s.key).second) continue;
        if (done) ++cached;
        else ++to_run[s.kind];
      }
    }
    std::vector<std::string> parts;
    for (const auto& [kind, n] : to_run) parts.push_back(fmt::format("{} {}", n, kind));
    const std::string left = parts.empty() ? "none" : fmt::format("{}", fmt::join(parts, ", "));
    std::printf("%s: %zu stages, %zu cached; to run: %s\n", c.name.c_str(), unique.size(), cached, left.c_str());
  }
}

// The stage backend --executor names (local: the default, J stages at a time here).
StageBackend BackendOf(const RunArgs& a) {
  if (a.executor == "local") return LocalBackend(SubprocessExecutor(SelfPath()));
  if (a.executor == "slurm") {
    SlurmOptions so;
    so.program = SelfPath();
    so.site_args = SplitSlurmArgs(a.slurm_args);
    so.poll_seconds = a.slurm_poll;
    so.arrays = a.slurm_arrays == "on";
    return SlurmBackend(so);
  }
  throw Error(fmt::format("--executor '{}': expected local or slurm", a.executor));
}

void RunExperimentCommand(const RunArgs& a) {
  Require(a.executor == "local" || a.executor == "slurm",
          fmt::format("--executor '{}': expected local or slurm", a.executor));
  Require(a.executor == "slurm" || a.slurm_args.empty(), "--slurm-args needs --executor slurm");
  Require(a.slurm_arrays == "on" || a.slurm_arrays == "off",
          fmt::format("--slurm-arrays '{}': expected on or off", a.slurm_arrays));
  std::vector<fs::path> configs;
  if (a.name == "all") {
    configs = ListConfigs();
  } else {
    configs.push_back(ResolveConfig(a.name));
  }
  const ExperimentRunnerOptions o = RunnerOptions(a);
  const fs::path root = o.out;
  // Parse every config first: a bad one fails before anything runs.
  std::vector<ExperimentConfig> parsed;
  for (const auto& path : configs) parsed.push_back(ReadExperimentConfig(path));
  if (a.dry_run) {
    PrintDryRun(parsed, a, o);
    return;
  }
  // All experiments under one scheduler: no barrier between them, shared stages once.
  std::vector<ExperimentJob> batch;
  for (const auto& c : parsed) {
    ExperimentRunnerOptions oc = o;
    oc.out = root / c.name;
    const std::optional<std::string> previous = ResultsProfile(oc.out);
    if (previous && *previous != a.profile) {
      std::fprintf(stderr, "%s: %s holds the results of profile '%s'; this run's (profile '%s') replace them "
                   "(the stages stay cached; -o DIR keeps profiles apart)\n",
                   c.name.c_str(), oc.out.string().c_str(), previous->c_str(), a.profile.c_str());
    }
    oc.record_stages = a.executor == "slurm";
    oc.command = fmt::format("crease experiment run {}{}{}{}{}", a.name == "all" ? "all" : c.name,
                             a.profile.empty() ? "" : " --profile " + a.profile,
                             a.seeds > 0 ? fmt::format(" --seeds {}", a.seeds) : "",
                             a.jobs > 1 ? fmt::format(" --jobs {}", a.jobs) : "",
                             a.shard.empty() ? "" : " --shard " + a.shard);
    batch.push_back({c, oc});
  }
  const std::vector<ExperimentSummary> summaries = RunExperiments(batch, BackendOf(a));
  int failed = 0;
  for (size_t i = 0; i < batch.size(); ++i) {
    const ExperimentSummary& s = summaries[i];
    std::printf("%s: %d/%d runs ok, %d stages (%d cached, %d run, %d failed) → %s\n", batch[i].config.name.c_str(),
                s.runs_ok, s.runs, s.stages, s.stages_cached, s.stages_run, s.stages_failed,
                batch[i].options.out.string().c_str());
    failed += s.runs_failed;
  }
  if (!summaries.empty()) std::printf("all done in %.1f s\n", summaries.back().seconds);
  if (failed > 0) throw Error(fmt::format("{} runs failed (see runs/*.json and the stage logs)", failed));
}

void AddRunCommand(CLI::App* exp) {
  auto* cmd = exp->add_subcommand("run", "Run an experiment (stages cached; a rerun resumes)");
  auto a = std::make_shared<RunArgs>();
  cmd->add_option("experiment", a->name, "Experiment name (experiments/NAME.yaml), a config file, or all")->required();
  cmd->add_option("--profile", a->profile,
                  "quick, paper, or another profile the config defines (e.g. detail-ladder's lights)");
  cmd->add_option("--seeds", a->seeds, "Independent actor sets (overrides the config)");
  cmd->add_option("--jobs,-j", a->jobs, "Stages run at once (local executor)")->capture_default_str();
  cmd->add_option("--shard", a->shard, "Run only slice I of N of the runs (I/N, 1-based)");
  cmd->add_option("--out,-o", a->out, "Results folder (default out/experiments; one subfolder per experiment)");
  cmd->add_option("--cache", a->cache, "Stage cache (default: <out>/cache, shared by the experiments)");
  cmd->add_option("--executor", a->executor,
                  "local (stages run here, --jobs at a time) or slurm (each missing stage a batch job or array task with "
                  "afterok dependencies; the cache and the crease program on a folder every node sees)")
      ->capture_default_str();
  cmd->add_option("--slurm-args", a->slurm_args,
                  "Site options for every sbatch, e.g. \"--partition=short --account=lab --qos=normal\"");
  cmd->add_option("--slurm-arrays", a->slurm_arrays,
                  "on: alike stages (one kind and resources, the same dependency wave: sweep points × seeds) are "
                  "submitted as one job array; off: one job per stage")
      ->capture_default_str();
  cmd->add_option("--slurm-poll", a->slurm_poll, "Seconds between the runner's squeue polls (slurm executor)")
      ->capture_default_str();
  cmd->add_flag("--dry-run", a->dry_run,
                "Print the runs and the commands of their stages (marking those in the cache) and, per "
                "experiment, what is left to run; run nothing");
  cmd->callback([a] { RunExperimentCommand(*a); });
}

void AddStageAndStatusCommands(CLI::App* exp) {
  {
    auto* cmd = exp->add_subcommand("stage", "Make one planned stage from its plan file (what a Slurm job runs)");
    struct Args {
      std::string plan;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("plan", a->plan, "The stage's plan.json (cache/<kind>/<key>.slurm/plan.json)")->required();
    cmd->callback([a] {
      RequireReadableFile(a->plan);
      const ExperimentStage stage = StageFromJson(ReadJsonFile(a->plan), a->plan);
      std::printf("%s stage %s: %s\n", stage.kind.c_str(), stage.key.c_str(), ExperimentCommandLine(stage.argv).c_str());
      std::fflush(stdout);
      const std::string error = ExecuteStage(stage, SubprocessExecutor(SelfPath()));
      if (!error.empty()) throw Error(error);
      std::printf("%s stage %s complete: %s\n", stage.kind.c_str(), stage.key.c_str(),
                  (stage.dir / "stage.json").string().c_str());
    });
  }
  {
    auto* cmd = exp->add_subcommand(
        "status", "What an experiment run with --executor slurm has done, queued, running, failed (cache + squeue)");
    struct Args {
      std::string out;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("out", a->out, "The experiment's results folder (e.g. out/experiments/tracking-refinement)")
        ->required();
    cmd->callback([a] {
      const std::vector<StageStatus> status = ExperimentStageStatus(a->out, SlurmOptions{});
      std::printf("%s", FormatStageStatus(fs::path(a->out).filename().string(), status).c_str());
    });
  }
}

void AddReportCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("report", "Figures and a Markdown report of experiment results (reports/)");
  struct Args {
    std::string results, out, markdown, preface;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("results", a->results, "Results folder (one experiment, or a folder of experiments)")->required();
  cmd->add_option("--out,-o", a->out, "Report folder (default: the results folder)");
  cmd->add_option("--markdown", a->markdown,
                  "The report's Markdown file (default OUT/report.md; figure links relative to it)");
  cmd->add_option("--preface", a->preface, "Markdown put after the report's introduction (how it was made, caveats)");
  cmd->callback([a] {
    const fs::path script = SourceDir() / "reports" / "make_report.py";
    RequireReadableFile(script);
    std::vector<std::string> args = {"/usr/bin/python3", script.string(), a->results};
    if (!a->out.empty()) args.insert(args.end(), {"-o", a->out});
    if (!a->markdown.empty()) args.insert(args.end(), {"--markdown", a->markdown});
    if (!a->preface.empty()) args.insert(args.end(), {"--preface", a->preface});
    std::vector<char*> cargs;
    for (auto& arg : args) cargs.push_back(arg.data());
    cargs.push_back(nullptr);
    std::fflush(stdout);
    execv(cargs[0], cargs.data());
    throw Error(fmt::format("cannot run /usr/bin/python3 {}: {}", script.string(), std::strerror(errno)));
  });
}

}  // namespace

void AddExperimentCommands(CLI::App& app) {
  auto* exp = app.add_subcommand("experiment", "Experiments: one config per paper figure or ablation (issue 7)");
  exp->require_subcommand(1);
  {
    auto* cmd = exp->add_subcommand("list", "List the experiments of experiments/ with the paper figure each tests");
    cmd->callback([] {
      for (const auto& path : ListConfigs()) {
        const ExperimentConfig c = ReadExperimentConfig(path);
        std::printf("%-22s %s%s\n", c.name.c_str(), c.title.c_str(),
                    c.paper.empty() ? "" : fmt::format(" [{}]", c.paper).c_str());
      }
    });
  }
  AddRunCommand(exp);
  AddStageAndStatusCommands(exp);
  AddReportCommand(app);
}

}  // namespace crease::app
