#include "pipeline/capture/capture_io.h"

#include <climits>
#include <cstdint>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/array_file.h"
#include "core/error.h"
#include "core/json_io.h"
#include "core/options.h"

namespace crease {

namespace {

constexpr char kMagic[] = "CREASCFR";

template <int C>
std::vector<float> ToFloat(const Eigen::Matrix<double, Eigen::Dynamic, C, Eigen::RowMajor>& m) {
  std::vector<float> out(static_cast<size_t>(m.size()));
  for (Eigen::Index i = 0; i < m.size(); ++i) out[static_cast<size_t>(i)] = static_cast<float>(m.data()[i]);
  return out;
}

template <int C>
Eigen::Matrix<double, Eigen::Dynamic, C, Eigen::RowMajor> FromFloat(const std::vector<float>& v) {
  Eigen::Matrix<double, Eigen::Dynamic, C, Eigen::RowMajor> m(static_cast<Eigen::Index>(v.size() / C), C);
  for (size_t i = 0; i < v.size(); ++i) m.data()[i] = v[i];
  return m;
}

}  // namespace

CaptureFrameArrays MakeCaptureFrameArrays(const CapturedFrame& frame) {
  CaptureFrameArrays a;
  a.frame = frame.frame;
  a.tracked = frame.has_mesh;
  a.coarse = frame.coarse;
  a.refined = frame.refined;
  a.landmarks = frame.tracked.landmarks;
  const RefinedFrame& r = frame.refinement;
  if (frame.has_mesh && r.refined) {
    a.flow_vertex = r.flow_vertex;
    for (FlowPointStatus st : r.status) a.flow_status.push_back(static_cast<uint8_t>(st));
    a.flow_projected = r.projected_positions;
    a.flow_positions = r.flow_positions;
    a.flow_fitted = r.fit_positions;
  }
  return a;
}

void WriteCaptureFrameArrays(const std::filesystem::path& path, const CaptureFrameArrays& frame) {
  Require(frame.coarse.rows() == frame.refined.rows(),
          fmt::format("{}: L^t has {} vertices but L~^t {}", path.string(), frame.coarse.rows(), frame.refined.rows()));
  nlohmann::json header;
  header["frame"] = frame.frame;
  header["tracked"] = frame.tracked;
  header["num_vertices"] = frame.coarse.rows();
  ArrayFileWriter writer(header.dump());
  const std::vector<float> coarse = ToFloat<3>(frame.coarse), refined = ToFloat<3>(frame.refined);
  const std::vector<float> landmarks = ToFloat<2>(frame.landmarks);
  writer.Add("coarse", coarse.data(), {frame.coarse.rows(), 3});
  writer.Add("refined", refined.data(), {frame.refined.rows(), 3});
  writer.Add("landmarks", landmarks.data(), {frame.landmarks.rows(), 2});
  const int64_t nf = static_cast<int64_t>(frame.flow_vertex.size());
  std::vector<float> projected, positions, fitted;
  if (nf > 0) {
    Require(static_cast<int64_t>(frame.flow_status.size()) == nf && frame.flow_projected.rows() == nf &&
                frame.flow_positions.rows() == nf && frame.flow_fitted.rows() == nf,
            fmt::format("{}: the flow point arrays disagree in size", path.string()));
    projected = ToFloat<2>(frame.flow_projected);
    positions = ToFloat<2>(frame.flow_positions);
    fitted = ToFloat<2>(frame.flow_fitted);
    writer.Add("flow_vertex", frame.flow_vertex.data(), {nf});
    writer.Add("flow_status", frame.flow_status.data(), {nf});
    writer.Add("flow_projected", projected.data(), {nf, 2});
    writer.Add("flow_positions", positions.data(), {nf, 2});
    writer.Add("flow_fitted", fitted.data(), {nf, 2});
  }
  writer.Write(path, kMagic, CaptureFrameArrays::kFormatVersion);
}

CaptureFrameArrays ReadCaptureFrameArrays(const std::filesystem::path& path) {
  const ArrayFile file = ReadArrayFile(path, kMagic, CaptureFrameArrays::kFormatVersion, "capture frame");
  const std::string what = path.string();
  nlohmann::json header;
  try {
    header = nlohmann::json::parse(file.header_json);
  } catch (const std::exception& e) {
    throw Error(fmt::format("{}: malformed header ({})", what, e.what()));
  }
  Require(header.is_object() && header.contains("frame") && header["frame"].is_number_integer() &&
              header.contains("tracked") && header["tracked"].is_boolean() && header.contains("num_vertices") &&
              header["num_vertices"].is_number_integer() && header["num_vertices"].get<int64_t>() >= 0,
          fmt::format("{}: header lacks an integer frame, a boolean tracked or a count num_vertices", what));
  // Issue 19 (cfr_fuzzer): a count near 2^63 overflowed 3 × n.
  Require(header["num_vertices"].get<int64_t>() <= kMaxCaptureVertices &&
              header["frame"].get<int64_t>() >= 0 && header["frame"].get<int64_t>() <= INT32_MAX,
          fmt::format("{}: num_vertices above {} or a frame number outside [0, 2^31)", what, kMaxCaptureVertices));
  CaptureFrameArrays out;
  out.frame = header["frame"].get<int>();
  out.tracked = header["tracked"].get<bool>();
  const int64_t n = header["num_vertices"].get<int64_t>();
  out.coarse = FromFloat<3>(file.Get<float>("coarse", 3 * n, what));
  out.refined = FromFloat<3>(file.Get<float>("refined", 3 * n, what));
  const std::vector<float> lm = file.Get<float>("landmarks", -1, what);
  Require(lm.size() % 2 == 0, fmt::format("{}: landmarks array has an odd size", what));
  out.landmarks = FromFloat<2>(lm);
  // A tracked frame's meshes and landmarks are numbers (issue 19: eval computed on NaN).
  Require(!out.tracked || (out.coarse.allFinite() && out.refined.allFinite() && out.landmarks.allFinite()),
          fmt::format("{}: a tracked frame holds NaN or infinite coordinates in coarse, refined or landmarks", what));
  if (file.arrays.count("flow_vertex")) {
    const std::vector<int32_t> ids = file.Get<int32_t>("flow_vertex", -1, what);
    const int64_t nf = static_cast<int64_t>(ids.size());
    for (int32_t v : ids) {
      Require(v >= 0 && v < n, fmt::format("{}: flow point vertex {} outside the {} vertices", what, v, n));
    }
    out.flow_vertex.assign(ids.begin(), ids.end());
    out.flow_status = file.Get<uint8_t>("flow_status", nf, what);
    out.flow_projected = FromFloat<2>(file.Get<float>("flow_projected", 2 * nf, what));
    out.flow_positions = FromFloat<2>(file.Get<float>("flow_positions", 2 * nf, what));
    out.flow_fitted = FromFloat<2>(file.Get<float>("flow_fitted", 2 * nf, what));
  }
  return out;
}

nlohmann::json ReadCaptureJson(const std::filesystem::path& path) {
  const std::string what = path.string();
  const nlohmann::json j = ReadJsonFile(path);
  Require(j.is_object(), fmt::format("{}: not a JSON object (a `crease capture` summary)", what));
  auto field = [&what](const char* key) { return fmt::format("{}: field '{}'", what, key); };
  const auto frames = j.find("frame_indices");
  Require(frames != j.end() && frames->is_array(), field("frame_indices") + " must be a list of frame numbers");
  for (const nlohmann::json& f : *frames) {
    Require(f.is_number_integer() && f.get<int64_t>() >= 0 && f.get<int64_t>() <= INT32_MAX,
            field("frame_indices") + " holds a value that is not a frame number");
  }
  if (j.contains("map_resolution")) {
    const nlohmann::json& r = j["map_resolution"];
    Require(r.is_number_integer() && r.get<int64_t>() >= 1 && r.get<int64_t>() <= kMaxCaptureMapResolution,
            field("map_resolution") + fmt::format(" must be an integer in [1, {}]", kMaxCaptureMapResolution));
  }
  for (const char* key : {"options", "detail_extraction", "timing"}) {
    if (j.contains(key)) Require(j[key].is_object(), field(key) + " must be an object");
  }
  for (const char* key : {"fps", "tracking_share", "detail_share"}) {
    if (j.contains(key)) Require(j[key].is_number(), field(key) + " must be a number");
  }
  return j;
}

CaptureOptions CaptureOptionsOfJson(const nlohmann::json& capture_json, const std::string& what) {
  CaptureOptions options;
  const auto stored = capture_json.find("options");
  if (stored != capture_json.end()) SetOptionsFromStoredJson(stored->dump(), what, &options);
  return options;
}

}  // namespace crease
