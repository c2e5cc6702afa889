#include "synth/sequence.h"

#include <gtest/gtest.h>

#include "core/face_rig.h"
#include "core/mesh_primitives.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;

TEST(Sequence, PresetsAreValidAndDoWhatTheySay) {
  for (const auto& name : SequencePresetNames()) {
    const Sequence s = MakePresetSequence(name);
    EXPECT_NO_THROW(s.Validate(name));
    EXPECT_GT(s.num_frames(), 60) << name;
    EXPECT_EQ(s.fps, 30.0);
  }
  // wrinkle-workout: a full brow raise, starting and ending neutral.
  const Sequence w = MakePresetSequence("wrinkle-workout");
  double peak = 0;
  for (int i = 0; i < w.num_frames(); ++i) peak = std::max(peak, w.Frame(i).expression["browInnerUp"]);
  EXPECT_EQ(peak, 1.0);
  EXPECT_EQ(w.Frame(0).expression["browInnerUp"], 0.0);
  EXPECT_EQ(w.Frame(w.num_frames() - 1).expression["jawOpen"], 0.0);
  // moving-light: from the front (elevation 0) to above (80), monotonically, expression held.
  const Sequence m = MakePresetSequence("moving-light");
  double last = -1;
  for (int i = m.num_frames() / 10 + 3; i < m.num_frames(); ++i) {
    const SequenceFrame f = m.Frame(i);
    EXPECT_GE(f.light_elevation_deg, last);
    last = f.light_elevation_deg;
    EXPECT_EQ(f.expression.at("browInnerUp"), 1.0);
  }
  EXPECT_NEAR(last, 80.0, 1e-9);
  EXPECT_TRUE(MakePresetSequence("fast-motion").motion_blur);
  // occlusion: the occluder crosses the face (x changes sign).
  const Sequence o = MakePresetSequence("occlusion");
  EXPECT_TRUE(o.Frame(0).has_occluder);
  EXPECT_GT(o.Frame(0).occluder_x_mm, 0);
  EXPECT_LT(o.Frame(o.num_frames() - 1).occluder_x_mm, 0);
  // workout-talking: the workout's brow raise first (talking's jaw not leaking back
  // before the junction), talking afterwards.
  const Sequence wt = MakePresetSequence("workout-talking", 7.0);
  EXPECT_NEAR(wt.duration_s, 7.0, 1e-9);
  double brow = 0, jaw_early = 0, jaw_late = 0;
  for (int i = 0; i < wt.num_frames(); ++i) {
    const SequenceFrame f = wt.Frame(i);
    auto get = [&](const char* c) { return f.expression.count(c) ? f.expression.at(c) : 0.0; };
    if (f.time_s < 1.2) {
      brow = std::max(brow, get("browInnerUp"));
      jaw_early = std::max(jaw_early, get("jawOpen"));
    }
    if (f.time_s > 4.6) jaw_late = std::max(jaw_late, get("jawOpen"));
  }
  EXPECT_EQ(brow, 1.0);
  EXPECT_EQ(jaw_early, 0.0);
  EXPECT_GT(jaw_late, 0.05);
  // scan-holds: each scan expression at exactly its scan weights over its hold,
  // nothing else on, the head still; neutral before the first and between holds.
  const Sequence h = MakePresetSequence("scan-holds");
  EXPECT_EQ(h.Frame(0).expression.at("browInnerUp"), 0.0);
  for (size_t i = 0; i < ScanExpressionSpecs().size(); ++i) {
    const auto weights = ParseExpressionWeights(ScanExpressionSpecs()[i]);
    const auto [first, last] = ScanHoldFrames(static_cast<int>(i));
    EXPECT_GE(last - first, 29) << i;  // 1 s at 30 fps
    for (int t : {first, (first + last) / 2, last}) {
      const SequenceFrame f = h.Frame(t);
      EXPECT_EQ(f.yaw_deg, 0.0);
      for (const auto& [name, v] : f.expression) {
        EXPECT_NEAR(v, weights.count(name) ? weights.at(name) : 0.0, 1e-12) << "hold " << i << " frame " << t << " " << name;
      }
    }
    for (const auto& [name, v] : h.Frame(last + 15).expression) EXPECT_NEAR(v, 0.0, 1e-12) << "after hold " << i;
    EXPECT_LT(h.Frame(first - 3).expression.at(weights.begin()->first), weights.begin()->second) << "ramp " << i;
  }
  // Scaled to 4.3 s (half its length): the holds keep their place, scaled.
  const Sequence h2 = MakePresetSequence("scan-holds", 4.3);
  EXPECT_EQ(h2.num_frames(), 130);
  const auto [first2, last2] = ScanHoldFrames(2, 30.0, 4.3);
  EXPECT_EQ(first2, (ScanHoldFrames(2).first + 1) / 2);
  EXPECT_EQ(h2.Frame(last2).expression.at("mouthSmile"), 1.0);
  EXPECT_LT(h2.Frame(last2 + 3).expression.at("mouthSmile"), 1.0);
  EXPECT_NE(ErrorOf([] { ScanHoldFrames(4); }).find("hold 4 is out of range (it has 4)"), std::string::npos);
  EXPECT_EQ(ParseExpressionWeights("browDown=1,,mouthSmile=0.5").at("mouthSmile"), 0.5);
  EXPECT_NE(ErrorOf([] { ParseExpressionWeights("browDown"); }).find("browDown"), std::string::npos);
  // Same preset, same values: presets are deterministic.
  EXPECT_EQ(MakePresetSequence("talking").Frame(37).expression, MakePresetSequence("talking").Frame(37).expression);
  EXPECT_NE(ErrorOf([] { MakePresetSequence("dancing"); }).find("unknown sequence preset 'dancing'"),
            std::string::npos);
}

TEST(Sequence, InterpolationHitsKeysAndStaysBetweenThem) {
  Sequence s;
  s.keys = {{0.0, {{"expression:a", 0.0}, {"pose:yaw_deg", -10}}},
            {1.0, {{"expression:a", 1.0}}},
            {2.0, {{"expression:a", 0.2}, {"pose:yaw_deg", 10}}}};
  s.duration_s = 3.0;
  for (const char* mode : {"linear", "smooth", "catmull-rom"}) {
    s.interpolation = mode;
    s.Validate("s");
    EXPECT_DOUBLE_EQ(s.At(1.0).expression["a"], 1.0) << mode;
    EXPECT_DOUBLE_EQ(s.At(2.5).expression["a"], 0.2) << mode;  // held after the last key
    // Channels are independent: yaw has keys at 0 and 2 only.
    EXPECT_NEAR(s.At(1.0).yaw_deg, 0.0, 1e-12) << mode;
  }
  s.interpolation = "linear";
  EXPECT_DOUBLE_EQ(s.At(0.25).expression["a"], 0.25);
  s.interpolation = "smooth";
  for (double t = 0; t <= 1.0; t += 0.01) {
    const double v = s.At(t).expression["a"];
    EXPECT_GE(v, 0.0);
    EXPECT_LE(v, 1.0);
  }
  EXPECT_EQ(s.num_frames(), 91);
  EXPECT_NE(ErrorOf([&] { s.Frame(91); }).find("out of range"), std::string::npos);
}

TEST(Sequence, YamlRoundTripAndErrors) {
  const Sequence a = MakePresetSequence("talking", 2.0);
  const Sequence b = ParseSequenceYaml(SequenceToYaml(a), "rt.yaml");
  ASSERT_EQ(a.keys.size(), b.keys.size());
  for (size_t i = 0; i < a.keys.size(); ++i) {
    EXPECT_EQ(a.keys[i].t, b.keys[i].t);
    EXPECT_EQ(a.keys[i].values, b.keys[i].values);
  }
  EXPECT_EQ(a.interpolation, b.interpolation);
  EXPECT_EQ(a.duration_s, b.duration_s);

  const std::string ok = "name: x\nkeys:\n  - t: 0\n    expression: {jawOpen: 0}\n  - t: 1\n    expression: {jawOpen: 1}\n";
  EXPECT_EQ(ParseSequenceYaml(ok, "ok.yaml").num_frames(), 31);
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("keys: [", "m.yaml"); }).find("m.yaml: malformed YAML"), std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("keys:\n  - t: 0\n    pose: {yawn: 3}\n", "p.yaml"); })
                .find("p.yaml: keys[0].pose: unknown field 'yawn'"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("keys:\n  - t: 1\n  - t: 0.5\n", "t.yaml"); }).find("key 1: times must increase"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("keys:\n  - t: 0\n    expression: {a: lots}\n", "n.yaml"); })
                .find("n.yaml: keys[0].expression.a: expected a number"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("frames: 3\nkeys:\n  - t: 0\n", "f.yaml"); }).find("unknown field 'frames'"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("keys: []\n", "e.yaml"); }).find("non-empty list"), std::string::npos);
  // Issue 19 (fuzz/sequence_yaml_fuzzer): a list where a string belongs was yaml-cpp's
  // bad conversion, an internal error without the file.
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("name:\n  - t: 0\nkeys:\n  - t: 0\n", "l.yaml"); })
                .find("l.yaml:2:3: expected a single value here, not a list or mapping"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseSequenceYaml("keys:\n  - t: 0\n    [pose]: 1\n", "k.yaml"); })
                .find("k.yaml:3:5: expected a single value here"),
            std::string::npos);
}

TEST(Sequence, ExpressionNamesResolveOntoLeftRightPairs) {
  FaceRig rig;
  rig.neutral = MakeGrid(1, 1, 1, 1);
  rig.expression_basis = Eigen::MatrixXf::Zero(12, 3);
  rig.expression_names = {"jawOpen", "mouthSmile_L", "mouthSmile_R"};
  rig.identity_basis.resize(12, 0);
  SequenceFrame f;
  f.expression = {{"jawOpen", 0.5}, {"mouthSmile", 0.8}};
  EXPECT_EQ(ExpressionWeightsForRig(f, rig), (std::vector<double>{0.5, 0.8, 0.8}));
  f.expression = {{"browDown", 1.0}};
  EXPECT_NE(ErrorOf([&] { ExpressionWeightsForRig(f, rig); }).find("expression 'browDown', which the rig lacks"),
            std::string::npos);
}

}  // namespace
}  // namespace crease
