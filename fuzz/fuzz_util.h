// Helpers shared by the libFuzzer targets (issue 19). Each target feeds its input
// to one real crease loader; a crease::Error (the clean "<file>: problem" error a
// user sees) is an expected outcome. Anything else ends the run and is a finding:
// a sanitizer report (ASan, UBSan), a crash, a hang (-timeout), an allocation over
// -rss_limit_mb / -malloc_limit_mb, or another exception escaping the loader (the
// CLI would print "internal error" without naming the file).
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "core/error.h"

namespace crease::fuzz {

// A folder of this process under $TMPDIR (default /tmp), created on first use and
// removed when the process exits normally.
inline const std::filesystem::path& ScratchDir() {
  struct Scratch {
    std::filesystem::path dir;
    Scratch() {
      const char* tmp = std::getenv("TMPDIR");
      dir = std::filesystem::path(tmp && *tmp ? tmp : "/tmp") / ("crease-fuzz-" + std::to_string(::getpid()));
      std::filesystem::create_directories(dir);
    }
    ~Scratch() {
      std::error_code ignored;
      std::filesystem::remove_all(dir, ignored);
    }
  };
  static const Scratch scratch;
  return scratch.dir;
}

// Writes the input to `name` in the scratch folder (for loaders that take a path;
// the extension selects the format) and returns its path.
inline std::filesystem::path WriteInput(const uint8_t* data, size_t size, const std::string& name) {
  const std::filesystem::path path = ScratchDir() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) std::abort();  // the fuzzer's own failure (disk full), not the loader's
  return path;
}

inline std::string AsString(const uint8_t* data, size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

// Runs `load`; crease::Error is the expected way to refuse bad input.
template <class Load>
void ExpectCleanErrors(Load&& load) {
  try {
    load();
  } catch (const crease::Error&) {
  }
}

}  // namespace crease::fuzz
