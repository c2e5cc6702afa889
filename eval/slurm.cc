#include "eval/slurm.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include <fmt/format.h>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_io.h"

extern char** environ;

namespace crease {

namespace fs = std::filesystem;
using json = nlohmann::json;

const std::vector<std::string>& SlurmStageKinds() {
  static const std::vector<std::string> kinds = {"rig",      "scans",      "pairs",   "model", "loao",  "tracker",
                                                 "actor",    "sequence",   "truth-maps", "capture", "eval"};
  return kinds;
}

void CheckSlurmSection(const json& section, const std::string& what) {
  Require(section.is_object(), fmt::format("{}: 'slurm' must map default or a stage kind to {{cpus, mem, time}}", what));
  for (const auto& [kind, r] : section.items()) {
    const auto& kinds = SlurmStageKinds();
    Require(kind == "default" || std::find(kinds.begin(), kinds.end(), kind) != kinds.end(),
            fmt::format("{}: slurm.{}: not a stage kind (default, {})", what, kind, fmt::join(kinds, ", ")));
    Require(r.is_object(), fmt::format("{}: slurm.{} must map cpus, mem, time to values", what, kind));
    for (const auto& [field, v] : r.items()) {
      if (field == "cpus") {
        Require(v.is_number_integer() && v.get<int>() >= 1, fmt::format("{}: slurm.{}.cpus must be an integer ≥ 1", what, kind));
      } else if (field == "mem" || field == "time") {
        Require((v.is_string() && !v.get<std::string>().empty() &&
                 v.get<std::string>().find_first_of(" \t\n'\"") == std::string::npos) ||
                    v.is_number_integer(),
                fmt::format("{}: slurm.{}.{} must be Slurm's syntax (mem: 4G, 500M; time: 4:00:00)", what, kind, field));
      } else {
        throw Error(fmt::format("{}: slurm.{}: unknown field '{}' (cpus, mem, time)", what, kind, field));
      }
    }
  }
}

SlurmResources SlurmResourcesOf(const ExperimentStage& stage) {
  SlurmResources r;
  const auto apply = [&](const json& entry) {
    if (entry.contains("cpus")) r.cpus = entry["cpus"].get<int>();
    for (auto [field, value] : {std::pair{"mem", &r.mem}, std::pair{"time", &r.time}})
      if (entry.contains(field)) *value = entry[field].is_string() ? entry[field].get<std::string>() : entry[field].dump();
  };
  if (stage.slurm.is_object()) {
    if (stage.slurm.contains("default")) apply(stage.slurm["default"]);
    if (stage.slurm.contains(stage.kind)) apply(stage.slurm[stage.kind]);
  }
  return r;
}

fs::path SlurmJobDir(const ExperimentStage& stage) { return stage.dir.parent_path() / (stage.key + ".slurm"); }

std::string SlurmJobName(const ExperimentStage& stage) { return "crease-" + stage.kind + "-" + stage.key; }

namespace {

// Single-quoted for a shell script.
}  // namespace

std::string SlurmJobScript(const ExperimentStage& stage, const fs::path& program) {
  const SlurmResources r = SlurmResourcesOf(stage);
  const fs::path dir = SlurmJobDir(stage);
  std::string s = "#!/bin/bash\n";
  s += fmt::format("#SBATCH --job-name={}\n", SlurmJobName(stage));
  s += fmt::format("#SBATCH --output={}\n", (dir / "slurm-%j.out").string());
  s += fmt::format("#SBATCH --cpus-per-task={}\n#SBATCH --mem={}\n#SBATCH --time={}\n", r.cpus, r.mem, r.time);
  s += "#SBATCH --nodes=1\n#SBATCH --ntasks=1\n";
  if (stage.exclusive) s += "#SBATCH --exclusive\n";
  s += fmt::format("# The {} stage {} of crease's experiment cache (crease experiment run --executor slurm):\n",
                   stage.kind, stage.key);
  s += "#   " + ExperimentCommandLine(stage.argv) + "\n";
  s += "# made in " + stage.dir.string() + " through `crease experiment stage` (stage.json marks it complete).\n";
  s += "exec " + ShellQuote(program.string(), /*always=*/true) + " experiment stage " +
       ShellQuote((dir / "plan.json").string(), /*always=*/true) + "\n";
  return s;
}

std::vector<std::string> SbatchArguments(const ExperimentStage& stage, const std::vector<std::string>& after_ok,
                                         const std::vector<std::string>& site_args) {
  std::vector<std::string> a = {"--parsable"};
  if (!after_ok.empty()) {
    a.push_back(fmt::format("--dependency=afterok:{}", fmt::join(after_ok, ":")));
    a.push_back("--kill-on-invalid-dep=yes");  // a failed input cancels the job instead of leaving it pending
  }
  a.insert(a.end(), site_args.begin(), site_args.end());
  a.push_back((SlurmJobDir(stage) / "job.sh").string());
  return a;
}

std::optional<SlurmClaim> ReadSlurmClaim(const ExperimentStage& stage) {
  const fs::path file = SlurmJobDir(stage) / "claim.json";
  if (!fs::exists(file)) return std::nullopt;
  try {
    const json j = ReadJsonFile(file);
    return SlurmClaim{j.at("job_id").get<std::string>(), j.at("job_name").get<std::string>()};
  } catch (const std::exception&) {
    return std::nullopt;  // unreadable (a runner died while writing it): submit again
  }
}

SlurmQueue ParseSqueue(const std::string& text) {
  SlurmQueue q;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    std::vector<std::string> f;
    for (size_t start = 0;;) {
      const auto bar = line.find('|', start);
      f.push_back(line.substr(start, bar == std::string::npos ? bar : bar - start));
      if (bar == std::string::npos) break;
      start = bar + 1;
    }
    if (f.size() < 3) continue;
    q[f[0]] = SlurmQueueEntry{f[1], f[2], f.size() > 3 ? f[3] : ""};
  }
  return q;
}

std::vector<SlurmStep> PlanSlurmSteps(const std::vector<ExperimentStage>& stages, const std::vector<bool>& complete,
                                      const std::vector<std::optional<SlurmClaim>>& claims, const SlurmQueue& queue) {
  Require(complete.size() == stages.size() && claims.size() == stages.size(), "PlanSlurmSteps: sizes differ");
  std::map<std::string, size_t> index;
  std::vector<SlurmStep> steps(stages.size());
  for (size_t i = 0; i < stages.size(); ++i) {
    index[stages[i].key] = i;
    SlurmStep& step = steps[i];
    if (complete[i]) {
      step.action = SlurmAction::kDone;
      continue;
    }
    const auto& claim = claims[i];
    const auto q = claim ? queue.find(claim->job_id) : queue.end();
    const bool active = q != queue.end() && q->second.name == claim->job_name && claim->job_name == SlurmJobName(stages[i]);
    bool input_resubmitted = false;
    for (const auto& dep : stages[i].depends) {
      const auto d = index.find(dep);
      input_resubmitted = input_resubmitted || (d != index.end() && steps[d->second].action == SlurmAction::kSubmit);
    }
    if (active && !input_resubmitted) {
      step = SlurmStep{SlurmAction::kWait, claim->job_id, ""};
    } else {
      step = SlurmStep{SlurmAction::kSubmit, "", active ? claim->job_id : ""};
    }
  }
  return steps;
}

std::vector<std::string> SplitSlurmArgs(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

namespace {

struct CommandResult {
  int status = 0;
  std::string out, err;
};

// Runs `argv` (argv[0] searched on PATH) and captures its output; stderr goes to a
// temporary file so that neither pipe can fill up.
CommandResult RunCommand(const std::vector<std::string>& argv) {
  std::vector<char*> cargs;
  std::vector<std::string> args = argv;
  for (auto& a : args) cargs.push_back(a.data());
  cargs.push_back(nullptr);
  int out_pipe[2];
  Require(pipe2(out_pipe, O_CLOEXEC) == 0, fmt::format("{}: cannot create a pipe: {}", argv[0], std::strerror(errno)));
  char err_name[] = "/tmp/crease-slurm-err-XXXXXX";
  const int err_fd = mkstemp(err_name);
  Require(err_fd >= 0, fmt::format("{}: cannot create a temporary file: {}", argv[0], std::strerror(errno)));
  unlink(err_name);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, out_pipe[1], 1);
  posix_spawn_file_actions_adddup2(&actions, err_fd, 2);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, cargs[0], &actions, nullptr, cargs.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  close(out_pipe[1]);
  CommandResult r;
  if (rc != 0) {
    close(out_pipe[0]);
    close(err_fd);
    throw Error(fmt::format("cannot run {}: {} (is Slurm's client installed and on PATH? Debian: slurm-client)", argv[0],
                            std::strerror(rc)));
  }
  char buf[4096];
  ssize_t n = 0;
  while ((n = read(out_pipe[0], buf, sizeof buf)) > 0 || (n < 0 && errno == EINTR))
    if (n > 0) r.out.append(buf, static_cast<size_t>(n));
  close(out_pipe[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  lseek(err_fd, 0, SEEK_SET);
  while ((n = read(err_fd, buf, sizeof buf)) > 0) r.err.append(buf, static_cast<size_t>(n));
  close(err_fd);
  // posix_spawnp reports a missing program as exit status 127 on glibc.
  if (r.status == 127 && r.out.empty() && r.err.empty())
    throw Error(fmt::format("cannot run {}: not found (is Slurm's client installed and on PATH? Debian: slurm-client)",
                            argv[0]));
  return r;
}

std::string Trimmed(std::string s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  return s;
}

// The jobs of `ids` that Slurm still holds.
SlurmQueue QueryQueue(const SlurmOptions& o, const std::set<std::string>& ids) {
  if (ids.empty()) return {};
  const std::string list = fmt::format("{}", fmt::join(ids, ","));
  const CommandResult r = RunCommand({o.squeue, "-h", "-o", "%i|%T|%j|%r", "-j", list});
  // squeue fails when none of the ids is known any more (they have all left the queue).
  if (r.status != 0 && r.err.find("Invalid job id") != std::string::npos) return {};
  Require(r.status == 0, fmt::format("{} -j {} failed (exit status {}): {}", o.squeue, list, r.status, Trimmed(r.err)));
  return ParseSqueue(r.out);
}

// A finished job's state while Slurm remembers it (CANCELLED, FAILED, TIMEOUT, …), else "".
std::string FinalJobState(const SlurmOptions& o, const std::string& id) {
  try {
    const CommandResult r = RunCommand({o.scontrol, "-o", "show", "job", id});
    const auto p = r.out.find("JobState=");
    if (r.status != 0 || p == std::string::npos) return "";
    return r.out.substr(p + 9, r.out.find(' ', p) - p - 9);
  } catch (const Error&) {
    return "";
  }
}

// An exclusive lock of cache/slurm.lock for as long as it lives.
class CacheLock {
 public:
  explicit CacheLock(const fs::path& cache) {
    fs::create_directories(cache);
    const fs::path file = cache / "slurm.lock";
    fd_ = open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    Require(fd_ >= 0, fmt::format("{}: cannot open the cache's lock: {}", file.string(), std::strerror(errno)));
    while (flock(fd_, LOCK_EX) != 0) {
      if (errno != EINTR) {
        close(fd_);
        throw Error(fmt::format("{}: cannot lock: {}", file.string(), std::strerror(errno)));
      }
    }
  }
  ~CacheLock() { close(fd_); }
  CacheLock(const CacheLock&) = delete;
  CacheLock& operator=(const CacheLock&) = delete;

 private:
  int fd_ = -1;
};

// Writes the stage's plan and script and submits it; returns the job id.
std::string SubmitStage(const ExperimentStage& s, const std::vector<std::string>& after_ok, const SlurmOptions& o) {
  const fs::path dir = SlurmJobDir(s);
  fs::create_directories(dir);
  fs::remove(dir / "claim.json");
  WriteJsonFile(dir / "plan.json", StageToJson(s));
  WriteFileAtomic(dir / "job.sh", [&](std::ostream& out) { out << SlurmJobScript(s, o.program); });
  std::vector<std::string> argv = {o.sbatch};
  const std::vector<std::string> args = SbatchArguments(s, after_ok, o.site_args);
  argv.insert(argv.end(), args.begin(), args.end());
  const CommandResult r = RunCommand(argv);
  const std::string id = Trimmed(r.out.substr(0, r.out.find(';')));
  Require(r.status == 0 && !id.empty() && id.find_first_not_of("0123456789") == std::string::npos,
          fmt::format("sbatch failed for the {} stage {} (exit status {}): {}\n  command: {}", s.kind, s.key, r.status,
                      Trimmed(r.err + r.out), ExperimentCommandLine(argv).substr(7)));
  WriteJsonFile(dir / "claim.json", json{{"job_id", id}, {"job_name", SlurmJobName(s)}});
  return id;
}

// Claims and submissions under the cache's lock: returns each stage's job id
// ("" for stages that are complete).
std::vector<std::string> SubmitMissing(const std::vector<ExperimentStage>& stages, const std::vector<bool>& cached,
                                       const SlurmOptions& o, const ExperimentRunnerOptions& options) {
  CacheLock lock(options.cache);
  std::vector<bool> complete(stages.size());
  std::vector<std::optional<SlurmClaim>> claims(stages.size());
  std::set<std::string> claimed;
  for (size_t i = 0; i < stages.size(); ++i) {
    complete[i] = cached[i] || StageIsComplete(stages[i]);  // another runner may have finished it
    if (!complete[i]) claims[i] = ReadSlurmClaim(stages[i]);
    if (claims[i]) claimed.insert(claims[i]->job_id);
  }
  const std::vector<SlurmStep> steps = PlanSlurmSteps(stages, complete, claims, QueryQueue(o, claimed));
  std::map<std::string, std::string> job_of_key;
  std::vector<std::string> jobs(stages.size());
  int waiting = 0, submitted = 0;
  for (size_t i = 0; i < stages.size(); ++i) {
    const SlurmStep& step = steps[i];
    if (step.action == SlurmAction::kDone) continue;
    if (step.action == SlurmAction::kWait) {
      jobs[i] = step.job_id;
      ++waiting;
    } else {
      if (!step.stale_job.empty()) RunCommand({o.scancel, step.stale_job});
      std::vector<std::string> after_ok;
      for (const auto& dep : stages[i].depends)
        if (job_of_key.count(dep)) after_ok.push_back(job_of_key[dep]);
      jobs[i] = SubmitStage(stages[i], after_ok, o);
      ++submitted;
    }
    job_of_key[stages[i].key] = jobs[i];
  }
  if (options.log)
    options.log(fmt::format("slurm: {} stages submitted, {} already queued or running (claimed)", submitted, waiting));
  return jobs;
}

// Polls squeue until Slurm holds none of `jobs`, logging the counts when they change.
void WaitForJobs(const std::vector<std::string>& jobs, const SlurmOptions& o, const ExperimentRunnerOptions& options) {
  std::set<std::string> active;
  for (const auto& j : jobs)
    if (!j.empty()) active.insert(j);
  const size_t total = active.size();
  std::string last;
  while (!active.empty()) {
    const SlurmQueue q = QueryQueue(o, active);
    int queued = 0, running = 0;
    for (auto it = active.begin(); it != active.end();) {
      const auto e = q.find(*it);
      // A job whose input failed pends forever where Slurm ignores --kill-on-invalid-dep.
      const bool orphaned = e != q.end() && e->second.reason == "DependencyNeverSatisfied";
      if (orphaned) RunCommand({o.scancel, *it});
      if (e == q.end() || orphaned) {
        it = active.erase(it);
        continue;
      }
      (e->second.state == "PENDING" ? queued : running) += 1;
      ++it;
    }
    const std::string line = fmt::format("slurm: {} queued, {} running, {} of {} jobs ended", queued, running,
                                         total - active.size(), total);
    if (line != last && options.log) options.log(line);
    last = line;
    if (!active.empty())
      std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int>(o.poll_seconds * 1000)));
  }
}

// Why stage `s` (made by `job`) is not complete.
std::string FailureOf(const ExperimentStage& s, const std::string& job, const std::string& job_state, bool input_failed) {
  if (input_failed) return "an input stage failed";
  const std::string out = ReadFileTail(SlurmJobDir(s) / fmt::format("slurm-{}.out", job), 1200);
  const std::string log = ReadFileTail(s.dir / "log.txt", 800);
  return fmt::format("{} stage failed (Slurm job {}{}): {}\n{}{}", s.kind, job,
                     job_state.empty() ? "" : ", " + job_state, ExperimentCommandLine(s.argv),
                     out.empty() ? "" : "job output: " + out, log.empty() ? "" : "\nstage log: " + log);
}

}  // namespace

StageBackend SlurmBackend(const SlurmOptions& o) {
  return [o](const std::vector<ExperimentStage>& stages, const std::vector<bool>& cached,
             const ExperimentRunnerOptions& options) {
    Require(!o.program.empty() && fs::exists(o.program),
            fmt::format("the crease program the Slurm jobs run ('{}') does not exist", o.program.string()));
    Require(o.poll_seconds > 0, "the Slurm poll interval must be > 0 s");
    const std::vector<std::string> jobs = SubmitMissing(stages, cached, o, options);
    WaitForJobs(jobs, o, options);
    std::vector<StageOutcome> outcomes(stages.size());
    std::map<std::string, bool> done;
    for (size_t i = 0; i < stages.size(); ++i) {
      outcomes[i].done = cached[i] || StageIsComplete(stages[i]);
      done[stages[i].key] = outcomes[i].done;
      if (outcomes[i].done) continue;
      bool input_failed = false;
      for (const auto& dep : stages[i].depends) input_failed = input_failed || !done[dep];
      outcomes[i].error = FailureOf(stages[i], jobs[i], input_failed ? "" : FinalJobState(o, jobs[i]), input_failed);
      if (options.log && !input_failed) options.log("  FAILED: " + outcomes[i].error);
    }
    return outcomes;
  };
}

std::vector<StageStatus> ExperimentStageStatus(const fs::path& out, const SlurmOptions& o) {
  const fs::path file = out / "stages.json";
  Require(fs::exists(file), fmt::format("{}: no stages.json (it is written by `crease experiment run … --executor "
                                        "slurm`; give the experiment's results folder, e.g. out/experiments/NAME)",
                                        file.string()));
  const json j = ReadJsonFile(file);
  std::vector<ExperimentStage> stages;
  std::vector<StageStatus> status;
  std::set<std::string> claimed;
  for (const auto& js : j.at("stages")) {
    stages.push_back(StageFromJson(js, file.string()));
    StageStatus s;
    s.kind = stages.back().kind;
    s.key = stages.back().key;
    s.command = ExperimentCommandLine(stages.back().argv);
    s.runs = js.value("runs", std::vector<std::string>{});
    if (StageIsComplete(stages.back())) {
      s.state = "done";
    } else if (const auto claim = ReadSlurmClaim(stages.back())) {
      s.job_id = claim->job_id;
      claimed.insert(claim->job_id);
    }
    status.push_back(std::move(s));
  }
  const SlurmQueue q = QueryQueue(o, claimed);
  std::map<std::string, std::string> state_of;
  for (size_t i = 0; i < stages.size(); ++i) {
    StageStatus& s = status[i];
    if (s.state.empty() && s.job_id.empty()) s.state = "not submitted";
    if (s.state.empty()) {
      const auto e = q.find(s.job_id);
      if (e != q.end() && e->second.name == SlurmJobName(stages[i])) {
        s.job_state = e->second.state;
        s.state = e->second.state == "PENDING" ? "queued" : "running";
      } else {
        bool input_failed = false;
        for (const auto& dep : stages[i].depends) input_failed = input_failed || state_of[dep] == "failed";
        s.state = "failed";
        s.job_state = input_failed ? "" : FinalJobState(o, s.job_id);
        s.error = FailureOf(stages[i], s.job_id, s.job_state, input_failed);
      }
    }
    state_of[s.key] = s.state;
  }
  return status;
}

std::string FormatStageStatus(const std::string& experiment, const std::vector<StageStatus>& stages) {
  std::map<std::string, int> count;
  for (const auto& s : stages) ++count[s.state];
  std::string text = fmt::format("{}: {} stages: {} done, {} queued, {} running, {} failed, {} not submitted\n",
                                 experiment, stages.size(), count["done"], count["queued"], count["running"],
                                 count["failed"], count["not submitted"]);
  for (const auto& s : stages) {
    const std::string runs = s.runs.empty()      ? ""
                             : s.runs.size() == 1 ? "  run " + s.runs.front()
                                                  : fmt::format("  runs {} (+{} more)", s.runs.front(), s.runs.size() - 1);
    text += fmt::format("  {:<13} {:<10} {}{}{}\n", s.state, s.kind, s.key,
                        s.job_id.empty() ? "" : fmt::format("  job {}{}", s.job_id, s.job_state.empty() ? "" : " " + s.job_state),
                        runs);
  }
  for (const auto& s : stages) {
    if (s.state != "failed") continue;
    std::string indented;
    std::istringstream in(s.error);
    std::string line;
    while (std::getline(in, line)) indented += "    " + line + "\n";
    text += fmt::format("\nFAILED {} {}:\n{}", s.kind, s.key, indented);
  }
  return text;
}

}  // namespace crease
