// The experiment runner on Slurm (issue 20): `crease experiment run … --executor slurm`.
//
// Every stage that the cache lacks becomes a batch job or a task of a job array; a
// stage's job depends (`afterok`) on the jobs of the stages it reads, and is cancelled
// by Slurm when one of them fails (--kill-on-invalid-dep=yes). The job runs `crease
// experiment stage PLAN`, which makes the stage folder through ExecuteStage exactly as
// the local executor does, so the cache and the collected results (results.csv,
// experiment.json, runs/*.json) are the same whichever executor made them.
//
// Job arrays: the missing stages of one kind with the same resources in the same
// dependency wave (sweep points × seeds: the models of every num_ferns value, the
// captures of every seed) are submitted as one array (`--array=0-(n-1)`), task i
// making stage i. Slurm gives an array one dependency list, so the array depends on
// the union of its tasks' inputs: a task may wait for an input it does not read (a
// slow scans job of seed 2 holds the pairs of seed 1), and one failed input cancels
// every task of the array (a rerun resubmits them). The wave keeps that union small:
// stages are grouped only with stages that are as deep in the chain of new jobs.
// `--slurm-arrays off` submits one job per stage.
//
// Beside each stage folder cache/<kind>/<key>/ the job keeps its own folder
// cache/<kind>/<key>.slurm/:
//   plan.json       the stage (StageToJson) that the job makes
//   job.sh          a batch script of the stage alone (resubmittable by hand)
//   claim.json      {job_id, task_id, job_name, output, final_state}: the stage is being
//                   made by that job (task_id −1) or array task
//   slurm-<id>.out  the output of a single job (the stage's error, Slurm's cancellation notice)
// An array's script and its tasks' outputs are in cache/slurm-arrays/<kind>-<hash>/.
// A rerun (or a second runner on the same cache) waits for a claimed job or task that
// is still queued or running instead of submitting another; a claimed one that has left
// the queue without completing the stage is submitted again (only those: the other
// tasks of its array are complete or still claimed). Claims are read and written under
// an exclusive lock of cache/slurm.lock (flock), so two runners never submit the same
// stage twice. A cancelled or failed job leaves no stage.json: its stage never looks
// complete. When a runner or `status` sees a job end without its stage, it records the
// job's final state in the claim, since Slurm forgets ended jobs after MinJobAge (5 min)
// when accounting is off.
//
// Config section `slurm` (optional; never part of a cache key or of the results):
//   slurm:
//     default: {cpus: 2, mem: 4G, time: "4:00:00"}   every stage
//     capture: {cpus: 4, time: "8:00:00"}             one stage kind (rig, scans, pairs,
//                                                     model, loao, tracker, actor, sequence,
//                                                     truth-maps, capture, eval)
// Difference from a full cluster integration: no accounting queries (a job's end state
// comes from `scontrol show job` while Slurm remembers it, then from the claim).
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "eval/experiment.h"

namespace crease {

// Batch resources of one stage: sbatch --cpus-per-task, --mem, --time.
struct SlurmResources {
  int cpus = 2;                 // CPUs per stage (crease's stages use every CPU they are given)
  std::string mem = "4G";       // memory, Slurm's syntax (4G, 500M)
  std::string time = "4:00:00"; // time limit, Slurm's syntax ([D-]H:MM:SS or minutes)
};

// The stage kinds a `slurm` section may name.
const std::vector<std::string>& SlurmStageKinds();
// Rejects a `slurm` section that is not {default|KIND: {cpus, mem, time}} (errors name `what` and the key).
void CheckSlurmSection(const nlohmann::json& section, const std::string& what);
// The resources of a stage: the defaults above, then the section's `default`, then its kind's entry.
SlurmResources SlurmResourcesOf(const ExperimentStage& stage);

// Where a stage's job keeps its files (cache/<kind>/<key>.slurm) and its job name.
std::filesystem::path SlurmJobDir(const ExperimentStage& stage);
std::string SlurmJobName(const ExperimentStage& stage);  // crease-<kind>-<key>

// The batch script of a stage: #SBATCH lines (name, output, resources, --exclusive
// for an exclusive capture) and `exec PROGRAM experiment stage <job dir>/plan.json`.
std::string SlurmJobScript(const ExperimentStage& stage, const std::filesystem::path& program);

// An array of alike stages (one kind, the resources of stages[0]): cache/slurm-arrays/
// <kind>-<hash of the keys>, its job name crease-<kind>-<that hash>, and its script
// (--array=0-(n-1); task i runs the plan of stages[i]).
std::filesystem::path SlurmArrayDir(const std::vector<ExperimentStage>& stages);
std::string SlurmArrayName(const std::vector<ExperimentStage>& stages);
std::string SlurmArrayScript(const std::vector<ExperimentStage>& stages, const std::filesystem::path& program);

// sbatch's arguments for the batch script `script` whose inputs are made by the jobs
// `after_ok` (job ids, array job ids or JOBID_TASK; none: no dependency), with the
// site's options; the script last.
std::vector<std::string> SbatchArguments(const std::filesystem::path& script, const std::vector<std::string>& after_ok,
                                         const std::vector<std::string>& site_args);

// The job or array task that claimed a stage (claim.json), if any.
struct SlurmClaim {
  std::string job_id;       // the job, or the array job
  int task_id = -1;         // the array task, −1: a single job
  std::string job_name;
  std::string output;       // the job's output file
  std::string final_state;  // the state it ended in, when a runner or status saw it end (CANCELLED, FAILED, …)
  std::string Id() const;   // job_id or JOBID_TASK: what squeue, scontrol, scancel and afterok take
};
std::optional<SlurmClaim> ReadSlurmClaim(const ExperimentStage& stage);
void WriteSlurmClaim(const ExperimentStage& stage, const SlurmClaim& claim);

// The jobs Slurm still holds (queued, running, completing …): job id (JOBID_TASK for
// an array task) → state, name and reason, from the output of `squeue -h -r -o %i|%T|%j|%r`.
struct SlurmQueueEntry {
  std::string state;   // PENDING, RUNNING, …
  std::string name;
  std::string reason;  // why it pends (Dependency, Resources, DependencyNeverSatisfied, …)
};
using SlurmQueue = std::map<std::string, SlurmQueueEntry>;
SlurmQueue ParseSqueue(const std::string& text);

// What the runner does about each stage.
enum class SlurmAction {
  kDone,    // complete in the cache
  kWait,    // claimed by a job that is still queued or running: depend on it
  kSubmit,  // missing: submit a job
};
struct SlurmStep {
  SlurmAction action = SlurmAction::kSubmit;
  std::string job_id;     // kWait: the claimed job or task (SlurmClaim::Id)
  std::string stale_job;  // kSubmit: a queued claim to cancel first (it waits on a job that is gone)
};
// The queue's entry of a claim's job when that job is still ours: the same id, the
// claimed name, a name of this stage kind (an id reused by a new cluster is not). Else null.
const SlurmQueueEntry* ClaimedJobInQueue(const std::optional<SlurmClaim>& claim, const ExperimentStage& stage,
                                         const SlurmQueue& queue);
// Decides per stage (stages in dependency order, as RunExperiments passes them):
// complete → done; a claim whose job is in `queue` (ClaimedJobInQueue) → wait, unless
// one of its inputs must be submitted again (then its job waits on a job that is gone:
// cancel and resubmit); otherwise submit.
std::vector<SlurmStep> PlanSlurmSteps(const std::vector<ExperimentStage>& stages, const std::vector<bool>& complete,
                                      const std::vector<std::optional<SlurmClaim>>& claims, const SlurmQueue& queue);

// At most this many tasks per array (Slurm's MaxArraySize is 1001 by default).
inline constexpr size_t kMaxSlurmArrayTasks = 1000;
// The sbatch calls for the stages to submit (steps[i] == kSubmit), in an order where
// every stage comes after its inputs: each a list of stage indices, one stage (a single
// job) or several alike ones (an array: one kind, equal resources and exclusivity, the
// same wave, i.e. the same length of the longest chain of submitted inputs before it).
// `arrays` false: one stage per call.
std::vector<std::vector<size_t>> GroupSlurmSubmissions(const std::vector<ExperimentStage>& stages,
                                                       const std::vector<SlurmStep>& steps, bool arrays);

struct SlurmOptions {
  std::filesystem::path program;       // the crease program the jobs run (on a path every node sees)
  std::vector<std::string> site_args;  // passed to every sbatch (--partition, --account, --qos, …)
  std::string sbatch = "sbatch";       // the Slurm client programs (PATH is searched)
  std::string squeue = "squeue";
  std::string scancel = "scancel";
  std::string scontrol = "scontrol";
  double poll_seconds = 5.0;           // how often the runner asks squeue while it waits
  bool arrays = true;                  // alike stages as job arrays (GroupSlurmSubmissions)
};

// Splits --slurm-args text at whitespace ("--partition=short --qos=normal").
std::vector<std::string> SplitSlurmArgs(const std::string& text);

// Submits the missing stages as jobs and arrays, waits until Slurm holds none of them
// (a job pending with DependencyNeverSatisfied is cancelled: its input failed), and
// reports each stage's outcome (a failed one with its job, command and output tail;
// its final state is recorded in the claim).
// Errors (sbatch missing or failing, squeue failing) name the command and its message.
StageBackend SlurmBackend(const SlurmOptions& options);

// `crease experiment status OUT`: each stage of out/stages.json (written by a run
// with --executor slurm) as done, queued, running, failed or not submitted, from
// the cache, the claims and squeue; failed ones with their command and log tail and
// the job's final state (from scontrol while Slurm remembers the job, else the claim's).
struct StageStatus {
  std::string kind, key, state, job_id, job_state, command, error;
  std::vector<std::string> runs;
};
std::vector<StageStatus> ExperimentStageStatus(const std::filesystem::path& out, const SlurmOptions& options);
std::string FormatStageStatus(const std::string& experiment, const std::vector<StageStatus>& stages);

}  // namespace crease
