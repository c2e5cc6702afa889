// Helpers shared by crease's tests.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "core/error.h"
#include "core/rig_import.h"

namespace crease::testing {

// The message of the crease::Error that `f` throws, "" when it throws none.
inline std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// A fresh, empty folder for the running test under GoogleTest's temp dir.
inline std::filesystem::path TestDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "crease_tests" /
                                    (std::string(info->test_suite_name()) + "." + info->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

inline void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// The bundled sample rig (data/sample_rig: a blendshape OBJ folder in cm), imported once.
inline const FaceRig& SampleRig() {
  static const FaceRig rig = [] {
    RigImportOptions options;
    options.units_to_mm = 10.0;
    return ImportObjRig(std::filesystem::path(CREASE_DATA_DIR) / "sample_rig", options);
  }();
  return rig;
}

}  // namespace crease::testing

// Expects `call` to throw a crease::Error whose message contains `text`.
#define EXPECT_ERROR_HAS(call, text)                                              \
  do {                                                                            \
    const std::string message_ = ::crease::testing::ErrorOf([&] { call; });       \
    EXPECT_NE(message_.find(text), std::string::npos) << "message: " << message_; \
  } while (false)
