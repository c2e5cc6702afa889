// Helpers shared by crease's tests.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <system_error>
#include <vector>

#include <unistd.h>

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

// Removes `dir` when the process exits after all its tests passed (a failed test's
// files stay for a look).
inline void RemoveAtExitIfPassed(const std::filesystem::path& dir) {
  static std::vector<std::filesystem::path> dirs;
  if (dirs.empty()) {
    std::atexit([] {
      if (!::testing::UnitTest::GetInstance()->Passed()) return;
      std::error_code ec;
      for (const auto& d : dirs) std::filesystem::remove_all(d, ec);
    });
  }
  dirs.push_back(dir);
}

// An absent folder crease_tests/NAME_PID under GoogleTest's temp dir (removed if a
// dead run left it), removed again when the process exits after its tests passed and
// kept for a look when one failed. The process id keeps two suites that run at once
// (a CI clone beside a developer's run) from clearing each other's folders.
inline std::filesystem::path ProcessTempDir(const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / "crease_tests" / (name + "_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  RemoveAtExitIfPassed(dir);
  return dir;
}

// A fresh, empty folder for the running test: ProcessTempDir("SUITE.NAME").
inline std::filesystem::path TestDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = ProcessTempDir(std::string(info->test_suite_name()) + "." + info->name());
  std::filesystem::create_directories(dir);
  return dir;
}

inline void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// The bundled sample rig (data/sample_rig: a blendshape OBJ folder in cm), imported once.
// A crease array file's bytes (magic 8 bytes, version u32, header length u64, the
// JSON header, the arrays) with its header replaced by edit(header) and the length
// field updated: for tests of malformed headers.
inline std::string EditArrayFileHeader(std::string bytes, const std::function<std::string(std::string)>& edit) {
  uint64_t length = 0;
  std::memcpy(&length, bytes.data() + 12, sizeof(length));
  const std::string header = edit(bytes.substr(20, length));
  const uint64_t new_length = header.size();
  bytes.replace(20, length, header);
  std::memcpy(bytes.data() + 12, &new_length, sizeof(new_length));
  return bytes;
}

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
