#include "core/json_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/rng.h"
#include "test_util.h"

namespace crease {
namespace {
namespace fs = std::filesystem;

TEST(JsonIo, RoundTripIsExactForDoubles) {
  const fs::path p = ::crease::testing::TestDir() / "crease_json_rt.json";
  Rng rng(5);
  nlohmann::json j;
  std::vector<double> values;
  for (int i = 0; i < 1000; ++i) values.push_back(rng.Normal() * std::pow(10.0, rng.UniformInt(-30, 30)));
  values.push_back(std::numeric_limits<double>::denorm_min());
  values.push_back(0.1);
  j["values"] = values;
  j["name"] = "ünïcode";
  WriteJsonFile(p, j);
  const nlohmann::json back = ReadJsonFile(p);
  EXPECT_EQ(back["values"].get<std::vector<double>>(), values);
  EXPECT_EQ(back["name"], "ünïcode");
}

TEST(JsonIo, MalformedFileNamesLineAndColumn) {
  const fs::path p = ::crease::testing::TestDir() / "crease_json_bad.json";
  std::ofstream(p) << "{\n  \"a\": 1,\n  \"b\": ]\n}\n";
  try {
    ReadJsonFile(p);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(p.string() + ":3:"), std::string::npos) << e.what();
  }
  try {
    ReadJsonFile(::crease::testing::TestDir() / "does_not_exist.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("file does not exist"), std::string::npos);
  }
}

// Issue 19 (fuzz/camera_json_fuzzer): a number beyond double's range was an
// nlohmann out_of_range exception ("internal error" without the file).
TEST(JsonIo, NumberOutOfRangeNamesTheFile) {
  const fs::path p = ::crease::testing::TestDir() / "crease_json_1e400.json";
  std::ofstream(p) << "{\"fx\": 1e400}";
  try {
    ReadJsonFile(p);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(p.string() + ": malformed JSON"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("1e400"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace crease
