// A cheap learnable toy problem for the landmark regressor (no rendering, no studio):
// 68 points on an ellipse-like contour under a random similarity, drawn as bright dots
// on a noisy dark image; and the same as labelled faces (pipeline/capture/labelled_faces.h).
#pragma once

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/rng.h"
#include "core/types.h"
#include "pipeline/capture/labelled_faces.h"

namespace crease::testing {

inline constexpr double kLevelEyesPhase = 21.0 * std::numbers::pi / 68.0;

struct Toy {
  std::vector<cv::Mat> images;
  std::vector<MatX2d> shapes;
};

// `phase` turns the contour (radians): kLevelEyesPhase puts points 36 and 45 (the
// outer eye corners, which MeanShapeOf levels with 36 on the left) at nearly equal
// heights at the top, 36 on the left, so that the mean shape placed in a face box
// is the right way up.
inline Toy MakeToy(int count, uint64_t seed, double phase = 0.0) {
  Rng rng(seed);
  MatX2d base(68, 2);
  for (int i = 0; i < 68; ++i) {
    const double a = 2 * std::numbers::pi * i / 68.0 + phase;
    base.row(i) << 30 * std::cos(a) + 4 * std::cos(3 * a), 36 * std::sin(a) + 3 * std::sin(2 * a);
  }
  Toy toy;
  for (int k = 0; k < count; ++k) {
    const double s = std::exp(rng.Normal(0, 0.08)), ang = rng.Normal(0, 0.1);
    const double cx = 60 + rng.Normal(0, 5), cy = 60 + rng.Normal(0, 5);
    MatX2d shape(68, 2);
    for (int i = 0; i < 68; ++i) {
      const double x = base(i, 0) + rng.Normal(0, 1.5), y = base(i, 1) + rng.Normal(0, 1.5);
      shape.row(i) << cx + s * (std::cos(ang) * x - std::sin(ang) * y), cy + s * (std::sin(ang) * x + std::cos(ang) * y);
    }
    cv::Mat img(120, 120, CV_32FC1);
    cv::randu(img, 0.0f, 0.15f);
    for (int i = 0; i < 68; ++i) cv::circle(img, cv::Point2d(shape(i, 0), shape(i, 1)), 2, cv::Scalar(0.9), cv::FILLED);
    toy.images.push_back(img);
    toy.shapes.push_back(shape);
  }
  return toy;
}

// The toy's images as 8-bit RGB labelled faces named PREFIX0, PREFIX1, …
inline std::vector<LabelledFace> ToyFaces(const Toy& toy, const std::string& prefix) {
  std::vector<LabelledFace> faces(toy.images.size());
  for (size_t i = 0; i < faces.size(); ++i) {
    faces[i].name = prefix + std::to_string(i);
    cv::Mat rgb;
    cv::cvtColor(toy.images[i], rgb, cv::COLOR_GRAY2RGB);
    rgb.convertTo(faces[i].image, CV_8UC3, 255.0);
    faces[i].landmarks = toy.shapes[i];
  }
  return faces;
}

}  // namespace crease::testing
