#include "core/rig_info.h"

#include <algorithm>
#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/options.h"

namespace crease {

std::vector<std::string> MissingStandardRegions(const FaceRig& rig) {
  std::vector<std::string> missing;
  for (const auto& n : StandardRegionNames()) {
    if (!rig.FindRegion(n)) missing.push_back(n);
  }
  return missing;
}

nlohmann::json RigInfoJson(const FaceRig& rig, const std::string& file) {
  const auto [lo, hi] = BoundingBox(rig.neutral);
  nlohmann::json j;
  j["file"] = file;
  j["source"] = rig.source;
  j["vertices"] = rig.num_vertices();
  j["triangles"] = rig.neutral.num_faces();
  j["extent_mm"] = {hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z()};
  j["identity_modes"] = rig.num_identity();
  j["expressions"] = rig.expression_names;
  nlohmann::json lms = nlohmann::json::object();
  for (const auto& l : rig.landmarks) lms[l.name] = l.vertex;
  j["landmarks"] = lms;
  nlohmann::json regions = nlohmann::json::object();
  for (const auto& r : rig.regions) {
    regions[r.name] = {{"size", r.mask.rows},
                       {"coverage", static_cast<double>(cv::countNonZero(r.mask)) / r.mask.total()}};
  }
  j["regions"] = regions;
  j["missing_standard_regions"] = MissingStandardRegions(rig);
  return j;
}

namespace {

// Distinct colours for region masks (linear RGB).
const std::vector<cv::Vec3f>& RegionPalette() {
  static const std::vector<cv::Vec3f> p = {{0.90f, 0.30f, 0.10f}, {0.95f, 0.75f, 0.05f}, {0.10f, 0.45f, 0.90f},
                                           {0.05f, 0.75f, 0.85f}, {0.20f, 0.70f, 0.15f}, {0.55f, 0.85f, 0.20f},
                                           {0.75f, 0.20f, 0.75f}, {0.85f, 0.10f, 0.35f}, {0.45f, 0.30f, 0.15f}};
  return p;
}

}  // namespace

cv::Mat RegionPicture(const FaceRig& rig, int size) {
  cv::Mat img(size, size, CV_32FC3, cv::Scalar(0.05, 0.05, 0.05));
  for (size_t r = 0; r < rig.regions.size(); ++r) {
    cv::Mat m;
    cv::resize(rig.regions[r].mask, m, cv::Size(size, size), 0, 0, cv::INTER_NEAREST);
    const cv::Vec3f c = RegionPalette()[r % RegionPalette().size()];
    img.setTo(cv::Scalar(c[0], c[1], c[2]) * 0.6, m);
  }
  const TriMesh& mesh = rig.neutral;
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      cv::line(img, cv::Point2d(mesh.UV(a, 0) * size, mesh.UV(a, 1) * size),
               cv::Point2d(mesh.UV(b, 0) * size, mesh.UV(b, 1) * size), cv::Scalar(0.35, 0.35, 0.35), 1,
               cv::LINE_AA);
    }
  }
  for (const auto& l : rig.landmarks) {
    cv::circle(img, cv::Point2d(mesh.UV(l.vertex, 0) * size, mesh.UV(l.vertex, 1) * size), 3,
               cv::Scalar(1.0, 1.0, 1.0), cv::FILLED, cv::LINE_AA);
  }
  return img;
}

Eigen::MatrixXd VertexRegionIndices(const FaceRig& rig, const TriMesh& mesh) {
  Eigen::MatrixXd region = Eigen::MatrixXd::Constant(mesh.num_vertices(), 1, -1.0);
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    for (size_t r = 0; r < rig.regions.size() && region(v, 0) < 0; ++r) {
      if (rig.InRegion(rig.regions[r].name, mesh.UV.row(v).transpose())) region(v, 0) = static_cast<double>(r);
    }
  }
  return region;
}

Eigen::VectorXd ParseNamedCoefficients(const std::vector<std::string>& items, const std::vector<std::string>& names,
                                       const std::string& kind) {
  Eigen::VectorXd w = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(names.size()));
  for (const auto& item : items) {
    const auto [name, value] = ParseNameValue(item, "--" + kind, "VALUE");
    auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) {
      // Identity modes may also be given by index.
      try {
        size_t used = 0;
        const int idx = std::stoi(name, &used);
        if (used == name.size() && idx >= 0 && idx < static_cast<int>(names.size())) {
          w[idx] = value;
          continue;
        }
      } catch (const std::exception&) {
      }
      std::string known;
      for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
      throw Error(fmt::format("--{}: the rig has no {} named '{}' (it has: {})", kind, kind, name, known));
    }
    w[it - names.begin()] = value;
  }
  return w;
}

}  // namespace crease
