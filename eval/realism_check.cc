#include "eval/realism_check.h"

#include <chrono>
#include <map>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/ibug.h"
#include "core/image_io.h"
#include "pipeline/capture/landmarks.h"
#include "synth/dataset.h"

namespace crease {

void RealismCheckOptions::VisitFields(OptionVisitor& v) {
  v.Field("actors", actors);
  v.Field("seed", seed);
  v.Field("lights", lights);
  v.Field("yaws_deg", yaws_deg);
  v.Field("expressions", expressions);
  v.Field("samples_dir", samples_dir);
}

void RealismCheckOptions::Check() const {
  CheckGe("RealismCheckOptions", "actors", actors, 1);
  Require(!lights.empty() && !yaws_deg.empty() && !expressions.empty(),
          "RealismCheckOptions: lights, yaws_deg and expressions must not be empty");
  for (const auto& l : lights) LightRigFromSpec(l);
  studio.Check();
  actor.Check();
}

RealismCheckReport RunRealismCheck(const FaceRig& rig, const RealismCheckOptions& options) {
  options.Check();
  Require(rig.LandmarkIndex("ibug_68") >= 0, "realism check: the rig has no 68 iBUG landmarks");
  std::vector<int> ibug(68);
  for (int i = 0; i < 68; ++i) ibug[i] = rig.LandmarkIndex(fmt::format("ibug_{}", i + 1));
  const auto start = std::chrono::steady_clock::now();
  DlibLandmarkSource dlib;
  const HogFaceDetector near_miss(0, kNoFaceScore);
  RealismCheckReport report;
  double sum_px = 0, sum_in_px = 0, sum_iod = 0, sum_in_iod = 0;
  for (int a = 0; a < options.actors; ++a) {
    const uint64_t seed = options.seed + static_cast<uint64_t>(a);
    const Actor actor = GenerateActor(rig, seed, options.actor);
    const Studio studio(rig, actor, options.studio);
    for (const auto& light_spec : options.lights) {
      const LightRig lights = LightRigFromSpec(light_spec);
      const std::string light_name = std::filesystem::path(light_spec).stem().string();
      for (double yaw : options.yaws_deg) {
        for (const auto& expr : options.expressions) {
          SequenceFrame pose;
          pose.yaw_deg = yaw;
          const Eigen::VectorXd w = expr.empty() ? Eigen::VectorXd::Zero(rig.num_expressions()) : ParseExpressionSpec(expr, rig);
          const StudioFrame f = studio.RenderStill(w, pose, &lights, nullptr, seed * 7919 + report.rows.size());
          RealismCheckRow row{seed, light_name, expr.empty() ? "neutral" : expr, yaw};
          dlib.Reset();
          const LandmarkResult r = dlib.Track(f.image.decoded);
          MatX2d gt(68, 2);
          for (int i = 0; i < 68; ++i) gt.row(i) = f.truth.landmark_pixels.row(ibug[i]);
          row.iod_px = InterOcularDistance(gt);
          // Count a detection only when it is this face (its box holds the true nose tip).
          const Eigen::Vector2d nose = gt.row(kIbugNoseTip).transpose();
          const auto holds_face = [&](const FaceBox& b) {
            return nose.x() >= b.x && nose.x() <= b.x + b.width && nose.y() >= b.y && nose.y() <= b.y + b.height;
          };
          row.detected = r.found && holds_face(r.box);
          row.score = kNoFaceScore;
          for (const FaceBox& b : near_miss.Detect(f.image.decoded)) {
            if (holds_face(b)) row.score = std::max(row.score, b.score);
          }
          if (row.detected) {
            const Eigen::VectorXd err = (r.points - gt).rowwise().norm();
            row.error_px = err.mean();
            row.error_inner_px = err.tail(51).mean();
            row.error_iod = row.error_px / row.iod_px;
            row.error_inner_iod = row.error_inner_px / row.iod_px;
            sum_px += row.error_px;
            sum_in_px += row.error_inner_px;
            sum_iod += row.error_iod;
            sum_in_iod += row.error_inner_iod;
            ++report.detected;
          }
          if (!options.samples_dir.empty()) {
            cv::Mat img;
            f.image.decoded.copyTo(img);
            for (int i = 0; i < 68; ++i) {
              cv::circle(img, cv::Point2d(gt(i, 0), gt(i, 1)), 2, cv::Scalar(0.0, 1.0, 0.0), cv::FILLED, cv::LINE_AA);
              if (row.detected) {
                cv::circle(img, cv::Point2d(r.points(i, 0), r.points(i, 1)), 2, cv::Scalar(1.0, 0.0, 0.0), cv::FILLED,
                           cv::LINE_AA);
              }
            }
            WriteImage(std::filesystem::path(options.samples_dir) /
                           fmt::format("actor{}_{}_yaw{:+.0f}_{}.png", seed, light_name, yaw, report.rows.size()),
                       img);
          }
          report.rows.push_back(row);
          ++report.frames;
        }
      }
    }
  }
  report.detection_rate = report.frames ? static_cast<double>(report.detected) / report.frames : 0.0;
  if (report.detected) {
    report.mean_error_px = sum_px / report.detected;
    report.mean_error_inner_px = sum_in_px / report.detected;
    report.mean_error_iod = sum_iod / report.detected;
    report.mean_error_inner_iod = sum_in_iod / report.detected;
  }
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

std::string RealismCheckReport::ToTable() const {
  struct Acc {
    int n = 0, det = 0;
    double e = 0, ei = 0, score = 0;
  };
  std::map<std::string, Acc> by;
  for (const auto& r : rows) {
    for (const std::string& key : {fmt::format("light {}", r.light), fmt::format("yaw {:+.0f}", r.yaw_deg),
                                  fmt::format("expr {}", r.expression)}) {
      Acc& a = by[key];
      ++a.n;
      a.score += r.score;
      if (r.detected) {
        ++a.det;
        a.e += r.error_iod;
        a.ei += r.error_inner_iod;
      }
    }
  }
  std::string s = fmt::format("{:<48} {:>7} {:>9} {:>12} {:>12} {:>7}\n", "subset", "frames", "detected",
                              "err/IOD (68)", "err/IOD (51)", "score");
  for (const auto& [k, a] : by) {
    s += fmt::format("{:<48} {:>7} {:>8.0f}% {:>12.3f} {:>12.3f} {:>7.2f}\n", k, a.n, 100.0 * a.det / a.n,
                     a.det ? a.e / a.det : 0.0, a.det ? a.ei / a.det : 0.0, a.score / a.n);
  }
  double score = 0;
  for (const auto& r : rows) score += r.score / std::max<size_t>(1, rows.size());
  s += fmt::format("{:<48} {:>7} {:>8.0f}% {:>12.3f} {:>12.3f} {:>7.2f}\n", "all", frames, 100.0 * detection_rate,
                   mean_error_iod, mean_error_inner_iod, score);
  s += fmt::format("mean landmark error on detected frames: {:.2f} px (68 points), {:.2f} px (51 inner points)\n",
                   mean_error_px, mean_error_inner_px);
  return s;
}

std::string RealismCheckReport::ToJson() const {
  nlohmann::json j;
  j["frames"] = frames;
  j["detected"] = detected;
  j["detection_rate"] = detection_rate;
  j["mean_error_px"] = mean_error_px;
  j["mean_error_inner_px"] = mean_error_inner_px;
  j["mean_error_iod"] = mean_error_iod;
  j["mean_error_inner_iod"] = mean_error_inner_iod;
  j["seconds"] = seconds;
  nlohmann::json r = nlohmann::json::array();
  for (const auto& x : rows) {
    r.push_back({{"actor_seed", x.actor_seed}, {"light", x.light}, {"yaw_deg", x.yaw_deg},
                 {"expression", x.expression}, {"detected", x.detected}, {"score", x.score}, {"error_px", x.error_px},
                 {"error_inner_px", x.error_inner_px}, {"error_iod", x.error_iod},
                 {"error_inner_iod", x.error_inner_iod}, {"iod_px", x.iod_px}});
  }
  j["rows"] = r;
  return j.dump(2);
}

}  // namespace crease
