// `crease experiment list|run` (the runner of eval/experiment.h) and `crease report`
// (reports/make_report.py over a results folder), issue 7.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "eval/experiment.h"

namespace crease::app {

namespace fs = std::filesystem;

namespace {

fs::path SourceDir() {
  if (const char* env = std::getenv("CREASE_SOURCE_DIR")) return env;
  return CREASE_SOURCE_DIR;
}

fs::path ExperimentsDir() { return SourceDir() / "experiments"; }

// The configs of experiments/ in the order of experiments/ORDER (the README's
// order), then any others by name.
std::vector<fs::path> ListConfigs() {
  const fs::path dir = ExperimentsDir();
  Require(fs::is_directory(dir), fmt::format("{}: no experiments folder (set CREASE_SOURCE_DIR to the crease "
                                             "source tree)", dir.string()));
  std::vector<fs::path> all;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".yaml") all.push_back(e.path());
  std::sort(all.begin(), all.end());
  std::vector<fs::path> ordered;
  std::ifstream order(dir / "ORDER");
  std::string name;
  while (order >> name) {
    const fs::path p = dir / (name + ".yaml");
    if (std::find(all.begin(), all.end(), p) != all.end()) ordered.push_back(p);
  }
  for (const auto& p : all)
    if (std::find(ordered.begin(), ordered.end(), p) == ordered.end()) ordered.push_back(p);
  return ordered;
}

fs::path ResolveConfig(const std::string& name) {
  if (fs::exists(name) && fs::is_regular_file(name)) return name;
  const fs::path p = ExperimentsDir() / (name + ".yaml");
  if (fs::exists(p)) return p;
  std::vector<std::string> names;
  for (const auto& c : ListConfigs()) names.push_back(c.stem().string());
  throw Error(fmt::format("experiment '{}': no such config file or experiment (known: {}, all)", name,
                          fmt::join(names, ", ")));
}

fs::path SelfPath() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  Require(!ec, "cannot find the crease program (/proc/self/exe)");
  return p;
}

std::string GitDescription() {
  const std::string cmd = fmt::format("git -C '{}' rev-parse --short HEAD 2>/dev/null", SourceDir().string());
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return "";
  char buf[64] = {0};
  std::string out;
  if (std::fgets(buf, sizeof buf, p)) out = buf;
  pclose(p);
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
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
  {
    auto* cmd = exp->add_subcommand("run", "Run an experiment (stages cached; a rerun resumes)");
    static std::string name, profile, out, cache, shard;
    static int seeds = 0, jobs = 1;
    static bool dry_run = false;
    cmd->add_option("experiment", name, "Experiment name (experiments/NAME.yaml), a config file, or all")->required();
    cmd->add_option("--profile", profile, "quick, paper, or another profile the config defines (e.g. detail-ladder's lights)");
    cmd->add_option("--seeds", seeds, "Independent actor sets (overrides the config)");
    cmd->add_option("--jobs,-j", jobs, "Stages run at once")->capture_default_str();
    cmd->add_option("--shard", shard, "Run only slice I of N of the runs (I/N, 1-based)");
    cmd->add_option("--out,-o", out, "Results folder (default out/experiments; one subfolder per experiment)");
    cmd->add_option("--cache", cache, "Stage cache (default: <out>/cache, shared by the experiments)");
    cmd->add_flag("--dry-run", dry_run, "Print the runs and the commands of their stages, run nothing");
    cmd->callback([] {
      std::vector<fs::path> configs;
      if (name == "all") {
        configs = ListConfigs();
      } else {
        configs.push_back(ResolveConfig(name));
      }
      ExperimentRunnerOptions o;
      o.profile = profile;
      o.seeds = seeds;
      o.jobs = jobs;
      if (!shard.empty()) {
        const auto slash = shard.find('/');
        try {
          Require(slash != std::string::npos, "no /");
          o.shard = std::stoi(shard.substr(0, slash)) - 1;
          o.num_shards = std::stoi(shard.substr(slash + 1));
        } catch (const std::exception&) {
          throw Error(fmt::format("--shard '{}': expected I/N, e.g. 1/4", shard));
        }
      }
      // Absolute: the commands recorded with the results run from anywhere.
      const fs::path root = fs::absolute(out.empty() ? fs::path("out/experiments") : fs::path(out));
      o.cache = fs::absolute(cache.empty() ? root / "cache" : fs::path(cache));
      o.program_version = CREASE_VERSION;
      const std::string git = GitDescription();
      o.build_description = git.empty() ? CREASE_VERSION : fmt::format("{} (git {})", CREASE_VERSION, git);
      o.log = [](const std::string& line) {
        std::printf("%s\n", line.c_str());
        std::fflush(stdout);
      };
      // Parse every config first: a bad one fails before anything runs.
      std::vector<ExperimentConfig> parsed;
      for (const auto& path : configs) parsed.push_back(ReadExperimentConfig(path));
      if (dry_run) {
        for (const auto& c0 : parsed) {
          ExperimentConfig c = ApplyProfile(c0, profile);
          if (seeds > 0) c.seeds = seeds;
          const auto runs = ShardRuns(ExpandRuns(c), o.shard, o.num_shards);
          std::printf("%s: %zu runs\n", c.name.c_str(), runs.size());
          for (const auto& r : runs) {
            std::printf("  %s\n", r.id.c_str());
            for (const auto& s : PlanRunStages(r, o.cache, o.program_version)) {
              std::printf("    [%s %s] %s\n", s.kind.c_str(), s.key.c_str(), ExperimentCommandLine(s.argv).c_str());
            }
          }
        }
        return;
      }
      // All experiments under one scheduler: no barrier between them, shared stages once.
      std::vector<ExperimentJob> batch;
      for (const auto& c : parsed) {
        ExperimentRunnerOptions oc = o;
        oc.out = root / c.name;
        oc.command = fmt::format("crease experiment run {}{}{}{}{}", name == "all" ? "all" : c.name,
                                 profile.empty() ? "" : " --profile " + profile,
                                 seeds > 0 ? fmt::format(" --seeds {}", seeds) : "",
                                 jobs > 1 ? fmt::format(" --jobs {}", jobs) : "",
                                 shard.empty() ? "" : " --shard " + shard);
        batch.push_back({c, oc});
      }
      const std::vector<ExperimentSummary> summaries = RunExperiments(batch, SubprocessExecutor(SelfPath()));
      int failed = 0;
      for (size_t i = 0; i < batch.size(); ++i) {
        const ExperimentSummary& s = summaries[i];
        std::printf("%s: %d/%d runs ok, %d stages (%d cached, %d run, %d failed) → %s\n",
                    batch[i].config.name.c_str(), s.runs_ok, s.runs, s.stages, s.stages_cached, s.stages_run,
                    s.stages_failed, batch[i].options.out.string().c_str());
        failed += s.runs_failed;
      }
      if (!summaries.empty()) std::printf("all done in %.1f s\n", summaries.back().seconds);
      if (failed > 0) throw Error(fmt::format("{} runs failed (see runs/*.json and the stage logs)", failed));
    });
  }
  {
    auto* cmd = app.add_subcommand("report", "Figures and a Markdown report of experiment results (reports/)");
    static std::string results, out, markdown, preface;
    cmd->add_option("results", results, "Results folder (one experiment, or a folder of experiments)")->required();
    cmd->add_option("--out,-o", out, "Report folder (default: the results folder)");
    cmd->add_option("--markdown", markdown,
                    "The report's Markdown file (default OUT/report.md; figure links relative to it)");
    cmd->add_option("--preface", preface, "Markdown put after the report's introduction (how it was made, caveats)");
    cmd->callback([] {
      const fs::path script = SourceDir() / "reports" / "make_report.py";
      RequireReadableFile(script);
      std::vector<std::string> args = {"/usr/bin/python3", script.string(), results};
      if (!out.empty()) args.insert(args.end(), {"-o", out});
      if (!markdown.empty()) args.insert(args.end(), {"--markdown", markdown});
      if (!preface.empty()) args.insert(args.end(), {"--preface", preface});
      std::vector<char*> cargs;
      for (auto& a : args) cargs.push_back(a.data());
      cargs.push_back(nullptr);
      std::fflush(stdout);
      execv(cargs[0], cargs.data());
      throw Error(fmt::format("cannot run /usr/bin/python3 {}: {}", script.string(), std::strerror(errno)));
    });
  }
}

}  // namespace crease::app
