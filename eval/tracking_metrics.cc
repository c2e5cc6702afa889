#include "eval/tracking_metrics.h"

#include <cstring>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/ibug.h"
#include "core/json_io.h"

namespace crease {

namespace fs = std::filesystem;

FrameTruth ReadFrameTruth(const fs::path& dataset, int frame, int num_vertices) {
  const std::string name = fmt::format("{:06d}", frame);
  const fs::path jpath = dataset / "truth" / (name + ".json");
  Require(fs::is_regular_file(jpath), fmt::format("{}: no ground truth for frame {}", jpath.string(), frame));
  const nlohmann::json j = ReadJsonFile(jpath);
  FrameTruth t;
  try {
    const auto& lms = j.at("landmarks");
    Require(lms.size() == 68, fmt::format("{}: expected 68 landmarks, found {}", jpath.string(), lms.size()));
    t.landmarks.resize(68, 2);
    t.landmark_visible.resize(68);
    for (int i = 0; i < 68; ++i) {
      t.landmarks(i, 0) = lms[i].at("x").get<double>();
      t.landmarks(i, 1) = lms[i].at("y").get<double>();
      t.landmark_visible[i] = lms[i].value("visible", true) ? 1 : 0;
    }
    const auto& c = j.at("cam_from_head");
    const auto q = c.at("rotation_wxyz").get<std::vector<double>>();
    const auto tr = c.at("translation_mm").get<std::vector<double>>();
    // Issue 19 (truth_json_fuzzer): shorter arrays were read past their end.
    Require(q.size() == 4 && tr.size() == 3,
            fmt::format("{}: cam_from_head needs rotation_wxyz (4 numbers) and translation_mm (3), found {} and {}",
                        jpath.string(), q.size(), tr.size()));
    const double q_norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    Require(std::abs(q_norm - 1.0) < 1e-3,
            fmt::format("{}: cam_from_head.rotation_wxyz is not a unit quaternion (norm {})", jpath.string(), q_norm));
    t.cam_from_head = Rigid3d(Eigen::Quaterniond(q[0], q[1], q[2], q[3]), Eigen::Vector3d(tr[0], tr[1], tr[2]));
    if (j.contains("identity")) {
      const auto a = j.at("identity").get<std::vector<double>>();
      t.identity = Eigen::Map<const Eigen::VectorXd>(a.data(), static_cast<Eigen::Index>(a.size()));
    }
    if (j.contains("expression")) {
      for (const auto& [name, w] : j.at("expression").items()) t.expression.emplace_back(name, w.get<double>());
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(fmt::format("{}: malformed ground truth: {}", jpath.string(), e.what()));
  }
  const fs::path bpath = dataset / "truth" / (name + "_vertices.bin");
  const std::string bytes = ReadFileToString(bpath);
  if (num_vertices < 0) {  // as many as the file holds
    Require(bytes.size() % 12 == 0, fmt::format("{}: {} bytes, not 3 floats per vertex", bpath.string(), bytes.size()));
    num_vertices = static_cast<int>(bytes.size() / 12);
  }
  Require(bytes.size() == static_cast<size_t>(num_vertices) * 3 * sizeof(float),
          fmt::format("{}: {} bytes, expected {} (3 floats for each of the rig's {} vertices)", bpath.string(),
                      bytes.size(), static_cast<size_t>(num_vertices) * 12, num_vertices));
  std::vector<float> v(static_cast<size_t>(num_vertices) * 3);
  std::memcpy(v.data(), bytes.data(), bytes.size());
  t.vertices.resize(num_vertices, 2);
  t.vertex_visible.resize(num_vertices);
  for (int i = 0; i < num_vertices; ++i) {
    t.vertices(i, 0) = v[3 * i];
    t.vertices(i, 1) = v[3 * i + 1];
    t.vertex_visible[i] = v[3 * i + 2] > 0.5f;
  }
  // Issue 19: NaN truth was accepted and every error computed on it.
  Require(t.vertices.allFinite(), fmt::format("{}: NaN or infinite vertex projections", bpath.string()));
  Require(t.landmarks.allFinite() && t.cam_from_head.translation.allFinite() &&
              t.cam_from_head.rotation.coeffs().allFinite() && t.identity.allFinite(),
          fmt::format("{}: NaN or infinite landmarks, pose or identity", jpath.string()));
  return t;
}

FrameTrackingError CompareToTruth(const FrameTruth& truth, const MatX2d& landmarks, const MatX2d& projected_landmarks,
                                  const MatX2d& projected_vertices) {
  FrameTrackingError e;
  const double iod = InterOcularDistance(truth.landmarks);
  if (landmarks.rows() == 68) {
    e.landmark_px = (landmarks - truth.landmarks).rowwise().norm().mean();
    e.landmark_iod = iod > 0 ? e.landmark_px / iod : 0.0;
  }
  if (projected_landmarks.rows() == 68) e.fit_landmark_px = (projected_landmarks - truth.landmarks).rowwise().norm().mean();
  if (projected_vertices.rows() == truth.vertices.rows()) {
    double sum = 0;
    for (int i = 0; i < truth.vertices.rows(); ++i) {
      if (!truth.vertex_visible[i]) continue;
      sum += (projected_vertices.row(i) - truth.vertices.row(i)).norm();
      ++e.visible_vertices;
    }
    e.vertex_px = e.visible_vertices ? sum / e.visible_vertices : 0.0;
  }
  return e;
}

Eigen::VectorXd ExpressionVector(const FaceRig& rig, const std::vector<std::pair<std::string, double>>& named) {
  Eigen::VectorXd e = Eigen::VectorXd::Zero(rig.num_expressions());
  for (const auto& [name, w] : named) {
    const int k = rig.ExpressionIndex(name);
    if (k >= 0) e[k] = w;
  }
  return e;
}

TrackedFrame TruthAsTrackedFrame(const FaceRig& rig, const FrameTruth& truth, int frame) {
  TrackedFrame t;
  t.frame = frame;
  t.tracked = true;
  t.detected = false;
  t.confidence = 1.0;
  t.landmarks = truth.landmarks;
  t.fit.expression = ExpressionVector(rig, truth.expression);
  t.fit.cam_from_head = truth.cam_from_head;
  t.fit.converged = true;
  return t;
}

Eigen::VectorXd TruthIdentity(const FaceRig& rig, const FrameTruth& truth) {
  return ZeroPadded(truth.identity, rig.num_identity());
}

}  // namespace crease
