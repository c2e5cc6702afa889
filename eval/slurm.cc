#include "eval/slurm.h"

#include <fcntl.h>
#include <spawn.h>
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
#include "core/file_lock.h"
#include "core/file_util.h"
#include "core/json_io.h"

extern char** environ;

namespace crease {

namespace fs = std::filesystem;
using json = nlohmann::json;

const std::vector<std::string>& SlurmStageKinds() {
  static const std::vector<std::string> kinds = {"rig",      "scans",      "pairs",   "model", "loao",  "tracker",
                                                 "actor",    "sequence",   "truth-maps", "capture", "eval",
                                                 "scan-truth"};
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

// The #SBATCH lines of a job named `name` with the resources of `stage`, its output to `output`.
std::string SbatchHeader(const ExperimentStage& stage, const std::string& name, const fs::path& output) {
  const SlurmResources r = SlurmResourcesOf(stage);
  std::string s = "#!/bin/bash\n";
  s += fmt::format("#SBATCH --job-name={}\n", name);
  s += fmt::format("#SBATCH --output={}\n", output.string());
  s += fmt::format("#SBATCH --cpus-per-task={}\n#SBATCH --mem={}\n#SBATCH --time={}\n", r.cpus, r.mem, r.time);
  s += "#SBATCH --nodes=1\n#SBATCH --ntasks=1\n";
  if (stage.exclusive) s += "#SBATCH --exclusive\n";
  return s;
}

// The script's last line: the crease program makes the stage of the plan `plan` (shell text).
std::string StageExec(const fs::path& program, const std::string& plan) {
  return "exec " + ShellQuote(program.string(), /*always=*/true) + " experiment stage " + plan + "\n";
}

// A hash of the stages' keys, which names their array.
std::string KeysHash(const std::vector<ExperimentStage>& stages) {
  json keys = json::array();
  for (const auto& s : stages) keys.push_back(s.key);
  return ExperimentKey(keys);
}

}  // namespace

std::string SlurmJobScript(const ExperimentStage& stage, const fs::path& program) {
  const fs::path dir = SlurmJobDir(stage);
  std::string s = SbatchHeader(stage, SlurmJobName(stage), dir / "slurm-%j.out");
  s += fmt::format("# The {} stage {} of crease's experiment cache (crease experiment run --executor slurm):\n",
                   stage.kind, stage.key);
  s += "#   " + ExperimentCommandLine(stage.argv) + "\n";
  s += "# made in " + stage.dir.string() + " through `crease experiment stage` (stage.json marks it complete).\n";
  return s + StageExec(program, ShellQuote((dir / "plan.json").string(), /*always=*/true));
}

fs::path SlurmArrayDir(const std::vector<ExperimentStage>& stages) {
  Require(!stages.empty(), "SlurmArrayDir: no stages");
  const ExperimentStage& first = stages.front();
  return first.dir.parent_path().parent_path() / "slurm-arrays" / (first.kind + "-" + KeysHash(stages));
}

std::string SlurmArrayName(const std::vector<ExperimentStage>& stages) {
  Require(!stages.empty(), "SlurmArrayName: no stages");
  return "crease-" + stages.front().kind + "-" + KeysHash(stages);
}

std::string SlurmArrayScript(const std::vector<ExperimentStage>& stages, const fs::path& program) {
  const fs::path dir = SlurmArrayDir(stages);
  std::string s = SbatchHeader(stages.front(), SlurmArrayName(stages), dir / "slurm-%A_%a.out");
  s += fmt::format("#SBATCH --array=0-{}\n", stages.size() - 1);
  s += fmt::format("# {} {} stages of crease's experiment cache (crease experiment run --executor slurm), task i\n",
                   stages.size(), stages.front().kind);
  s += "# making plans[i] in its cache folder through `crease experiment stage` (stage.json marks it complete):\n";
  std::string plans = "plans=(\n";
  for (size_t i = 0; i < stages.size(); ++i) {
    s += fmt::format("#   {} {}  {}\n", i, stages[i].key, ExperimentCommandLine(stages[i].argv));
    plans += "  " + ShellQuote((SlurmJobDir(stages[i]) / "plan.json").string(), /*always=*/true) + "\n";
  }
  return s + plans + ")\n" + StageExec(program, "\"${plans[$SLURM_ARRAY_TASK_ID]}\"");
}

std::vector<std::string> SbatchArguments(const fs::path& script, const std::vector<std::string>& after_ok,
                                         const std::vector<std::string>& site_args) {
  std::vector<std::string> a = {"--parsable"};
  if (!after_ok.empty()) {
    a.push_back(fmt::format("--dependency=afterok:{}", fmt::join(after_ok, ":")));
    a.push_back("--kill-on-invalid-dep=yes");  // a failed input cancels the job instead of leaving it pending
  }
  a.insert(a.end(), site_args.begin(), site_args.end());
  a.push_back(script.string());
  return a;
}

std::string SlurmClaim::Id() const { return task_id < 0 ? job_id : fmt::format("{}_{}", job_id, task_id); }

std::optional<SlurmClaim> ReadSlurmClaim(const ExperimentStage& stage) {
  const fs::path file = SlurmJobDir(stage) / "claim.json";
  if (!fs::exists(file)) return std::nullopt;
  try {
    const json j = ReadJsonFile(file);
    SlurmClaim c{j.at("job_id").get<std::string>(), j.value("task_id", -1), j.at("job_name").get<std::string>(),
                 j.value("output", ""), j.value("final_state", "")};
    if (c.output.empty()) c.output = (SlurmJobDir(stage) / fmt::format("slurm-{}.out", c.job_id)).string();
    return c;
  } catch (const std::exception&) {
    return std::nullopt;  // unreadable (a runner died while writing it): submit again
  }
}

void WriteSlurmClaim(const ExperimentStage& stage, const SlurmClaim& c) {
  json j{{"job_id", c.job_id}, {"task_id", c.task_id}, {"job_name", c.job_name}, {"output", c.output}};
  if (!c.final_state.empty()) j["final_state"] = c.final_state;
  WriteJsonFile(SlurmJobDir(stage) / "claim.json", j);
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

const SlurmQueueEntry* ClaimedJobInQueue(const std::optional<SlurmClaim>& claim, const ExperimentStage& stage,
                                         const SlurmQueue& queue) {
  if (!claim) return nullptr;
  const auto q = queue.find(claim->Id());
  const bool ours = q != queue.end() && q->second.name == claim->job_name &&
                    claim->job_name.rfind("crease-" + stage.kind + "-", 0) == 0;
  return ours ? &q->second : nullptr;
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
    const bool active = ClaimedJobInQueue(claim, stages[i], queue) != nullptr;
    bool input_resubmitted = false;
    for (const auto& dep : stages[i].depends) {
      const auto d = index.find(dep);
      input_resubmitted = input_resubmitted || (d != index.end() && steps[d->second].action == SlurmAction::kSubmit);
    }
    if (active && !input_resubmitted) {
      step = SlurmStep{SlurmAction::kWait, claim->Id(), ""};
    } else {
      step = SlurmStep{SlurmAction::kSubmit, "", active ? claim->Id() : ""};
    }
  }
  return steps;
}

namespace {

// Each stage's wave: 0 for a stage to submit none of whose inputs is submitted, else
// one more than its deepest submitted input; −1 for the stages not submitted.
std::vector<int> SubmissionWaves(const std::vector<ExperimentStage>& stages, const std::vector<SlurmStep>& steps) {
  std::map<std::string, size_t> index;
  std::vector<int> wave(stages.size(), -1);
  for (size_t i = 0; i < stages.size(); ++i) {
    index[stages[i].key] = i;
    if (steps[i].action != SlurmAction::kSubmit) continue;
    wave[i] = 0;
    for (const auto& dep : stages[i].depends) {
      const auto d = index.find(dep);
      if (d != index.end() && wave[d->second] >= 0) wave[i] = std::max(wave[i], wave[d->second] + 1);
    }
  }
  return wave;
}

}  // namespace

std::vector<std::vector<size_t>> GroupSlurmSubmissions(const std::vector<ExperimentStage>& stages,
                                                       const std::vector<SlurmStep>& steps, bool arrays) {
  Require(steps.size() == stages.size(), "GroupSlurmSubmissions: sizes differ");
  const std::vector<int> wave = SubmissionWaves(stages, steps);
  std::vector<std::vector<size_t>> groups;
  std::vector<int> group_wave;
  std::map<std::string, size_t> filling;  // what makes stages alike → the group they join
  for (size_t i = 0; i < stages.size(); ++i) {
    if (wave[i] < 0) continue;
    const SlurmResources r = SlurmResourcesOf(stages[i]);
    const std::string alike = arrays ? fmt::format("{}|{}|{}|{}|{}|{}", wave[i], stages[i].kind, r.cpus, r.mem, r.time,
                                                   stages[i].exclusive)
                                     : std::to_string(i);
    auto g = filling.find(alike);
    if (g == filling.end() || groups[g->second].size() >= kMaxSlurmArrayTasks) {
      g = filling.insert_or_assign(alike, groups.size()).first;
      groups.emplace_back();
      group_wave.push_back(wave[i]);
    }
    groups[g->second].push_back(i);
  }
  std::vector<size_t> order(groups.size());
  for (size_t g = 0; g < order.size(); ++g) order[g] = g;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return group_wave[a] < group_wave[b]; });
  std::vector<std::vector<size_t>> sorted;
  for (size_t g : order) sorted.push_back(std::move(groups[g]));
  return sorted;
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

// The jobs of `ids` (job ids, or JOBID_TASK of array tasks) that Slurm still holds,
// every array task on its own line (-r).
SlurmQueue QueryQueue(const SlurmOptions& o, const std::set<std::string>& ids) {
  if (ids.empty()) return {};
  std::set<std::string> jobs;
  for (const auto& id : ids) jobs.insert(id.substr(0, id.find('_')));
  const std::string list = fmt::format("{}", fmt::join(jobs, ","));
  const CommandResult r = RunCommand({o.squeue, "-h", "-r", "-o", "%i|%T|%j|%r", "-j", list});
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

fs::path SlurmLockFile(const fs::path& cache) { return cache / "slurm.lock"; }

// The cache a stage folder cache/<kind>/<key> is in.
fs::path CacheOf(const ExperimentStage& s) { return s.dir.parent_path().parent_path(); }

// Records in the stage's claim the state its job ended in, unless the claim names
// another job by now (resubmitted meanwhile).
void RecordFinalState(const ExperimentStage& s, const SlurmClaim& job, const std::string& state) {
  if (state.empty() || job.final_state == state) return;
  const FileLock lock(SlurmLockFile(CacheOf(s)));
  std::optional<SlurmClaim> claim = ReadSlurmClaim(s);
  if (!claim || claim->Id() != job.Id()) return;
  claim->final_state = state;
  WriteSlurmClaim(s, *claim);
}

// Submits the batch script `script`; returns the job id. `what` names its stages in errors.
std::string Sbatch(const fs::path& script, const std::vector<std::string>& after_ok, const SlurmOptions& o,
                   const std::string& what) {
  std::vector<std::string> argv = {o.sbatch};
  const std::vector<std::string> args = SbatchArguments(script, after_ok, o.site_args);
  argv.insert(argv.end(), args.begin(), args.end());
  const CommandResult r = RunCommand(argv);
  const std::string id = Trimmed(r.out.substr(0, r.out.find(';')));
  Require(r.status == 0 && !id.empty() && id.find_first_not_of("0123456789") == std::string::npos,
          fmt::format("sbatch failed for {} (exit status {}): {}\n  command: {}", what, r.status, Trimmed(r.err + r.out),
                      ExperimentCommandLine(argv).substr(7)));
  return id;
}

// Writes the stages' plans and scripts and submits them, one stage as a job, several
// as an array; returns their claims (written to claim.json).
std::vector<SlurmClaim> SubmitGroup(const std::vector<ExperimentStage>& group, const std::vector<std::string>& after_ok,
                                    const SlurmOptions& o) {
  for (const auto& s : group) {
    const fs::path dir = SlurmJobDir(s);
    fs::create_directories(dir);
    fs::remove(dir / "claim.json");
    WriteJsonFile(dir / "plan.json", StageToJson(s));
    WriteFileAtomic(dir / "job.sh", [&](std::ostream& out) { out << SlurmJobScript(s, o.program); });
  }
  const ExperimentStage& first = group.front();
  std::vector<SlurmClaim> claims;
  if (group.size() == 1) {
    const fs::path dir = SlurmJobDir(first);
    const std::string id = Sbatch(dir / "job.sh", after_ok, o, fmt::format("the {} stage {}", first.kind, first.key));
    claims.push_back(SlurmClaim{id, -1, SlurmJobName(first), (dir / fmt::format("slurm-{}.out", id)).string(), ""});
  } else {
    const fs::path dir = SlurmArrayDir(group);
    fs::create_directories(dir);
    WriteFileAtomic(dir / "job.sh", [&](std::ostream& out) { out << SlurmArrayScript(group, o.program); });
    const std::string id = Sbatch(dir / "job.sh", after_ok, o,
                                  fmt::format("the array of {} {} stages {}", group.size(), first.kind, dir.string()));
    for (size_t t = 0; t < group.size(); ++t)
      claims.push_back(SlurmClaim{id, static_cast<int>(t), SlurmArrayName(group),
                                  (dir / fmt::format("slurm-{}_{}.out", id, t)).string(), ""});
  }
  for (size_t t = 0; t < group.size(); ++t) WriteSlurmClaim(group[t], claims[t]);
  return claims;
}

// The claims of the stages not complete, and each stage's step (called under the cache's lock).
struct ClaimedSteps {
  std::vector<std::optional<SlurmClaim>> claims;
  std::vector<SlurmStep> steps;
};
ClaimedSteps PlanClaimedSteps(const std::vector<ExperimentStage>& stages, const std::vector<bool>& cached,
                              const SlurmOptions& o) {
  std::vector<bool> complete(stages.size());
  ClaimedSteps c;
  c.claims.resize(stages.size());
  std::set<std::string> claimed;
  for (size_t i = 0; i < stages.size(); ++i) {
    complete[i] = cached[i] || StageIsComplete(stages[i]);  // another runner may have finished it
    if (!complete[i]) c.claims[i] = ReadSlurmClaim(stages[i]);
    if (c.claims[i]) claimed.insert(c.claims[i]->Id());
  }
  c.steps = PlanSlurmSteps(stages, complete, c.claims, QueryQueue(o, claimed));
  return c;
}

// Claims and submissions under the cache's lock: returns each stage's job (an empty
// job id for the stages that are complete). A dependent names a stage in afterok by
// its job or task (JOBID_TASK) when it was claimed earlier, by its array's job id
// when it is submitted now within an array (then all of that array's tasks are
// waited for; arrays depend on the union of their tasks' inputs anyway).
std::vector<SlurmClaim> SubmitMissing(const std::vector<ExperimentStage>& stages, const std::vector<bool>& cached,
                                      const SlurmOptions& o, const ExperimentRunnerOptions& options) {
  const FileLock lock(SlurmLockFile(options.cache));
  const ClaimedSteps plan = PlanClaimedSteps(stages, cached, o);
  std::vector<SlurmClaim> jobs(stages.size());
  std::map<std::string, std::string> after_of;  // stage key → what its dependents' afterok names
  int waiting = 0, submitted = 0, calls = 0, arrays = 0;
  for (size_t i = 0; i < stages.size(); ++i) {
    if (plan.steps[i].action != SlurmAction::kWait) continue;
    jobs[i] = *plan.claims[i];
    after_of[stages[i].key] = jobs[i].Id();
    ++waiting;
  }
  for (const auto& group : GroupSlurmSubmissions(stages, plan.steps, o.arrays)) {
    std::vector<ExperimentStage> members;
    std::vector<std::string> after_ok;  // the union of the members' inputs' jobs
    for (size_t i : group) {
      if (!plan.steps[i].stale_job.empty()) RunCommand({o.scancel, plan.steps[i].stale_job});
      members.push_back(stages[i]);
      for (const auto& dep : stages[i].depends) {
        const auto a = after_of.find(dep);
        if (a != after_of.end() && std::find(after_ok.begin(), after_ok.end(), a->second) == after_ok.end())
          after_ok.push_back(a->second);
      }
    }
    const std::vector<SlurmClaim> made = SubmitGroup(members, after_ok, o);
    for (size_t k = 0; k < group.size(); ++k) {
      jobs[group[k]] = made[k];
      after_of[stages[group[k]].key] = group.size() > 1 ? made[k].job_id : made[k].Id();
    }
    submitted += static_cast<int>(group.size());
    ++calls;
    arrays += group.size() > 1 ? 1 : 0;
  }
  if (options.log)
    options.log(fmt::format("slurm: {} stages submitted in {} sbatch calls ({} arrays), {} already queued or running "
                            "(claimed)", submitted, calls, arrays, waiting));
  return jobs;
}

// Polls squeue until Slurm holds none of `jobs`, logging the counts when they change.
void WaitForJobs(const std::vector<SlurmClaim>& jobs, const SlurmOptions& o, const ExperimentRunnerOptions& options) {
  std::set<std::string> active;
  for (const auto& j : jobs)
    if (!j.job_id.empty()) active.insert(j.Id());
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
std::string FailureOf(const ExperimentStage& s, const SlurmClaim& job, const std::string& job_state, bool input_failed) {
  if (input_failed) return "an input stage failed";
  const std::string out = ReadFileTail(job.output, 1200);
  const std::string log = ReadFileTail(s.dir / "log.txt", 800);
  return fmt::format("{} stage failed (Slurm job {}{}): {}\n{}{}", s.kind, job.Id(),
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
    const std::vector<SlurmClaim> jobs = SubmitMissing(stages, cached, o, options);
    WaitForJobs(jobs, o, options);
    std::vector<StageOutcome> outcomes(stages.size());
    std::map<std::string, bool> done;
    for (size_t i = 0; i < stages.size(); ++i) {
      outcomes[i].done = cached[i] || StageIsComplete(stages[i]);
      done[stages[i].key] = outcomes[i].done;
      if (outcomes[i].done) continue;
      bool input_failed = false;
      for (const auto& dep : stages[i].depends) input_failed = input_failed || !done[dep];
      const std::string state = input_failed ? "" : FinalJobState(o, jobs[i].Id());
      RecordFinalState(stages[i], jobs[i], state);
      outcomes[i].error = FailureOf(stages[i], jobs[i], state, input_failed);
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
  std::vector<std::optional<SlurmClaim>> claims;
  std::set<std::string> claimed;
  for (const auto& js : j.at("stages")) {
    stages.push_back(StageFromJson(js, file.string()));
    StageStatus s;
    s.kind = stages.back().kind;
    s.key = stages.back().key;
    s.command = ExperimentCommandLine(stages.back().argv);
    s.runs = js.value("runs", std::vector<std::string>{});
    claims.push_back(std::nullopt);
    if (StageIsComplete(stages.back())) {
      s.state = "done";
    } else if ((claims.back() = ReadSlurmClaim(stages.back()))) {
      s.job_id = claims.back()->Id();
      claimed.insert(s.job_id);
    }
    status.push_back(std::move(s));
  }
  const SlurmQueue q = QueryQueue(o, claimed);
  std::map<std::string, std::string> state_of;
  for (size_t i = 0; i < stages.size(); ++i) {
    StageStatus& s = status[i];
    if (s.state.empty() && s.job_id.empty()) s.state = "not submitted";
    if (s.state.empty()) {
      if (const SlurmQueueEntry* e = ClaimedJobInQueue(claims[i], stages[i], q)) {
        s.job_state = e->state;
        s.state = e->state == "PENDING" ? "queued" : "running";
      } else {
        bool input_failed = false;
        for (const auto& dep : stages[i].depends) input_failed = input_failed || state_of[dep] == "failed";
        s.state = "failed";
        s.job_state = input_failed ? "" : FinalJobState(o, s.job_id);
        RecordFinalState(stages[i], *claims[i], s.job_state);
        if (!input_failed && s.job_state.empty()) s.job_state = claims[i]->final_state;  // Slurm forgot the job
        s.error = FailureOf(stages[i], *claims[i], s.job_state, input_failed);
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
