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
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/file_util.h"
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
    for (const auto& s : PlanRunStages(r, cache, StageVersions::Uniform("test")))
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
  const auto a = SbatchArguments(SlurmJobDir(capture) / "job.sh", {"11", "12_3"},
                                 SplitSlurmArgs("  --partition=short\t--qos=normal "));
  EXPECT_EQ(a.front(), "--parsable");
  EXPECT_TRUE(Has(a, "--dependency=afterok:11:12_3"));
  EXPECT_TRUE(Has(a, "--kill-on-invalid-dep=yes"));
  EXPECT_TRUE(Has(a, "--partition=short"));
  EXPECT_TRUE(Has(a, "--qos=normal"));
  EXPECT_EQ(a.back(), (SlurmJobDir(capture) / "job.sh").string());
  const auto rig = SbatchArguments(SlurmJobDir(Kind(stages, "rig")) / "job.sh", {}, {});
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
  claims[at("scans")] = SlurmClaim{"7", -1, SlurmJobName(stages[at("scans")]), "", ""};
  queue["7"] = {"RUNNING", SlurmJobName(stages[at("scans")]), ""};
  claims[at("tracker")] = SlurmClaim{"8", -1, SlurmJobName(stages[at("tracker")]), "", ""};  // ended without finishing
  claims[at("actor")] = SlurmClaim{"9", -1, SlurmJobName(stages[at("actor")]), "", ""};
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
  claims[at("pairs")] = SlurmClaim{"10", -1, SlurmJobName(stages[at("pairs")]), "", ""};
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

// A fresh folder ROOT with fake Slurm programs in ROOT/bin and runner options on
// ROOT/cache and ROOT/out (stages.json recorded, as Slurm runs do).
struct FakeCluster {
  fs::path root;
  SlurmOptions slurm;
  ExperimentRunnerOptions options;
};
FakeCluster MakeFakeCluster(const std::string& name) {
  FakeCluster f;
  f.root = fs::temp_directory_path() / (name + "_" + std::to_string(getpid()));
  fs::remove_all(f.root);
  fs::create_directories(f.root / "bin");
  f.slurm = FakeSlurm(f.root / "bin");
  f.options.program_version = "test";
  f.options.stage_versions = StageVersions::Uniform("test");
  f.options.cache = f.root / "cache";
  f.options.out = f.root / "out";
  f.options.record_stages = true;
  return f;
}

TEST(Slurm, TheBackendSubmitsWhatIsMissingWithAfterokOnItsInputsJobs) {
  FakeCluster fake = MakeFakeCluster("crease_slurm_test");
  const fs::path& root = fake.root;
  SlurmOptions& slurm = fake.slurm;
  slurm.arrays = false;  // one job per stage (--slurm-arrays off); arrays: the next test
  const ExperimentRunnerOptions& o = fake.options;
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
    const auto at = std::find_if(first.begin(), first.end(), [&](const std::string& l) {
      return l.find(SlurmJobDir(stages[i]).string() + "/job.sh") != std::string::npos;
    });
    ASSERT_NE(at, first.end()) << stages[i].kind << " not submitted";
    const std::string line = *at;
    EXPECT_EQ(line.substr(0, line.find(' ')), job[stages[i].key]);
    for (const auto& d : stages[i].depends) EXPECT_LT(std::stoi(job[d]), std::stoi(job[stages[i].key])) << line;
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

// kConfig with two seeds: sweep points × seeds.
std::string TwoSeeds() {
  std::string yaml = kConfig;
  yaml.replace(yaml.find("seeds: 1"), 8, "seeds: 2");
  return yaml;
}

TEST(Slurm, AlikeStagesOfOneWaveAreGroupedIntoArrays) {
  const auto stages = UniqueStages(ParseExperimentConfig(TwoSeeds(), "toy.yaml"), "/c");
  const std::vector<SlurmStep> submit(stages.size());  // every stage missing
  const auto groups = GroupSlurmSubmissions(stages, submit, /*arrays=*/true);
  std::map<std::string, size_t> group_of;  // key → position of its group
  size_t grouped = 0;
  for (size_t g = 0; g < groups.size(); ++g) {
    for (size_t i : groups[g]) {
      const ExperimentStage& s = stages[i];
      EXPECT_EQ(s.kind, stages[groups[g].front()].kind);
      EXPECT_EQ(SlurmResourcesOf(s).cpus, SlurmResourcesOf(stages[groups[g].front()]).cpus);
      for (const auto& dep : s.depends) {
        ASSERT_TRUE(group_of.count(dep)) << s.kind << " before its input";
        EXPECT_LT(group_of[dep], g) << s.kind << " in the group of its input";
      }
      group_of[s.key] = g;
      ++grouped;
    }
  }
  EXPECT_EQ(grouped, stages.size());
  EXPECT_LT(groups.size(), stages.size());
  // The 4 models (2 num_ferns × 2 seeds) are one array, the 2 scans another.
  const auto size_of_kind = [&](const std::string& kind) { return groups[group_of[Kind(stages, kind).key]].size(); };
  EXPECT_EQ(size_of_kind("model"), 4u);
  EXPECT_EQ(size_of_kind("scans"), 2u);
  // Off: one stage per sbatch; complete or claimed stages are not submitted.
  EXPECT_EQ(GroupSlurmSubmissions(stages, submit, false).size(), stages.size());
  std::vector<SlurmStep> some = submit;
  some[0].action = SlurmAction::kDone;
  some[1].action = SlurmAction::kWait;
  size_t n = 0;
  for (const auto& g : GroupSlurmSubmissions(stages, some, true)) n += g.size();
  EXPECT_EQ(n, stages.size() - 2);
}

// The stages that read `key`, directly or not, and `key` itself.
std::set<std::string> Downstream(const std::vector<ExperimentStage>& stages, const std::string& key) {
  std::set<std::string> out = {key};
  for (const auto& s : stages)
    for (const auto& d : s.depends)
      if (out.count(d)) out.insert(s.key);
  return out;
}

TEST(Slurm, ArraysAreSubmittedOnceAndARerunResubmitsOnlyTheirFailedTasks) {
  FakeCluster fake = MakeFakeCluster("crease_slurm_array_test");
  const fs::path& root = fake.root;
  const SlurmOptions& slurm = fake.slurm;
  const ExperimentRunnerOptions& o = fake.options;
  const ExperimentConfig c = ParseExperimentConfig(TwoSeeds(), "toy.yaml");
  const auto stages = UniqueStages(c, o.cache);
  RunExperiments({ExperimentJob{c, o}}, SlurmBackend(slurm));
  const auto calls = Lines(root / "bin" / "sbatch.log");
  EXPECT_EQ(calls.size(), GroupSlurmSubmissions(stages, std::vector<SlurmStep>(stages.size()), true).size());
  EXPECT_LT(calls.size(), stages.size());
  // The models: one array, task i making model i, its script listing their plans.
  std::vector<ExperimentStage> models;
  for (const auto& s : stages)
    if (s.kind == "model") models.push_back(s);
  ASSERT_EQ(models.size(), 4u);
  const auto claim0 = ReadSlurmClaim(models[0]);
  ASSERT_TRUE(claim0);
  EXPECT_EQ(claim0->job_name, SlurmArrayName(models));
  for (int t = 0; t < 4; ++t) {
    const auto claim = ReadSlurmClaim(models[t]);
    EXPECT_EQ(claim->job_id, claim0->job_id);
    EXPECT_EQ(claim->task_id, t);
    EXPECT_EQ(claim->Id(), claim0->job_id + "_" + std::to_string(t));
    EXPECT_EQ(claim->output, (SlurmArrayDir(models) / ("slurm-" + claim->Id() + ".out")).string());
  }
  const std::string script = ReadFileToString(SlurmArrayDir(models) / "job.sh");
  EXPECT_NE(script.find("#SBATCH --array=0-3\n"), std::string::npos) << script;
  EXPECT_NE(script.find("experiment stage \"${plans[$SLURM_ARRAY_TASK_ID]}\"\n"), std::string::npos) << script;
  for (const auto& m : models) EXPECT_NE(script.find((SlurmJobDir(m) / "plan.json").string()), std::string::npos);
  // The array waits on the pairs array (the union of its tasks' inputs), by its job id.
  const std::string pairs_job = ReadSlurmClaim(Kind(stages, "pairs"))->job_id;
  for (const auto& line : calls) {
    if (line.find(SlurmArrayDir(models).string()) != std::string::npos) {
      EXPECT_NE(line.find("--dependency=afterok:" + pairs_job + " "), std::string::npos) << line;
    }
  }
  // A task still running shows in status by its task id; an ended job's state is kept
  // in its claim (the runner saw it end), which status shows once Slurm has forgotten it.
  EXPECT_EQ(ReadSlurmClaim(Kind(stages, "rig"))->final_state, "CANCELLED");
  std::ofstream(root / "bin" / "queue") << claim0->job_id << "_2|RUNNING|" << SlurmArrayName(models) << "|None\n";
  std::ofstream(root / "bin" / "scontrol") << "#!/bin/sh\nexit 1\n";  // Slurm forgot every ended job
  const auto status = ExperimentStageStatus(o.out, slurm);
  for (size_t i = 0; i < stages.size(); ++i) {
    if (stages[i].key == models[2].key) {
      EXPECT_EQ(status[i].state, "running");
      EXPECT_EQ(status[i].job_id, claim0->job_id + "_2");
    } else if (stages[i].kind == "rig") {
      EXPECT_EQ(status[i].state, "failed");
      EXPECT_EQ(status[i].job_state, "CANCELLED");
    }
  }
  // Every stage made but model task 1 and what reads it: the rerun submits those only.
  const std::set<std::string> failed = Downstream(stages, models[1].key);
  for (const auto& s : stages) {
    if (!failed.count(s.key)) {
      ASSERT_EQ(ExecuteStage(s, [](const auto&, const auto&) { return 0; }), "");
    }
  }
  RunExperiments({ExperimentJob{c, o}}, SlurmBackend(slurm));
  const auto all = Lines(root / "bin" / "sbatch.log");
  ASSERT_EQ(all.size(), calls.size() + failed.size());  // one of each kind: single jobs
  for (size_t i = calls.size(); i < all.size(); ++i) {
    bool names_a_failed_stage = false;
    for (const auto& s : stages)
      if (all[i].find(SlurmJobDir(s).string() + "/job.sh") != std::string::npos) names_a_failed_stage = failed.count(s.key);
    EXPECT_TRUE(names_a_failed_stage) << all[i];
  }
  fs::remove_all(root);
}

}  // namespace
}  // namespace crease
