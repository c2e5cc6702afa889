// The experiment runner on Slurm (issue 20): `crease experiment run … --executor slurm`.
//
// Every stage that the cache lacks becomes one batch job; a stage's job depends
// (`afterok`) on the jobs of the stages it reads, and is cancelled by Slurm when one
// of them fails (--kill-on-invalid-dep=yes). The job runs `crease experiment stage
// PLAN`, which makes the stage folder through ExecuteStage exactly as the local
// executor does, so the cache and the collected results (results.csv,
// experiment.json, runs/*.json) are the same whichever executor made them.
//
// Beside each stage folder cache/<kind>/<key>/ the job keeps its own folder
// cache/<kind>/<key>.slurm/:
//   plan.json       the stage (StageToJson) that the job makes
//   job.sh          the batch script (resources as #SBATCH lines; resubmittable by hand)
//   claim.json      {job_id, job_name}: the stage is being made by that job
//   slurm-<id>.out  the job's output (the stage's error, Slurm's cancellation notice)
// A rerun (or a second runner on the same cache) waits for a claimed job that is
// still queued or running instead of submitting another; a claimed job that has
// left the queue without completing the stage is submitted again. Claims are
// read and written under an exclusive lock of cache/slurm.lock (flock), so two
// runners never submit the same stage twice. A cancelled or failed job leaves no
// stage.json: its stage never looks complete.
//
// Config section `slurm` (optional; never part of a cache key or of the results):
//   slurm:
//     default: {cpus: 2, mem: 4G, time: "4:00:00"}   every stage
//     capture: {cpus: 4, time: "8:00:00"}             one stage kind (rig, scans, pairs,
//                                                     model, loao, tracker, actor, sequence,
//                                                     truth-maps, capture, eval)
// Differences from a full cluster integration: no job arrays (each stage is its own
// job; sweep points × seeds submit as many jobs), and no accounting queries (a
// job's end state comes from `scontrol show job` while Slurm remembers it).
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

// sbatch's arguments for a stage whose inputs are made by the jobs `after_ok`
// (none: no dependency), with the site's options; the script path last.
std::vector<std::string> SbatchArguments(const ExperimentStage& stage, const std::vector<std::string>& after_ok,
                                         const std::vector<std::string>& site_args);

// The job that claimed a stage (claim.json), if any.
struct SlurmClaim {
  std::string job_id;
  std::string job_name;
};
std::optional<SlurmClaim> ReadSlurmClaim(const ExperimentStage& stage);

// The jobs Slurm still holds (queued, running, completing …): job id → state, name and
// reason, from the output of `squeue -h -o %i|%T|%j|%r`.
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
  std::string job_id;     // kWait: the claimed job
  std::string stale_job;  // kSubmit: a queued claim to cancel first (it waits on a job that is gone)
};
// Decides per stage (stages in dependency order, as RunExperiments passes them):
// complete → done; a claim whose job (same id and name) is in `queue` → wait, unless
// one of its inputs must be submitted again (then its job waits on a job that is gone:
// cancel and resubmit); otherwise submit.
std::vector<SlurmStep> PlanSlurmSteps(const std::vector<ExperimentStage>& stages, const std::vector<bool>& complete,
                                      const std::vector<std::optional<SlurmClaim>>& claims, const SlurmQueue& queue);

struct SlurmOptions {
  std::filesystem::path program;       // the crease program the jobs run (on a path every node sees)
  std::vector<std::string> site_args;  // passed to every sbatch (--partition, --account, --qos, …)
  std::string sbatch = "sbatch";       // the Slurm client programs (PATH is searched)
  std::string squeue = "squeue";
  std::string scancel = "scancel";
  std::string scontrol = "scontrol";
  double poll_seconds = 5.0;           // how often the runner asks squeue while it waits
};

// Splits --slurm-args text at whitespace ("--partition=short --qos=normal").
std::vector<std::string> SplitSlurmArgs(const std::string& text);

// Submits the missing stages as jobs, waits until Slurm holds none of them (a job
// pending with DependencyNeverSatisfied is cancelled: its input failed), and
// reports each stage's outcome (a failed one with its job, command and output tail).
// Errors (sbatch missing or failing, squeue failing) name the command and its message.
StageBackend SlurmBackend(const SlurmOptions& options);

// `crease experiment status OUT`: each stage of out/stages.json (written by a run
// with --executor slurm) as done, queued, running, failed or not submitted, from
// the cache, the claims and squeue; failed ones with their command and log tail.
struct StageStatus {
  std::string kind, key, state, job_id, job_state, command, error;
  std::vector<std::string> runs;
};
std::vector<StageStatus> ExperimentStageStatus(const std::filesystem::path& out, const SlurmOptions& options);
std::string FormatStageStatus(const std::string& experiment, const std::vector<StageStatus>& stages);

}  // namespace crease
