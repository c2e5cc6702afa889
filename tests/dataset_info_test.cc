// core/dataset_info.h: dataset.json's one reader checks every field and names the
// file and the key (issue 18: one typed reader; issue 19: bad values refused).
#include "core/dataset_info.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/json_io.h"
#include "tests/test_util.h"

namespace crease {
namespace {
namespace fs = std::filesystem;
using crease::testing::ErrorOf;
using crease::testing::TestDir;
using crease::testing::WriteText;

// What `crease synth sequence` writes (synth/dataset.cc), trimmed to the keys read.
nlohmann::json Written() {
  return {{"format", SequenceDatasetInfo::kFormat},
          {"version", SequenceDatasetInfo::kVersion},
          {"sequence", "talking"},
          {"first_frame", 3},
          {"frames", 5},
          {"fps", 25.0},
          {"width", 640},
          {"height", 480},
          {"rig", "rig.crig"},
          {"tracking_rig", "tracking_rig.crig"},
          {"files",
           {{"frame", "frames/{frame:06d}.png"}, {"expression_displacement", "maps/{frame:06d}_d.exr"}}}};
}

// The error of reading a dataset whose dataset.json is `j` ("" when it reads).
std::string ReadError(const nlohmann::json& j) {
  const fs::path dir = TestDir();
  WriteJsonFile(dir / "dataset.json", j);
  return ErrorOf([&] { ReadSequenceDatasetInfo(dir); });
}

TEST(DatasetInfo, ReadsWhatTheStudioWrites) {
  const fs::path dir = TestDir();
  WriteJsonFile(dir / "dataset.json", Written());
  ASSERT_TRUE(IsSequenceDataset(dir));
  const SequenceDatasetInfo d = ReadSequenceDatasetInfo(dir);
  EXPECT_EQ(d.sequence, "talking");
  EXPECT_EQ(d.first_frame, 3);
  EXPECT_EQ(d.last_frame(), 7);
  EXPECT_TRUE(d.HasFrame(7));
  EXPECT_FALSE(d.HasFrame(8));
  EXPECT_FALSE(d.HasFrame(2));
  EXPECT_DOUBLE_EQ(d.fps, 25.0);
  EXPECT_EQ(d.width, 640);
  EXPECT_EQ(d.FramePath(4), dir / "frames/000004.png");
  EXPECT_EQ(d.TruthPath(4), dir / "truth/000004.json");
  EXPECT_EQ(d.DisplacementPath(12), dir / "maps/000012_d.exr");
  EXPECT_EQ(d.RigPath(), dir / "rig.crig");
  EXPECT_EQ(d.TrackingRigPath(), dir / "tracking_rig.crig");
  // Without a tracking rig the rig is tracked; without maps D^t cannot be scored.
  nlohmann::json j = Written();
  j.erase("tracking_rig");
  j["files"]["expression_displacement"] = "";
  WriteJsonFile(dir / "dataset.json", j);
  const SequenceDatasetInfo e = ReadSequenceDatasetInfo(dir);
  EXPECT_EQ(e.TrackingRigPath(), dir / "rig.crig");
  EXPECT_NE(ErrorOf([&] { e.DisplacementPath(3); }).find("rendered with --no-maps"), std::string::npos);
}

TEST(DatasetInfo, RefusesBadFieldsNamingFileAndKey) {
  EXPECT_EQ(ReadError(Written()), "");
  auto with = [](const char* key, const nlohmann::json& value) {
    nlohmann::json j = Written();
    j[key] = value;
    return ReadError(j);
  };
  EXPECT_NE(with("version", 99).find("dataset.json: version 99 is not supported"), std::string::npos);
  EXPECT_NE(with("format", "other").find("format must be \"crease synthetic sequence\""), std::string::npos);
  EXPECT_NE(with("width", -640).find("width = -640 is outside [16, 8192]"), std::string::npos);
  EXPECT_NE(with("height", 1.5).find("height must be an integer"), std::string::npos);
  EXPECT_NE(with("frames", 0).find("frames = 0 is outside"), std::string::npos);
  EXPECT_NE(with("first_frame", "3").find("first_frame must be an integer"), std::string::npos);
  EXPECT_NE(with("fps", -1.0).find("fps must be a number in (0, 1000]"), std::string::npos);
  EXPECT_NE(with("rig", "/dev/zero").find("rig = \"/dev/zero\" must be a relative path"), std::string::npos);
  EXPECT_NE(with("tracking_rig", "../x.crig").find("tracking_rig = \"../x.crig\""), std::string::npos);
  EXPECT_NE(with("files", 3).find("files must be an object"), std::string::npos);
  nlohmann::json no_frames = Written();
  no_frames.erase("frames");
  EXPECT_NE(ReadError(no_frames).find("dataset.json: the key 'frames' is missing"), std::string::npos);
  EXPECT_NE(ReadError(nlohmann::json::array({1, 2})).find("must be a JSON object"), std::string::npos);
  nlohmann::json wide = Written();
  wide["files"]["expression_displacement"] = "maps/{frame:999999999d}.exr";
  EXPECT_NE(ReadError(wide).find("files.expression_displacement = "), std::string::npos);
  const fs::path dir = TestDir();
  EXPECT_NE(ErrorOf([&] { ReadSequenceDatasetInfo(dir); }).find("dataset.json: missing"), std::string::npos);
  WriteText(dir / "dataset.json", "{\"frames\": 1e400}");
  EXPECT_NE(ErrorOf([&] { ReadSequenceDatasetInfo(dir); }).find("dataset.json: malformed JSON"), std::string::npos);
}

// Issue 19: files.frame "{frame:999999999d}" made eval take 6.2 GB; a frame pattern
// is checked when dataset.json is read, naming the file and the key.
TEST(DatasetInfo, FramePatternIsChecked) {
  const fs::path file = "ds/dataset.json";
  auto pattern = [&](const nlohmann::json& frame) {
    return DatasetFramePattern({{"files", {{"frame", frame}}}}, file);
  };
  EXPECT_EQ(DatasetFramePattern(nlohmann::json::object(), file), "frames/{frame:06d}.png");
  EXPECT_EQ(pattern("img/{frame:04d}.png"), "img/{frame:04d}.png");
  EXPECT_EQ(pattern("{{x}}/{frame}.png"), "{{x}}/{frame}.png");
  auto error = [&](const nlohmann::json& frame) { return ErrorOf([&] { pattern(frame); }); };
  EXPECT_NE(error("frames/{frame:999999999d}.png").find("ds/dataset.json: files.frame = "), std::string::npos);
  EXPECT_NE(error("frames/{frame:999999999d}.png").find("pads wider than 32 characters"), std::string::npos);
  EXPECT_NE(error("frames/{index:06d}.png").find("the only field is {frame}, not {index:06d}"), std::string::npos);
  EXPECT_NE(error("frames/{frame:06q}.png").find("is not a valid pattern"), std::string::npos);
  EXPECT_NE(error("frames/{frame").find("is not closed"), std::string::npos);
  EXPECT_NE(error(7).find("ds/dataset.json: files.frame must be a string"), std::string::npos);
  EXPECT_NE(error("").find("files.frame must not be empty"), std::string::npos);
}

}  // namespace
}  // namespace crease
