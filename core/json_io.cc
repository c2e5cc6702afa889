#include "core/json_io.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_util.h"

namespace crease {

nlohmann::json ReadJsonFile(const std::filesystem::path& path) {
  const std::string text = ReadFileToString(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    // Translate the byte offset into line:column for a person.
    size_t line = 1, col = 1;
    for (size_t i = 0; i < std::min(text.size(), e.byte > 0 ? e.byte - 1 : 0); ++i) {
      if (text[i] == '\n') {
        ++line;
        col = 1;
      } else {
        ++col;
      }
    }
    throw Error(fmt::format("{}:{}:{}: malformed JSON ({})", path.string(), line, col, e.what()));
  } catch (const nlohmann::json::exception& e) {
    // A number beyond double's range (1e400) is out_of_range.406 while parsing
    // (found by fuzz/camera_json_fuzzer, issue 19).
    throw Error(fmt::format("{}: malformed JSON ({})", path.string(), e.what()));
  }
}

void WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& j, int indent) {
  const std::string text = j.dump(indent) + "\n";
  WriteFileAtomic(path, [&](std::ostream& out) { out << text; });
}

}  // namespace crease
