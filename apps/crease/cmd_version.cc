#include <algorithm>
#include <cstdio>
#include <string>

#include <CLI/Version.hpp>
#include <Eigen/Core>
#include <ceres/version.h>
#include <embree3/rtcore_config.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <oneapi/tbb/version.h>
#include <opencv2/core/version.hpp>
#include <OpenImageIO/oiioversion.h>
#include <vtkVersionMacros.h>

#include "apps/crease/commands.h"
#include "core/error.h"

namespace crease::app {

std::vector<std::string> SplitComma(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    const size_t end = std::min(s.find(',', start), s.size());
    if (end > start) out.push_back(s.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

std::string SetPairsToJson(const std::vector<std::string>& pairs) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& p : pairs) {
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0) throw Error(fmt::format("--set '{}': expected KEY=VALUE", p));
    const std::string value = p.substr(eq + 1);
    nlohmann::json v = nlohmann::json::parse(value, nullptr, /*allow_exceptions=*/false);
    if (v.is_discarded()) v = value;
    j[p.substr(0, eq)] = v;
  }
  return j.dump();
}

void ParseSizeFlag(const std::string& size, const std::string& example, int* width, int* height) {
  if (size.empty()) return;
  const auto x = size.find('x');
  try {
    if (x == std::string::npos) throw std::invalid_argument("no x");
    *width = std::stoi(size.substr(0, x));
    *height = std::stoi(size.substr(x + 1));
  } catch (const std::exception&) {
    throw Error(fmt::format("--size '{}': expected WIDTHxHEIGHT, e.g. {}", size, example));
  }
}

void AddVersionCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("version", "Print crease's version and the libraries it was built with");
  cmd->callback([] {
    std::printf("crease %s\n", CREASE_VERSION);
    std::printf("  compiler     %s\n", __VERSION__);
    std::printf("  Eigen        %d.%d.%d\n", EIGEN_WORLD_VERSION, EIGEN_MAJOR_VERSION, EIGEN_MINOR_VERSION);
    std::printf("  OpenCV       %s\n", CV_VERSION);
    std::printf("  Embree       %s\n", RTC_VERSION_STRING);
    std::printf("  OpenImageIO  %s\n", OIIO_VERSION_STRING);
    std::printf("  VTK          %s\n", VTK_VERSION);
    std::printf("  Ceres        %s\n", CERES_VERSION_STRING);
    std::printf("  oneTBB       %s\n", TBB_VERSION_STRING);
    std::printf("  CLI11        %s\n", CLI11_VERSION);
    std::printf("  nlohmann     %d.%d.%d\n", NLOHMANN_JSON_VERSION_MAJOR, NLOHMANN_JSON_VERSION_MINOR,
                NLOHMANN_JSON_VERSION_PATCH);
    std::printf("  fmt          %d.%d.%d\n", FMT_VERSION / 10000, FMT_VERSION / 100 % 100, FMT_VERSION % 100);
  });
}

}  // namespace crease::app
