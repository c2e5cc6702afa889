// Every Options struct of the project (issue 18): no two of its fields register one
// key, every key from before option sections (tests/data/old_option_keys.txt) either
// still works or is refused naming its new key, the keys are the checked-in list
// (tests/data/option_keys.txt), and no struct is missing from the list.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <gtest/gtest.h>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/options.h"
#include "core/preview_render.h"
#include "core/ray_caster.h"
#include "core/rig_import.h"
#include "eval/appearance_ceiling.h"
#include "eval/capture_metrics.h"
#include "eval/experiment.h"
#include "eval/realism_check.h"
#include "pipeline/capture/capture.h"
#include "pipeline/capture/detail_regression.h"
#include "pipeline/capture/flow_refinement.h"
#include "pipeline/capture/frame_texture.h"
#include "pipeline/capture/hifi_mesh.h"
#include "pipeline/capture/landmark_fit.h"
#include "pipeline/capture/landmarks.h"
#include "pipeline/capture/poisson_fill.h"
#include "pipeline/capture/shape_regressor.h"
#include "pipeline/capture/tracker.h"
#include "pipeline/capture/tracker_training.h"
#include "pipeline/training/detail_extraction.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/patch_baselines.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/pca.h"
#include "pipeline/training/rig_fit.h"
#include "pipeline/training/texture_extraction.h"
#include "pipeline/training/trainer.h"
#include "pipeline/training/wrinkle_map.h"
#include "synth/actor.h"
#include "synth/ict_head.h"
#include "synth/procedural_rig.h"
#include "synth/renderer.h"
#include "synth/scanned_head.h"
#include "synth/sensor.h"
#include "synth/studio.h"
#include "synth/studio_rig.h"
#include "synth/wrinkles.h"

namespace crease {
namespace {

// One Options struct: its keys (throws on a key registered twice) and a parse of a
// one-key JSON object (returns the error message, "" when accepted).
struct OptionsType {
  std::vector<std::string> (*keys)();
  std::string (*parse)(const std::string& json);
};

template <class Options>
OptionsType TypeOf() {
  return {&OptionFieldNames<Options>, [](const std::string& json) -> std::string {
            Options o;
            try {
              SetOptionsFromJson(json, "old.json", &o);
            } catch (const Error& e) {
              return e.what();
            }
            return "";
          }};
}

const std::map<std::string, OptionsType>& AllOptions() {
  static const std::map<std::string, OptionsType> all = {
      {"RigImportOptions", TypeOf<RigImportOptions>()},
      {"PreviewRenderOptions", TypeOf<PreviewRenderOptions>()},
      {"RayCasterOptions", TypeOf<RayCasterOptions>()},
      {"LowpassOptions", TypeOf<LowpassOptions>()},
      {"GeodesicOptions", TypeOf<GeodesicOptions>()},
      {"RenderOptions", TypeOf<RenderOptions>()},
      {"RendererOptions", TypeOf<RendererOptions>()},
      {"SensorOptions", TypeOf<SensorOptions>()},
      {"ScannedHeadOptions", TypeOf<ScannedHeadOptions>()},
      {"StudioOptions", TypeOf<StudioOptions>()},
      {"StudioRigOptions", TypeOf<StudioRigOptions>()},
      {"ActorOptions", TypeOf<ActorOptions>()},
      {"IctHeadOptions", TypeOf<IctHeadOptions>()},
      {"WrinkleStrainOptions", TypeOf<WrinkleStrainOptions>()},
      {"ProceduralRigOptions", TypeOf<ProceduralRigOptions>()},
      {"PcaOptions", TypeOf<PcaOptions>()},
      {"RigFitOptions", TypeOf<RigFitOptions>()},
      {"TextureOptions", TypeOf<TextureOptions>()},
      {"WrinkleMapOptions", TypeOf<WrinkleMapOptions>()},
      {"FernOptions", TypeOf<FernOptions>()},
      {"PatchLayoutOptions", TypeOf<PatchLayoutOptions>()},
      {"PatchBaselineOptions", TypeOf<PatchBaselineOptions>()},
      {"DetailExtractionOptions", TypeOf<DetailExtractionOptions>()},
      {"TrainingOptions", TypeOf<TrainingOptions>()},
      {"FlowRefinementOptions", TypeOf<FlowRefinementOptions>()},
      {"HifiMeshOptions", TypeOf<HifiMeshOptions>()},
      {"CaptureOptions", TypeOf<CaptureOptions>()},
      {"TrackerOptions", TypeOf<TrackerOptions>()},
      {"LandmarkFitOptions", TypeOf<LandmarkFitOptions>()},
      {"GroundTruthPriorOptions", TypeOf<GroundTruthPriorOptions>()},
      {"ShapeRegressorOptions", TypeOf<ShapeRegressorOptions>()},
      {"RegressorLandmarkOptions", TypeOf<RegressorLandmarkOptions>()},
      {"DlibLandmarkOptions", TypeOf<DlibLandmarkOptions>()},
      {"FrameTextureOptions", TypeOf<FrameTextureOptions>()},
      {"MesoscopicOptions", TypeOf<MesoscopicOptions>()},
      {"DetailRegressionOptions", TypeOf<DetailRegressionOptions>()},
      {"PoissonFillOptions", TypeOf<PoissonFillOptions>()},
      {"ReferenceAlignmentOptions", TypeOf<ReferenceAlignmentOptions>()},
      {"ExperimentDataset", TypeOf<ExperimentDataset>()},
      {"CaptureEvalOptions", TypeOf<CaptureEvalOptions>()},
      {"TrackerTrainingOptions", TypeOf<TrackerTrainingOptions>()},
      {"RealismCheckOptions", TypeOf<RealismCheckOptions>()},
      {"AppearanceCeilingOptions", TypeOf<AppearanceCeilingOptions>()},
  };
  return all;
}

TEST(OptionsRegistry, NoTwoFieldsOfAnyOptionsStructShareAKey) {
  for (const auto& [name, type] : AllOptions()) {
    SCOPED_TRACE(name);
    std::vector<std::string> keys;
    EXPECT_NO_THROW(keys = type.keys());
    EXPECT_FALSE(keys.empty());
  }
}

// Every key of every struct before option sections either still names a field or
// is refused naming exactly its new key (one of the struct's keys).
TEST(OptionsRegistry, OldFlatKeysNameTheirNewKey) {
  std::ifstream in(std::string(CREASE_TEST_DIR) + "/data/old_option_keys.txt");
  ASSERT_TRUE(in) << "tests/data/old_option_keys.txt";
  std::string type, key;
  int renamed = 0;
  while (in >> type >> key) {
    SCOPED_TRACE(type + " " + key);
    ASSERT_TRUE(AllOptions().count(type));
    const std::vector<std::string> keys = AllOptions().at(type).keys();
    if (std::find(keys.begin(), keys.end(), key) != keys.end()) continue;
    const std::string e = AllOptions().at(type).parse("{\"" + key + "\": 0}");
    const std::string prefix = "old.json: unknown option '" + key + "': it is now '";
    ASSERT_EQ(e.rfind(prefix, 0), 0u) << e;
    const std::string now = e.substr(prefix.size(), e.size() - prefix.size() - 1);
    EXPECT_NE(std::find(keys.begin(), keys.end(), now), keys.end()) << e;
    ++renamed;
  }
  EXPECT_GT(renamed, 100);
}

// The list above holds every struct with VisitFields in the project's headers.
TEST(OptionsRegistry, ListsEveryOptionsStruct) {
  namespace fs = std::filesystem;
  const fs::path root = fs::path(CREASE_TEST_DIR).parent_path();
  const std::regex owner(R"((?:struct|class) (\w+)[^;{]*\{)");
  std::set<std::string> found;
  for (const char* dir : {"core", "synth", "pipeline", "eval", "apps"}) {
    for (const auto& f : fs::recursive_directory_iterator(root / dir)) {
      if (f.path().extension() != ".h") continue;
      std::ifstream in(f.path());
      const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      // The struct a VisitFields declaration belongs to: the last one opened before it.
      for (size_t at = text.find("void VisitFields(OptionVisitor& v);"); at != std::string::npos;
           at = text.find("void VisitFields(OptionVisitor& v);", at + 1)) {
        std::string last;
        const std::string head = text.substr(0, at);
        for (std::sregex_iterator m(head.begin(), head.end(), owner), end; m != end; ++m) last = (*m)[1];
        found.insert(last);
      }
    }
  }
  for (const auto& name : found) EXPECT_TRUE(AllOptions().count(name)) << name << " is missing from AllOptions()";
  EXPECT_EQ(found.size(), AllOptions().size());
}

// Every struct's keys, one "Type key" line each (the format of the two key lists in
// tests/data), sorted: the order of the fields is no one's concern.
std::set<std::string> CurrentKeyLines() {
  std::set<std::string> lines;
  for (const auto& [name, type] : AllOptions())
    for (const auto& k : type.keys()) lines.insert(name + ' ' + k);
  return lines;
}

// The keys configs, models and pair files use are the checked-in list
// (tests/data/option_keys.txt): adding, renaming or removing one is a deliberate
// change seen in review, and a renamed key needs its old name in RenamedOptionKeys
// (core/options.cc) or the files that use it stop reading. On a mismatch the current
// list is written to option_keys.txt in the test's working folder (build/tests):
// copy it over tests/data/option_keys.txt when the change is intended.
TEST(OptionsRegistry, KeysAreTheCheckedInList) {
  std::ifstream in(std::string(CREASE_TEST_DIR) + "/data/option_keys.txt");
  ASSERT_TRUE(in) << "tests/data/option_keys.txt";
  std::set<std::string> expected;
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) expected.insert(line);
  const std::set<std::string> current = CurrentKeyLines();
  if (current == expected) return;
  std::ofstream("option_keys.txt") << fmt::format("{}\n", fmt::join(current, "\n"));
  std::vector<std::string> added, removed;
  std::set_difference(current.begin(), current.end(), expected.begin(), expected.end(), std::back_inserter(added));
  std::set_difference(expected.begin(), expected.end(), current.begin(), current.end(), std::back_inserter(removed));
  ADD_FAILURE() << "option keys differ from tests/data/option_keys.txt; new: [" << fmt::format("{}", fmt::join(added, ", "))
                << "], gone: [" << fmt::format("{}", fmt::join(removed, ", ")) << "]. The current list is in "
                << (std::filesystem::current_path() / "option_keys.txt").string()
                << "; if the change is intended, copy it to tests/data/option_keys.txt.";
}

}  // namespace
}  // namespace crease
