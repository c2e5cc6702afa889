// JSON files. Kept out of widely included headers: include <nlohmann/json.hpp>
// only where JSON is built or read. Writes are atomic (core/file_util.h).
#pragma once

#include <filesystem>
#include <nlohmann/json_fwd.hpp>

namespace crease {

// Parses a JSON file; errors name the file, and the line/column for syntax errors.
nlohmann::json ReadJsonFile(const std::filesystem::path& path);

// Writes `j` with `indent` (-1: compact), atomically, with a trailing newline.
void WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& j, int indent = 2);

}  // namespace crease
