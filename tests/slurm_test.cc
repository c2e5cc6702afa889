// The Slurm executor's pure parts (eval/slurm.h): resources from the config, the
// batch script and sbatch's arguments of planned stages, squeue's output, the
// claim decisions, and the backend's submissions against fake sbatch/squeue
// programs. The real cluster is exercised by slurm_cluster_test.sh.
#include "eval/slurm.h"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/json_io.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const char* kConfig = R"(
name: toy
seeds: 1
dataset: {training_actors: 1, test_actors: 1, frames: 4, exclusive_capture: true}
sweep:
  values:
    training.ferns.num_ferns: [20, 40]
slurm:
  default: {cpus: 1, mem: 1G}
  capture: {cpus: 4, time: "8:00:00"}
)";

// The unique stages of a config's runs in plan order (as RunExperiments passes them).
std::vector<ExperimentStage> UniqueStages(const ExperimentConfig& c, const fs::path& cache) {
  std::vector<ExperimentStage> unique;
  for (const auto& r : ExpandRuns(c))
    for (const auto& s : PlanRunStages(r, cache, "test"))
      if (std::none_of(unique.begin(), unique.end(), [&](const auto& u) { return u.key == s.key; })) unique.push_back(s);
  return unique;
}

const ExperimentStage& Kind(const std::vector<ExperimentStage>& stages, const std::string& kind) {
  for (const auto& s : stages)
    if (s.kind == kind) return s;
  throw Error("no stage " + kind);
}

bool Has(const std::vector<std::string>& v, const std::string& x) { return std::find(v.begin(), v.end(), x) != v.end(); }

TEST(Slurm, ResourcesComeFromTheConfigAndNeverEnterTheKeys) {
  const ExperimentConfig c = ParseExperimentConfig(kConfig, "toy.yaml");
  const auto stages = UniqueStages(c, "/cache");
  const SlurmResources rig = SlurmResourcesOf(Kind(stages, "rig"));
  EXPECT_EQ(rig.cpus, 1);
  EXPECT_EQ(rig.mem, "1G");
  EXPECT_EQ(rig.time, SlurmResources().time);  // the built-in default
  const SlurmResources capture = SlurmResourcesOf(Kind(stages, "capture"));
  EXPECT_EQ(capture.cpus, 4);
  EXPECT_EQ(capture.mem, "1G");
  EXPECT_EQ(capture.time, "8:00:00");
  // The same config without its slurm section plans the same stages.
  std::string plain = kConfig;
  plain = plain.substr(0, plain.find("slurm:"));
  const auto plain_stages = UniqueStages(ParseExperimentConfig(plain, "plain.yaml"), "/cache");
  ASSERT_EQ(plain_stages.size(), stages.size());
  for (size_t i = 0; i < stages.size(); ++i) EXPECT_EQ(plain_stages[i].key, stages[i].key) << stages[i].kind;
}

TEST(Slurm, BadSlurmSectionsNameTheProblem) {
  const auto expect_error = [](const std::string& section, const std::string& needle) {
    try {
      ParseExperimentConfig("name: x\nslurm: " + section + "\n", "bad.yaml");
      ADD_FAILURE() << "no error for " << section;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("bad.yaml"), std::string::npos) << e.what();
    }
  };
  expect_error("{captur: {cpus: 2}}", "captur");
  expect_error("{default: {gpus: 1}}", "gpus");
  expect_error("{default: {cpus: 0}}", "cpus");
  expect_error("{default: {mem: '4 G'}}", "mem");
  expect_error("[1, 2]", "slurm");
}

TEST(Slurm, TheJobScriptRunsThePlannedStageWithItsResources) {
  const auto stages = UniqueStages(ParseExperimentConfig(kConfig, "toy.yaml"), "/shared/cache");
  const ExperimentStage& capture = Kind(stages, "capture");
  EXPECT_EQ(SlurmJobDir(capture), fs::path("/shared/cache/capture") / (capture.key + ".slurm"));
  const std::string script = SlurmJobScript(capture, "/opt/crease/bin/crease");
  EXPECT_EQ(script.rfind("#!/bin/bash\n", 0), 0u);
  for (const std::string& line : std::vector<std::string>
       {"#SBATCH --job-name=crease-capture-" + capture.key, "#SBATCH --cpus-per-task=4", "#SBATCH --mem=1G",
        "#SBATCH --time=8:00:00", "#SBATCH --exclusive",  // exclusive_capture: alone on its node
        "#SBATCH --output=/shared/cache/capture/" + capture.key + ".slurm/slurm-%j.out",
        "exec '/opt/crease/bin/crease' experiment stage '/shared/cache/capture/" + capture.key + ".slurm/plan.json'"})
    EXPECT_NE(script.find(line + "\n"), std::string::npos) << line << "\n" << script;
  EXPECT_NE(script.find(ExperimentCommandLine(capture.argv)), std::string::npos);  // the command, for a reader
  EXPECT_EQ(SlurmJobScript(Kind(stages, "rig"), "/c").find("--exclusive"), std::string::npos);
  // The plan round-trips through JSON (what the job reads).
  const ExperimentStage back = StageFromJson(StageToJson(capture), "plan.json");
  EXPECT_EQ(back.argv, capture.argv);
  EXPECT_EQ(back.key_inputs, capture.key_inputs);
  EXPECT_EQ(back.dir, capture.dir);
  EXPECT_EQ(back.depends, capture.depends);
  EXPECT_TRUE(back.exclusive);
  json tampered = StageToJson(capture);
  tampered["key_inputs"]["frames"] = 99;
  EXPECT_THROW(StageFromJson(tampered, "plan.json"), Error);
}

TEST(Slurm, SbatchArgumentsCarryTheDependenciesAndTheSiteOptions) {
  const auto stages = UniqueStages(ParseExperimentConfig(kConfig, "toy.yaml"), "/c");
  const ExperimentStage& capture = Kind(stages, "capture");
  const auto a = SbatchArguments(capture, {"11", "12"}, SplitSlurmArgs("  --partition=short\t--qos=normal "));
  EXPECT_EQ(a.front(), "--parsable");
  EXPECT_TRUE(Has(a, "--dependency=afterok:11:12"));
  EXPECT_TRUE(Has(a, "--kill-on-invalid-dep=yes"));
  EXPECT_TRUE(Has(a, "--partition=short"));
  EXPECT_TRUE(Has(a, "--qos=normal"));
  EXPECT_EQ(a.back(), (SlurmJobDir(capture) / "job.sh").string());
  const auto rig = SbatchArguments(Kind(stages, "rig"), {}, {});
  EXPECT_EQ(rig.size(), 2u);  // --parsable and the script: no dependency
}

TEST(Slurm, SqueueOutputIsParsed) {
  const SlurmQueue q =
      ParseSqueue("12|PENDING|crease-rig-00ff|Dependency\n13|RUNNING|crease-eval-0a|None\r\ngarbage\n14|PENDING|x\n");
  ASSERT_EQ(q.size(), 3u);
  EXPECT_EQ(q.at("12").state, "PENDING");
  EXPECT_EQ(q.at("12").name, "crease-rig-00ff");
  EXPECT_EQ(q.at("12").reason, "Dependency");
  EXPECT_EQ(q.at("13").name, "crease-eval-0a");
  EXPECT_EQ(q.at("13").reason, "None");
  EXPECT_EQ(q.at("14").name, "x");
  EXPECT_EQ(q.at("14").reason, "");
}

TEST(Slurm, ClaimsAreWaitedOnOnlyWhileTheirJobIsQueued) {
  // A chain rig → scans → pairs → model and the other stages of one run.
  const auto stages = UniqueStages(ParseExperimentConfig(kConfig, "toy.yaml"), "/c");
  const size_t n = stages.size();
  std::vector<bool> complete(n, false);
  std::vector<std::optional<SlurmClaim>> claims(n);
  SlurmQueue queue;
  const auto at = [&](const std::string& kind) {
    return static_cast<size_t>(&Kind(stages, kind) - stages.data());
  };
  complete[at("rig")] = true;
  claims[at("scans")] = SlurmClaim{"7", SlurmJobName(stages[at("scans")])};
  queue["7"] = {"RUNNING", SlurmJobName(stages[at("scans")]), ""};
  claims[at("tracker")] = SlurmClaim{"8", SlurmJobName(stages[at("tracker")])};  // ended without finishing
  claims[at("actor")] = SlurmClaim{"9", SlurmJobName(stages[at("actor")])};
  queue["9"] = {"PENDING", "someone-elses-job", ""};  // the id was reused (a new cluster)
  auto steps = PlanSlurmSteps(stages, complete, claims, queue);
  EXPECT_EQ(steps[at("rig")].action, SlurmAction::kDone);
  EXPECT_EQ(steps[at("scans")].action, SlurmAction::kWait);
  EXPECT_EQ(steps[at("scans")].job_id, "7");
  EXPECT_EQ(steps[at("pairs")].action, SlurmAction::kSubmit);
  EXPECT_EQ(steps[at("tracker")].action, SlurmAction::kSubmit);
  EXPECT_EQ(steps[at("actor")].action, SlurmAction::kSubmit);
  EXPECT_TRUE(steps[at("actor")].stale_job.empty());  // not ours: never cancelled
  // A queued job whose input must be made again waits on a job that is gone:
  // cancelled and submitted again.
  claims[at("pairs")] = SlurmClaim{"10", SlurmJobName(stages[at("pairs")])};
  queue["10"] = {"PENDING", SlurmJobName(stages[at("pairs")]), ""};
  queue.erase("7");
  steps = PlanSlurmSteps(stages, complete, claims, queue);
  EXPECT_EQ(steps[at("scans")].action, SlurmAction::kSubmit);
  EXPECT_EQ(steps[at("pairs")].action, SlurmAction::kSubmit);
  EXPECT_EQ(steps[at("pairs")].stale_job, "10");
  // Its input queued again instead: it keeps waiting.
  queue["7"] = {"PENDING", SlurmJobName(stages[at("scans")]), ""};
  steps = PlanSlurmSteps(stages, complete, claims, queue);
  EXPECT_EQ(steps[at("pairs")].action, SlurmAction::kWait);
  EXPECT_EQ(steps[at("pairs")].job_id, "10");
}

// Fake Slurm client programs in `dir`: sbatch numbers jobs from 100 and logs its
// arguments; squeue prints dir/queue once and empties it; scancel logs; scontrol
// says CANCELLED.
SlurmOptions FakeSlurm(const fs::path& dir) {
  const auto script = [&](const std::string& name, const std::string& body) {
    const fs::path p = dir / name;
    std::ofstream(p) << "#!/bin/sh\n" << body;
    chmod(p.c_str(), 0755);
    return p.string();
  };
  const std::string d = dir.string();
  SlurmOptions o;
  o.sbatch = script("sbatch", "n=$(cat " + d + "/next 2>/dev/null || echo 100)\necho $((n + 1)) > " + d +
                                  "/next\necho \"$n $*\" >> " + d + "/sbatch.log\necho \"$n;cluster\"\n");
  o.squeue = script("squeue", "cat " + d + "/queue 2>/dev/null\n: > " + d + "/queue\n");
  o.scancel = script("scancel", "echo \"$*\" >> " + d + "/scancel.log\n");
  o.scontrol = script("scontrol", "echo \"JobId=$4 JobState=CANCELLED Reason=None\"\n");
  o.program = "/bin/true";
  o.poll_seconds = 0.01;
  return o;
}

std::vector<std::string> Lines(const fs::path& file) {
  std::vector<std::string> lines;
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

TEST(Slurm, TheBackendSubmitsWhatIsMissingWithAfterokOnItsInputsJobs) {
  const fs::path root = fs::temp_directory_path() / ("crease_slurm_test_" + std::to_string(getpid()));
  fs::remove_all(root);
  fs::create_directories(root / "bin");
  const SlurmOptions slurm = FakeSlurm(root / "bin");
  ExperimentRunnerOptions o;
  o.program_version = "test";
  o.cache = root / "cache";
  o.out = root / "out";
  o.record_stages = true;
  const ExperimentConfig c = ParseExperimentConfig(kConfig, "toy.yaml");
  const auto stages = UniqueStages(c, o.cache);

  // Nothing cached: every stage submitted once, each after the jobs of its inputs.
  // The fake jobs make nothing, so every stage fails; the runs say why.
  ExperimentSummary s = RunExperiments({ExperimentJob{c, o}}, SlurmBackend(slurm)).front();
  EXPECT_EQ(s.stages_failed, s.stages);
  EXPECT_EQ(s.runs_ok, 0);
  const auto first = Lines(root / "bin" / "sbatch.log");
  ASSERT_EQ(first.size(), stages.size());
  std::map<std::string, std::string> job;  // key → claimed job id
  for (const auto& st : stages) {
    const auto claim = ReadSlurmClaim(st);
    ASSERT_TRUE(claim) << st.kind;
    EXPECT_EQ(claim->job_name, SlurmJobName(st));
    job[st.key] = claim->job_id;
    EXPECT_EQ(StageFromJson(ReadJsonFile(SlurmJobDir(st) / "plan.json"), "plan").key, st.key);
  }
  for (size_t i = 0; i < stages.size(); ++i) {
    std::string deps;
    for (const auto& d : stages[i].depends) deps += ":" + job[d];
    const std::string line = first[i];
    EXPECT_EQ(line.substr(0, line.find(' ')), job[stages[i].key]);
    if (deps.empty()) {
      EXPECT_EQ(line.find("--dependency"), std::string::npos) << line;
    } else {
      EXPECT_NE(line.find("--dependency=afterok" + deps + " "), std::string::npos) << line;
    }
    EXPECT_NE(line.find(SlurmJobDir(stages[i]).string() + "/job.sh"), std::string::npos) << line;
  }
  const json run = ReadJsonFile(o.out / "runs" / "training.ferns.num_ferns=20_seed1.json");
  EXPECT_NE(run.at("error").get<std::string>().find("rig stage failed (Slurm job 100, CANCELLED)"), std::string::npos)
      << run.at("error");
  EXPECT_TRUE(fs::exists(o.out / "stages.json"));

  // The rig made meanwhile, the scans' job still queued: the rerun submits the rest,
  // the pairs after the queued scans job.
  const ExperimentStage& rig = Kind(stages, "rig");
  const ExperimentStage& scans = Kind(stages, "scans");
  ASSERT_EQ(ExecuteStage(rig, [](const auto&, const auto&) { return 0; }), "");
  std::ofstream(root / "bin" / "queue") << job[scans.key] << "|PENDING|" << SlurmJobName(scans) << "\n";
  s = RunExperiments({ExperimentJob{c, o}}, SlurmBackend(slurm)).front();
  EXPECT_EQ(s.stages_cached, 1);
  const auto all = Lines(root / "bin" / "sbatch.log");
  ASSERT_EQ(all.size(), first.size() + stages.size() - 2);
  const std::string pairs_key = Kind(stages, "pairs").key;
  int pairs_lines = 0;
  for (size_t i = first.size(); i < all.size(); ++i) {
    EXPECT_EQ(all[i].find(rig.key + ".slurm"), std::string::npos) << "the complete rig was submitted again";
    EXPECT_EQ(all[i].find(scans.key + ".slurm"), std::string::npos) << "the claimed scans were submitted again";
    if (all[i].find(pairs_key + ".slurm") != std::string::npos) {
      ++pairs_lines;
      EXPECT_NE(all[i].find("--dependency=afterok:" + job[scans.key] + " "), std::string::npos) << all[i];
    }
  }
  EXPECT_EQ(pairs_lines, 1);
  // Status from the cache, the claims and (fake) squeue: the rig done, the rest failed.
  const auto status = ExperimentStageStatus(o.out, slurm);
  ASSERT_EQ(status.size(), stages.size());
  EXPECT_EQ(status[0].state, "done");
  EXPECT_EQ(status[1].state, "failed");
  EXPECT_NE(status[1].error.find("crease synth scans"), std::string::npos) << status[1].error;
  EXPECT_NE(FormatStageStatus("toy", status).find("1 done, 0 queued, 0 running"), std::string::npos);
  // A missing sbatch is an error naming it.
  SlurmOptions missing = slurm;
  missing.sbatch = (root / "bin" / "no-sbatch").string();
  fs::remove_all(o.cache);
  try {
    RunExperiments({ExperimentJob{c, o}}, SlurmBackend(missing));
    ADD_FAILURE() << "no error without sbatch";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no-sbatch"), std::string::npos) << e.what();
  }
  fs::remove_all(root);
}

}  // namespace
}  // namespace crease
