#include "pipeline/capture/shape_regressor.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <complex>
#include <numbers>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>


#include "core/array_file.h"
#include "core/color.h"
#include "core/error.h"
#include "core/ibug.h"
#include "core/stats.h"
#include "core/rng.h"
#include "pipeline/training/fern_cascade.h"

namespace crease {

namespace {

using Cd = std::complex<double>;
constexpr char kMagic[] = "CREASTRK";

// The inter-ocular landmark pair, `left` on the image's left in a frontal view: for
// the 68 iBUG points the outer eye corners (the 300-W convention; core/ibug.h), the
// subject's right eye first; for other landmark counts the first and last point.
void EyePair(int num_landmarks, int* left, int* right) {
  if (num_landmarks == kIbugNumPoints) {
    *left = kIbugRightEyeOuter;
    *right = kIbugLeftEyeOuter;
  } else {
    *left = 0;
    *right = num_landmarks - 1;
  }
}

Cd Point(const MatX2d& s, int i) { return {s(i, 0), s(i, 1)}; }

Cd Centroid(const MatX2d& s) {
  const Eigen::Vector2d c = s.colwise().mean();
  return {c.x(), c.y()};
}

// The similarity that maps the (centred) mean shape onto `shape` in least squares,
// shape ≈ g + c·mean (complex c = scale·e^{iθ}): M_S^{−1} of ESR is multiplication by c,
// M_S division by c (ESR Sec. 2.2).
struct Similarity {
  Cd g;  // the shape's centroid (pixels)
  Cd c;  // scale and rotation, normalised frame → pixels
};

Similarity SimilarityFromMean(const MatX2d& shape, const MatX2d& mean) {
  Similarity s;
  s.g = Centroid(shape);
  Cd num = 0;
  double den = 0;
  for (int i = 0; i < mean.rows(); ++i) {
    const Cd m = Point(mean, i);
    num += std::conj(m) * (Point(shape, i) - s.g);
    den += std::norm(m);
  }
  s.c = den > 0 ? num / den : Cd(1, 0);
  if (std::abs(s.c) < 1e-12) s.c = Cd(1e-12, 0);
  return s;
}

// A shape normalised: centroid 0, the eye pair horizontal at distance 1.
MatX2d Normalised(const MatX2d& s, int left, int right) {
  const Cd g = Centroid(s);
  Cd e = Point(s, right) - Point(s, left);
  if (std::abs(e) < 1e-12) e = Cd(1, 0);
  MatX2d out(s.rows(), 2);
  for (int i = 0; i < s.rows(); ++i) {
    const Cd p = (Point(s, i) - g) / e;
    out.row(i) << p.real(), p.imag();
  }
  return out;
}

// Places `shape` so that the square box of its points (side max(w, h), same centre)
// becomes the square of side `side` centred at `centre`.
MatX2d PlaceInSquareBox(const MatX2d& shape, Cd centre, double side) {
  const Eigen::Vector2d lo = shape.colwise().minCoeff(), hi = shape.colwise().maxCoeff();
  const Eigen::Vector2d c = 0.5 * (lo + hi);
  const double own = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1e-12});
  const double k = side / own;
  MatX2d out(shape.rows(), 2);
  for (int i = 0; i < shape.rows(); ++i) {
    out(i, 0) = centre.real() + k * (shape(i, 0) - c.x());
    out(i, 1) = centre.imag() + k * (shape(i, 1) - c.y());
  }
  return out;
}

// 8-bit sRGB → linear, for all 256 codes.
const float* SrgbDecodeTable() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = SrgbToLinear(i / 255.0f);
    return t;
  }();
  return table.data();
}

// Reads the sRGB-encoded grey value (in [0, 1]) of the nearest pixel, clamped to the
// image: the same value ToGray8 gives / 255 (luma of linear RGB, then sRGB encoded),
// computed only at the sampled pixels.
class GreySampler {
 public:
  explicit GreySampler(const cv::Mat& image) : image_(image) {
    Require(!image.empty(), "shape regressor: empty image");
    const int depth = image.depth(), ch = image.channels();
    Require((depth == CV_32F || depth == CV_8U) && (ch == 1 || ch == 3),
            fmt::format("shape regressor: images must be CV_32FC1/3 or CV_8UC1/3 (type {})", image.type()));
    float_ = depth == CV_32F;
    rgb_ = ch == 3;
  }
  float operator()(double x, double y) const {
    const int xi = std::clamp(static_cast<int>(std::lround(std::isfinite(x) ? x : 0.0)), 0, image_.cols - 1);
    const int yi = std::clamp(static_cast<int>(std::lround(std::isfinite(y) ? y : 0.0)), 0, image_.rows - 1);
    if (float_) {
      float v;
      if (rgb_) {
        const float* p = image_.ptr<float>(yi) + 3 * xi;
        v = 0.299f * p[0] + 0.587f * p[1] + 0.114f * p[2];  // cv::COLOR_RGB2GRAY weights
      } else {
        v = image_.ptr<float>(yi)[xi];
      }
      return LinearToSrgb(std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f);
    }
    if (rgb_) {
      // 8-bit sRGB RGB: decode, luma in linear light, encode — the value of the
      // linear float frame it decodes to, so 8-bit training images and float frames agree.
      const uint8_t* p = image_.ptr<uint8_t>(yi) + 3 * xi;
      const float* lut = SrgbDecodeTable();
      return LinearToSrgb(0.299f * lut[p[0]] + 0.587f * lut[p[1]] + 0.114f * lut[p[2]]);
    }
    return image_.ptr<uint8_t>(yi)[xi] * (1.0f / 255.0f);
  }

 private:
  const cv::Mat& image_;
  bool float_ = true, rgb_ = true;
};

// The P shape-indexed pixels of stage t for a shape with similarity `sim` (ESR Sec. 2.3).
void SamplePixels(const ShapeRegressor& r, int t, const GreySampler& sampler, const MatX2d& shape,
                  const Similarity& sim, float* x) {
  const int P = r.num_pixels();
  const uint16_t* lm = r.pixel_landmark.data() + static_cast<size_t>(t) * P;
  const float* off = r.pixel_offset.data() + static_cast<size_t>(t) * P * 2;
  for (int p = 0; p < P; ++p) {
    const Cd pos = Point(shape, lm[p]) + sim.c * Cd(off[2 * p], off[2 * p + 1]);
    x[p] = sampler(pos.real(), pos.imag());
  }
}

int FernBin(const ShapeRegressor& r, size_t fern, const float* x) {
  const int F = r.depth();
  const uint16_t* a = r.fern_pixel_a.data() + fern * F;
  const uint16_t* b = r.fern_pixel_b.data() + fern * F;
  const float* th = r.fern_threshold.data() + fern * F;
  int bin = 0;
  for (int f = 0; f < F; ++f) bin |= static_cast<int>(x[a[f]] - x[b[f]] > th[f]) << f;
  return bin;
}

// S += M_S^{−1}(U): the stage update U (normalised frame, L×2 floats) in pixels.
void ApplyUpdate(const Similarity& sim, const float* u, MatX2d* shape) {
  for (int i = 0; i < shape->rows(); ++i) {
    const Cd d = sim.c * Cd(u[2 * i], u[2 * i + 1]);
    (*shape)(i, 0) += d.real();
    (*shape)(i, 1) += d.imag();
  }
}

double MeanErrorOverIod(const MatX2d& s, const MatX2d& truth) {
  int l, r;
  EyePair(static_cast<int>(truth.rows()), &l, &r);
  const double iod = std::max(1e-9, (truth.row(l) - truth.row(r)).norm());
  return (s - truth).rowwise().norm().mean() / iod;
}

}  // namespace

// ---------------------------------------------------------------------------
// Options

void ShapeRegressorOptions::VisitFields(OptionVisitor& v) {
  v.Field("num_stages", num_stages);
  v.Field("num_ferns", num_ferns);
  v.Field("fern_depth", fern_depth);
  v.Field("num_sampled_pixels", num_sampled_pixels);
  v.Field("shrinkage", shrinkage);
  v.Field("feature_radius_first", feature_radius_first);
  v.Field("feature_radius_last", feature_radius_last);
  v.Field("augmentation", augmentation);
  v.Field("tracking_fraction", tracking_fraction);
  v.Field("perturb_translation", perturb_translation);
  v.Field("perturb_rotation_deg", perturb_rotation_deg);
  v.Field("perturb_scale", perturb_scale);
  v.Field("box_jitter_translation", box_jitter_translation);
  v.Field("box_jitter_scale", box_jitter_scale);
  v.Field("seed", seed);
}

void ShapeRegressorOptions::Check() const {
  const char* o = "ShapeRegressorOptions";
  CheckGe(o, "num_stages", num_stages, 1);
  CheckGe(o, "num_ferns", num_ferns, 1);
  CheckGe(o, "fern_depth", fern_depth, 1);
  CheckLe(o, "fern_depth", fern_depth, 10);
  CheckGe(o, "num_sampled_pixels", num_sampled_pixels, 2);
  CheckLe(o, "num_sampled_pixels", num_sampled_pixels, 65535);
  CheckGe(o, "shrinkage", shrinkage, 0);
  CheckGt(o, "feature_radius_first", feature_radius_first, 0);
  CheckGt(o, "feature_radius_last", feature_radius_last, 0);
  CheckGe(o, "augmentation", augmentation, 1);
  CheckGe(o, "tracking_fraction", tracking_fraction, 0);
  CheckLe(o, "tracking_fraction", tracking_fraction, 1);
  CheckGe(o, "perturb_translation", perturb_translation, 0);
  CheckGe(o, "perturb_rotation_deg", perturb_rotation_deg, 0);
  CheckGe(o, "perturb_scale", perturb_scale, 0);
  CheckGe(o, "box_jitter_translation", box_jitter_translation, 0);
  CheckGe(o, "box_jitter_scale", box_jitter_scale, 0);
}

// ---------------------------------------------------------------------------
// Model

MatX2d ShapeRegressor::Predict(const cv::Mat& image, const MatX2d& initial_shape) const {
  Require(initial_shape.rows() == num_landmarks,
          fmt::format("shape regressor: the initial shape has {} points, the model {}", initial_shape.rows(),
                      num_landmarks));
  const GreySampler sampler(image);
  const int T = num_stages(), K = num_ferns(), P = num_pixels(), D = 2 * num_landmarks;
  const size_t B = size_t{1} << depth();
  std::vector<float> x(P), u(D);
  MatX2d shape = initial_shape;
  for (int t = 0; t < T; ++t) {
    const Similarity sim = SimilarityFromMean(shape, mean_shape);
    SamplePixels(*this, t, sampler, shape, sim, x.data());
    std::fill(u.begin(), u.end(), 0.0f);
    for (int k = 0; k < K; ++k) {
      const size_t fern = static_cast<size_t>(t) * K + k;
      const float* out = fern_output.data() + (fern * B + FernBin(*this, fern, x.data())) * D;
      for (int d = 0; d < D; ++d) u[d] += out[d];
    }
    ApplyUpdate(sim, u.data(), &shape);
  }
  return shape;
}

MatX2d ShapeRegressor::MeanShapeInBox(const FaceBox& box) const {
  return PlaceInSquareBox(mean_shape, Cd(box.x + 0.5 * box.width, box.y + 0.5 * box.height),
                          std::max(box.width, box.height));
}

FaceBox ShapeRegressor::FromDetectorBox(const FaceBox& d) const {
  const double side = std::max(d.width, d.height);
  const double cx = d.x + 0.5 * d.width + detector_box.x() * side, cy = d.y + 0.5 * d.height + detector_box.y() * side;
  const double s = side * detector_box.z();
  return {cx - 0.5 * s, cy - 0.5 * s, s, s, d.score};
}

int CalibrateDetectorBox(ShapeRegressor* regressor, const std::vector<cv::Mat>& images,
                         const std::vector<MatX2d>& shapes, int upsample, double threshold) {
  Require(images.size() == shapes.size(), "CalibrateDetectorBox: as many shapes as images");
  const HogFaceDetector detector(upsample, threshold);
  std::vector<double> dx, dy, ratio;
  for (size_t i = 0; i < images.size(); ++i) {
    const FaceBox t = BoxOfPoints(shapes[i]);
    const double side_t = std::max(t.width, t.height);
    const double tx0 = t.x + 0.5 * t.width - 0.5 * side_t, ty0 = t.y + 0.5 * t.height - 0.5 * side_t;
    double best_iou = 0.3;
    const FaceBox* best = nullptr;
    const std::vector<FaceBox> faces = detector.Detect(images[i]);
    for (const FaceBox& d : faces) {
      const double ix = std::max(0.0, std::min(d.x + d.width, tx0 + side_t) - std::max(d.x, tx0));
      const double iy = std::max(0.0, std::min(d.y + d.height, ty0 + side_t) - std::max(d.y, ty0));
      const double inter = ix * iy, iou = inter / (d.width * d.height + side_t * side_t - inter);
      if (iou > best_iou) {
        best_iou = iou;
        best = &d;
      }
    }
    if (best == nullptr) continue;
    const double side_d = std::max(best->width, best->height);
    dx.push_back((t.x + 0.5 * t.width - (best->x + 0.5 * best->width)) / side_d);
    dy.push_back((t.y + 0.5 * t.height - (best->y + 0.5 * best->height)) / side_d);
    ratio.push_back(side_t / side_d);
  }
  if (dx.empty()) return 0;
  regressor->detector_box = Eigen::Vector3d(Median(dx), Median(dy), Median(ratio));
  return static_cast<int>(dx.size());
}

void ShapeRegressor::Check(const std::string& what) const {
  options.Check();
  const size_t T = num_stages(), K = num_ferns(), F = depth(), P = num_pixels(), L = num_landmarks;
  const size_t B = size_t{1} << F;
  Require(L >= 2 && L <= 65535, fmt::format("{}: num_landmarks = {} must be in [2, 65535]", what, L));
  Require(static_cast<size_t>(mean_shape.rows()) == L && mean_shape.allFinite(),
          fmt::format("{}: the mean shape must be {}×2 finite values", what, L));
  auto size_is = [&](size_t got, size_t want, const char* name) {
    Require(got == want, fmt::format("{}: {} has {} values, expected {}", what, name, got, want));
  };
  size_is(pixel_landmark.size(), T * P, "pixel_landmark");
  size_is(pixel_offset.size(), T * P * 2, "pixel_offset");
  size_is(fern_pixel_a.size(), T * K * F, "fern_pixel_a");
  size_is(fern_pixel_b.size(), T * K * F, "fern_pixel_b");
  size_is(fern_threshold.size(), T * K * F, "fern_threshold");
  size_is(fern_output.size(), T * K * B * 2 * L, "fern_output");
  for (uint16_t l : pixel_landmark) Require(l < L, fmt::format("{}: a pixel's landmark index {} ≥ {}", what, l, L));
  for (size_t i = 0; i < fern_pixel_a.size(); ++i) {
    Require(fern_pixel_a[i] < P && fern_pixel_b[i] < P,
            fmt::format("{}: fern pixel index ({}, {}) ≥ P = {}", what, fern_pixel_a[i], fern_pixel_b[i], P));
  }
  auto finite = [&](const std::vector<float>& v, const char* name) {
    for (float f : v) Require(std::isfinite(f), fmt::format("{}: {} holds a non-finite value", what, name));
  };
  finite(pixel_offset, "pixel_offset");
  finite(fern_threshold, "fern_threshold");
  finite(fern_output, "fern_output");
}

MatX2d MeanShapeOf(const std::vector<MatX2d>& shapes, int left_eye, int right_eye) {
  Require(!shapes.empty(), "MeanShapeOf: no shapes");
  const int L = static_cast<int>(shapes.front().rows());
  Require(left_eye >= 0 && left_eye < L && right_eye >= 0 && right_eye < L && left_eye != right_eye,
          fmt::format("MeanShapeOf: eye indices ({}, {}) out of range for {} points", left_eye, right_eye, L));
  MatX2d mean = MatX2d::Zero(L, 2);
  for (const MatX2d& s : shapes) {
    Require(s.rows() == L, fmt::format("MeanShapeOf: shapes have {} and {} points", L, s.rows()));
    mean += Normalised(s, left_eye, right_eye);
  }
  mean = Normalised(mean / static_cast<double>(shapes.size()), left_eye, right_eye);
  // Generalised Procrustes: align every shape to the mean by similarity, average, renormalise.
  for (int iter = 0; iter < 3; ++iter) {
    MatX2d sum = MatX2d::Zero(L, 2);
    for (const MatX2d& s : shapes) {
      const Similarity sim = SimilarityFromMean(s, mean);
      for (int i = 0; i < L; ++i) {
        const Cd p = (Point(s, i) - sim.g) / sim.c;
        sum(i, 0) += p.real();
        sum(i, 1) += p.imag();
      }
    }
    mean = Normalised(sum / static_cast<double>(shapes.size()), left_eye, right_eye);
  }
  return mean;
}

// ---------------------------------------------------------------------------
// Training (ESR Alg. 1)

namespace {

// Throws unless the training set is usable; returns the landmark count L.
int RequireTrainingSet(const std::vector<cv::Mat>& images, const std::vector<MatX2d>& shapes) {
  Require(!images.empty(), "TrainShapeRegressor: no training images");
  Require(images.size() == shapes.size(), fmt::format("TrainShapeRegressor: {} images but {} shapes", images.size(),
                                                      shapes.size()));
  const int L = static_cast<int>(shapes.front().rows());
  Require(L >= 2 && L <= 65535, fmt::format("TrainShapeRegressor: {} landmarks per shape", L));
  for (size_t i = 0; i < images.size(); ++i) {
    Require(!images[i].empty(), fmt::format("TrainShapeRegressor: image {} is empty", i));
    Require(shapes[i].rows() == L && shapes[i].allFinite(),
            fmt::format("TrainShapeRegressor: shape {} must be {}×2 finite pixels (has {} rows)", i, L,
                        shapes[i].rows()));
  }
  return L;
}

// One run of TrainShapeRegressor: the training samples (A augmented initial
// shapes per image), their current shapes, and one method per step of ESR Alg. 1.
class ShapeRegressorTrainer {
 public:
  ShapeRegressorTrainer(const std::vector<cv::Mat>& images, const std::vector<MatX2d>& shapes,
                        const ShapeRegressorOptions& options, int num_landmarks, ShapeRegressorTrainingResult* result);

  // Initial shapes (augmentation), from the stream `arng`.
  void InitialShapes(Rng arng);
  // Appends the mean error of the current shapes (over the inter-ocular distance).
  void ReportError();
  // Stage t: its pixels, targets and K ferns, then the shapes' update.
  void TrainStage(int t, Rng& srng);
  // The report's sample counts and mean |correlation|.
  void FinishReport();

 private:
  void SampleStagePixels(int t, Rng& srng);
  void StageSamples(int t);
  void TrainFern(size_t fern, const Eigen::MatrixXd& Xc, const Eigen::MatrixXd& pixel_scatter, Rng& srng);

  const std::vector<MatX2d>& shapes_;
  const ShapeRegressorOptions& options_;
  ShapeRegressorTrainingResult& result_;
  ShapeRegressor& r_;
  int left_eye_ = 0, right_eye_ = 0;
  const int n_img, A, N, T, K, F, P, B, L, D;
  std::vector<MatX2d> current_;
  std::vector<int> image_of_;
  std::vector<GreySampler> samplers_;
  RowMatrixXf Y_;  // residuals in the normalised frame
  RowMatrixXf U_;  // the stage's accumulated update
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> X_;  // pixel values
  std::vector<Similarity> sims_;
  std::vector<int> bins_;
  double corr_sum_ = 0;
  int64_t corr_count_ = 0;
};

ShapeRegressorTrainer::ShapeRegressorTrainer(const std::vector<cv::Mat>& images, const std::vector<MatX2d>& shapes,
                                             const ShapeRegressorOptions& options, int num_landmarks,
                                             ShapeRegressorTrainingResult* result)
    : shapes_(shapes),
      options_(options),
      result_(*result),
      r_(result->regressor),
      n_img(static_cast<int>(images.size())),
      A(options.augmentation),
      N(n_img * A),
      T(options.num_stages),
      K(options.num_ferns),
      F(options.fern_depth),
      P(options.num_sampled_pixels),
      B(1 << F),
      L(num_landmarks),
      D(2 * L) {
  EyePair(L, &left_eye_, &right_eye_);
  r_.options = options;
  r_.num_landmarks = L;
  r_.mean_shape = MeanShapeOf(shapes, left_eye_, right_eye_);
  r_.pixel_landmark.resize(static_cast<size_t>(T) * P);
  r_.pixel_offset.resize(static_cast<size_t>(T) * P * 2);
  r_.fern_pixel_a.resize(static_cast<size_t>(T) * K * F);
  r_.fern_pixel_b.resize(r_.fern_pixel_a.size());
  r_.fern_threshold.resize(r_.fern_pixel_a.size());
  r_.fern_output.resize(static_cast<size_t>(T) * K * B * D);
  current_.resize(N);
  image_of_.resize(N);
  samplers_.reserve(n_img);
  for (const cv::Mat& im : images) samplers_.emplace_back(im);
  Y_.resize(N, D);
  U_.resize(N, D);
  X_.resize(N, P);
  sims_.resize(N);
  bins_.resize(N);
}

// A initial shapes per image: the first tracking_fraction·A tracking-like (the
// truth under a random similarity), the rest detection-like (another image's
// truth in this image's jittered box).
void ShapeRegressorTrainer::InitialShapes(Rng arng) {
  const int n_track = static_cast<int>(std::lround(options_.tracking_fraction * A));
  for (int i = 0; i < n_img; ++i) {
    const MatX2d& truth = shapes_[i];
    const Cd g = Centroid(truth);
    const double iod = std::max(1e-9, (truth.row(left_eye_) - truth.row(right_eye_)).norm());
    const Eigen::Vector2d lo = truth.colwise().minCoeff(), hi = truth.colwise().maxCoeff();
    const double side = std::max(hi.x() - lo.x(), hi.y() - lo.y());
    const Cd box_centre(0.5 * (lo.x() + hi.x()), 0.5 * (lo.y() + hi.y()));
    for (int a = 0; a < A; ++a) {
      const int j = i * A + a;
      image_of_[j] = i;
      MatX2d s(L, 2);
      if (a < n_track) {
        // Tracking-like: the truth under a random similarity about its centroid.
        const Cd shift(arng.Normal(0, options_.perturb_translation * iod),
                       arng.Normal(0, options_.perturb_translation * iod));
        const double angle = arng.Normal(0, options_.perturb_rotation_deg) * std::numbers::pi / 180.0;
        const double scale = std::exp(arng.Normal(0, options_.perturb_scale));
        const Cd c = std::polar(scale, angle);
        for (int l = 0; l < L; ++l) {
          const Cd p = g + shift + c * (Point(truth, l) - g);
          s.row(l) << p.real(), p.imag();
        }
      } else {
        // Detection-like: another sample's truth in this sample's jittered square box.
        int other = i;
        if (n_img > 1) {
          other = static_cast<int>(arng.UniformInt(static_cast<uint64_t>(n_img - 1)));
          if (other >= i) ++other;
        }
        const Cd jitter(arng.Normal(0, options_.box_jitter_translation * side),
                        arng.Normal(0, options_.box_jitter_translation * side));
        const double k = std::exp(arng.Normal(0, options_.box_jitter_scale));
        s = PlaceInSquareBox(shapes_[other], box_centre + jitter, side * k);
      }
      current_[j] = s;
    }
  }
}

void ShapeRegressorTrainer::ReportError() {
  double sum = 0;
  for (int j = 0; j < N; ++j) sum += MeanErrorOverIod(current_[j], shapes_[image_of_[j]]);
  result_.report.train_error_iod.push_back(sum / N);
}

void ShapeRegressorTrainer::TrainStage(int t, Rng& srng) {
  SampleStagePixels(t, srng);
  StageSamples(t);
  U_.setZero();
  // P×P pixel scatter, once per stage (ESR Sec. 2.4: cov(x_m − x_n) from cov(x_m, x_n)).
  const Eigen::MatrixXd Xc = X_.cast<double>().rowwise() - X_.cast<double>().colwise().mean();
  const Eigen::MatrixXd pixel_scatter = Xc.transpose() * Xc;
  for (int k = 0; k < K; ++k) TrainFern(static_cast<size_t>(t) * K + k, Xc, pixel_scatter, srng);
  for (int j = 0; j < N; ++j) ApplyUpdate(sims_[j], U_.row(j).data(), &current_[j]);
}

// Shape-indexed pixels of stage t: around a random landmark of the mean shape,
// indexed by the nearest one (Differences 2).
void ShapeRegressorTrainer::SampleStagePixels(int t, Rng& srng) {
  const double radius = T == 1 ? options_.feature_radius_first
                               : options_.feature_radius_first +
                                     (options_.feature_radius_last - options_.feature_radius_first) * t / (T - 1);
  for (int p = 0; p < P; ++p) {
    const int l0 = static_cast<int>(srng.UniformInt(static_cast<uint64_t>(L)));
    const double rad = radius * std::sqrt(srng.Uniform()), ang = 2 * std::numbers::pi * srng.Uniform();
    const Cd pos = Point(r_.mean_shape, l0) + std::polar(rad, ang);
    int best = 0;
    double best_d = 1e300;
    for (int l = 0; l < L; ++l) {
      const double d = std::norm(pos - Point(r_.mean_shape, l));
      if (d < best_d) best_d = d, best = l;
    }
    const Cd off = pos - Point(r_.mean_shape, best);
    r_.pixel_landmark[static_cast<size_t>(t) * P + p] = static_cast<uint16_t>(best);
    r_.pixel_offset[(static_cast<size_t>(t) * P + p) * 2] = static_cast<float>(off.real());
    r_.pixel_offset[(static_cast<size_t>(t) * P + p) * 2 + 1] = static_cast<float>(off.imag());
  }
}

// Per sample: similarity, residual target Y = M_S(Ŝ − S), pixels.
void ShapeRegressorTrainer::StageSamples(int t) {
  tbb::parallel_for(tbb::blocked_range<int>(0, N, 64), [&](const tbb::blocked_range<int>& range) {
    for (int j = range.begin(); j < range.end(); ++j) {
      sims_[j] = SimilarityFromMean(current_[j], r_.mean_shape);
      const MatX2d& truth = shapes_[image_of_[j]];
      for (int l = 0; l < L; ++l) {
        const Cd y = (Point(truth, l) - Point(current_[j], l)) / sims_[j].c;
        Y_(j, 2 * l) = static_cast<float>(y.real());
        Y_(j, 2 * l + 1) = static_cast<float>(y.imag());
      }
      SamplePixels(r_, t, samplers_[image_of_[j]], current_[j], sims_[j], X_.row(j).data());
    }
  });
}

// One fern: F random unit directions in target space, drawn together (the
// residuals do not change within a fern), a correlated pixel pair and a random
// sample's threshold per direction, the bin outputs (ESR Eq. 7 / paper Eq. 4),
// and the residuals' update.
void ShapeRegressorTrainer::TrainFern(size_t fern, const Eigen::MatrixXd& Xc, const Eigen::MatrixXd& pixel_scatter,
                                      Rng& srng) {
  Eigen::MatrixXd V(D, F);
  for (int f = 0; f < F; ++f) {
    for (int d = 0; d < D; ++d) V(d, f) = srng.Normal();
    V.col(f).normalize();
  }
  Eigen::MatrixXd Yv = Y_.cast<double>() * V;        // N×F projected targets
  Yv.rowwise() -= Yv.colwise().mean();
  const Eigen::MatrixXd target_pixel = Xc.transpose() * Yv;  // P×F
  for (int f = 0; f < F; ++f) {
    const PixelPair pair = SelectCorrelatedPair(pixel_scatter, target_pixel.col(f), Yv.col(f).squaredNorm());
    corr_sum_ += std::abs(pair.correlation);
    ++corr_count_;
    const int sample = static_cast<int>(srng.UniformInt(static_cast<uint64_t>(N)));
    r_.fern_pixel_a[fern * F + f] = static_cast<uint16_t>(pair.m);
    r_.fern_pixel_b[fern * F + f] = static_cast<uint16_t>(pair.n);
    r_.fern_threshold[fern * F + f] = X_(sample, pair.m) - X_(sample, pair.n);
  }
  for (int j = 0; j < N; ++j) bins_[j] = FernBin(r_, fern, X_.row(j).data());
  // ESR Eq. 7 / paper Eq. 4: shrunk mean residual per bin.
  const Eigen::MatrixXf out = FernBinOutputs(bins_, Y_, B, options_.shrinkage);
  float* dst = r_.fern_output.data() + fern * B * D;
  for (int b = 0; b < B; ++b) {
    for (int d = 0; d < D; ++d) dst[static_cast<size_t>(b) * D + d] = out(b, d);
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, N, 256), [&](const tbb::blocked_range<int>& range) {
    for (int j = range.begin(); j < range.end(); ++j) {
      const float* o = dst + static_cast<size_t>(bins_[j]) * D;
      for (int d = 0; d < D; ++d) {
        U_(j, d) += o[d];
        Y_(j, d) -= o[d];
      }
    }
  });
}

void ShapeRegressorTrainer::FinishReport() {
  result_.report.num_images = n_img;
  result_.report.num_samples = N;
  result_.report.mean_abs_correlation = corr_count_ ? corr_sum_ / corr_count_ : 0.0;
}

}  // namespace

ShapeRegressorTrainingResult TrainShapeRegressor(const std::vector<cv::Mat>& images,
                                                 const std::vector<MatX2d>& shapes,
                                                 const ShapeRegressorOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  options.Check();
  const int L = RequireTrainingSet(images, shapes);
  ShapeRegressorTrainingResult result;
  ShapeRegressorTrainer trainer(images, shapes, options, L, &result);
  Rng rng(options.seed);
  trainer.InitialShapes(rng.Fork(0));
  trainer.ReportError();
  for (int t = 0; t < options.num_stages; ++t) {
    Rng srng = rng.Fork(1 + static_cast<uint64_t>(t));
    trainer.TrainStage(t, srng);
    trainer.ReportError();
  }
  trainer.FinishReport();
  result.report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

// ---------------------------------------------------------------------------
// Model file

void SaveShapeRegressor(const std::filesystem::path& path, const ShapeRegressor& regressor) {
  regressor.Check(path.string());
  nlohmann::json header;
  header["kind"] = "crease shape regressor (68 iBUG landmarks, Cao et al. 2012 explicit shape regression)";
  header["options"] = nlohmann::json::parse(OptionsToJson(regressor.options));
  header["num_landmarks"] = regressor.num_landmarks;
  header["detector_box"] = {regressor.detector_box.x(), regressor.detector_box.y(), regressor.detector_box.z()};
  ArrayFileWriter w(header.dump());
  const int64_t T = regressor.num_stages(), K = regressor.num_ferns(), F = regressor.depth(),
                P = regressor.num_pixels(), L = regressor.num_landmarks, B = int64_t{1} << F;
  w.Add("mean_shape", regressor.mean_shape.data(), {L, 2});
  w.Add("pixel_landmark", regressor.pixel_landmark.data(), {T, P});
  w.Add("pixel_offset", regressor.pixel_offset.data(), {T, P, 2});
  w.Add("fern_pixel_a", regressor.fern_pixel_a.data(), {T, K, F});
  w.Add("fern_pixel_b", regressor.fern_pixel_b.data(), {T, K, F});
  w.Add("fern_threshold", regressor.fern_threshold.data(), {T, K, F});
  w.Add("fern_output", regressor.fern_output.data(), {T, K, B, 2 * L});
  w.Write(path, kMagic, kShapeRegressorFileVersion);
}

ShapeRegressor LoadShapeRegressor(const std::filesystem::path& path) {
  const std::string what = path.string();
  const ArrayFile file = ReadArrayFile(path, kMagic, kShapeRegressorFileVersion, "shape regressor");
  ShapeRegressor r;
  try {
    const nlohmann::json header = nlohmann::json::parse(file.header_json);
    Require(header.contains("options") && header.contains("num_landmarks"),
            fmt::format("{}: the header lacks 'options' or 'num_landmarks'", what));
    SetOptionsFromJson(header.at("options").dump(), what, &r.options);
    r.num_landmarks = header.at("num_landmarks").get<int>();
    if (header.contains("detector_box")) {  // optional: older models use the detector's box as is
      const std::vector<double> b = header.at("detector_box").get<std::vector<double>>();
      Require(b.size() == 3 && std::isfinite(b[0]) && std::isfinite(b[1]) && std::isfinite(b[2]) && b[2] > 0.0,
              fmt::format("{}: 'detector_box' must be three finite numbers with a positive side ratio", what));
      r.detector_box = Eigen::Vector3d(b[0], b[1], b[2]);
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(fmt::format("{}: malformed header: {}", what, e.what()));
  }
  const int64_t T = r.num_stages(), K = r.num_ferns(), F = r.depth(), P = r.num_pixels(), L = r.num_landmarks,
                B = int64_t{1} << F;
  Require(L >= 2 && L <= 65535, fmt::format("{}: num_landmarks = {} must be in [2, 65535]", what, L));
  const std::vector<double> mean = file.Get<double>("mean_shape", L * 2, what);
  r.mean_shape = Eigen::Map<const MatX2d>(mean.data(), L, 2);
  r.pixel_landmark = file.Get<uint16_t>("pixel_landmark", T * P, what);
  r.pixel_offset = file.Get<float>("pixel_offset", T * P * 2, what);
  r.fern_pixel_a = file.Get<uint16_t>("fern_pixel_a", T * K * F, what);
  r.fern_pixel_b = file.Get<uint16_t>("fern_pixel_b", T * K * F, what);
  r.fern_threshold = file.Get<float>("fern_threshold", T * K * F, what);
  r.fern_output = file.Get<float>("fern_output", T * K * B * 2 * L, what);
  r.Check(what);
  return r;
}

// ---------------------------------------------------------------------------
// Landmark source

void RegressorLandmarkOptions::VisitFields(OptionVisitor& v) {
  v.Field("upsample", upsample);
  v.Field("detection_threshold", detection_threshold);
  v.Field("detection_passes", detection_passes);
  v.Field("detection_initialisations", detection_initialisations);
  v.Field("max_scale_change", max_scale_change);
  v.Field("max_outside_fraction", max_outside_fraction);
  v.Field("max_shape_deviation", max_shape_deviation);
  v.Field("min_interocular_px", min_interocular_px);
}

void RegressorLandmarkOptions::Check() const {
  const char* o = "RegressorLandmarkOptions";
  CheckGe(o, "upsample", upsample, 0);
  CheckLe(o, "upsample", upsample, 3);
  CheckGe(o, "detection_passes", detection_passes, 1);
  CheckGe(o, "detection_initialisations", detection_initialisations, 1);
  CheckLe(o, "detection_initialisations", detection_initialisations, 5);
  CheckGt(o, "max_scale_change", max_scale_change, 1.0);
  CheckGe(o, "max_outside_fraction", max_outside_fraction, 0.0);
  CheckGt(o, "max_shape_deviation", max_shape_deviation, 0.0);
  CheckGe(o, "min_interocular_px", min_interocular_px, 0.0);
}

struct RegressorLandmarkSource::Impl {
  ShapeRegressor regressor;
  RegressorLandmarkOptions options;
  HogFaceDetector detector;  // shared with DlibLandmarkSource (landmarks.h), no 68-point model needed
  MatX2d previous;  // last frame's landmarks (empty after a loss)
  int left_eye = kIbugRightEyeOuter, right_eye = kIbugLeftEyeOuter;  // set by EyePair

  std::vector<FaceBox> Detect(const cv::Mat& image) const { return detector.Detect(image); }
};

RegressorLandmarkSource::RegressorLandmarkSource(ShapeRegressor regressor, const RegressorLandmarkOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Check();
  regressor.Check();
  impl_->options = options;
  impl_->detector = HogFaceDetector(options.upsample, options.detection_threshold);
  impl_->regressor = std::move(regressor);
  EyePair(impl_->regressor.num_landmarks, &impl_->left_eye, &impl_->right_eye);
}

RegressorLandmarkSource::~RegressorLandmarkSource() = default;

void RegressorLandmarkSource::Reset() { impl_->previous.resize(0, 2); }

void RegressorLandmarkSource::SetNextInitialisation(const MatX2d& shape) {
  if (impl_->previous.rows() == shape.rows() && shape.allFinite()) impl_->previous = shape;
}

const ShapeRegressor& RegressorLandmarkSource::regressor() const { return impl_->regressor; }

bool RegressorLandmarkSource::IsLost(const MatX2d& shape, const cv::Size& image_size, const MatX2d* previous) const {
  const Impl& m = *impl_;
  if (shape.rows() != m.regressor.num_landmarks || !shape.allFinite()) return true;
  const double iod = (shape.row(m.left_eye) - shape.row(m.right_eye)).norm();
  if (iod < m.options.min_interocular_px) return true;
  const FaceBox b = BoxOfPoints(shape);
  const double fx = m.options.max_outside_fraction * b.width, fy = m.options.max_outside_fraction * b.height;
  if (b.x < -fx || b.y < -fy || b.x + b.width > image_size.width + fx || b.y + b.height > image_size.height + fy) {
    return true;
  }
  if (previous != nullptr && previous->rows() == shape.rows()) {
    const FaceBox pb = BoxOfPoints(*previous);
    const double ratio = std::max(b.width, b.height) / std::max(1e-9, std::max(pb.width, pb.height));
    if (ratio > m.options.max_scale_change || ratio < 1.0 / m.options.max_scale_change) return true;
  }
  // Degenerate shape: far from the mean shape after similarity alignment.
  const Similarity sim = SimilarityFromMean(shape, m.regressor.mean_shape);
  double sq = 0;
  for (int i = 0; i < shape.rows(); ++i) {
    sq += std::norm((Point(shape, i) - sim.g) / sim.c - Point(m.regressor.mean_shape, i));
  }
  return std::sqrt(sq / shape.rows()) > m.options.max_shape_deviation;
}

LandmarkResult RegressorLandmarkSource::Track(const cv::Mat& image) {
  Impl& m = *impl_;
  LandmarkResult r;
  const cv::Size size(image.cols, image.rows);
  if (m.previous.rows() == m.regressor.num_landmarks) {
    // DDE: initialise from the previous frame's landmarks.
    const MatX2d shape = m.regressor.Predict(image, m.previous);
    if (!IsLost(shape, size, &m.previous)) {
      r.found = true;
      r.box = BoxOfPoints(shape);
      r.points = shape;
      m.previous = shape;
      return r;
    }
    m.previous.resize(0, 2);  // lost: detect below
  }
  r.detected = true;
  const std::vector<FaceBox> faces = m.Detect(image);
  if (faces.empty()) return r;
  r.box = faces.front();
  const FaceBox start = m.regressor.FromDetectorBox(r.box);
  // Several starts in the box, the median of their results (Cao et al. 2012).
  static constexpr double kStarts[5][3] = {{0, 0, 1}, {-0.12, 0, 1}, {0.12, 0, 1}, {0, 0, 0.9}, {0, 0, 1.1}};
  std::vector<MatX2d> results;
  for (int k = 0; k < m.options.detection_initialisations; ++k) {
    FaceBox b = start;
    const double w = b.width * kStarts[k][2], h = b.height * kStarts[k][2];
    b.x += 0.5 * (b.width - w) + kStarts[k][0] * b.width;
    b.y += 0.5 * (b.height - h) + kStarts[k][1] * b.height;
    b.width = w;
    b.height = h;
    MatX2d s = m.regressor.MeanShapeInBox(b);
    for (int pass = 0; pass < m.options.detection_passes; ++pass) s = m.regressor.Predict(image, s);
    results.push_back(std::move(s));
  }
  MatX2d shape(results.front().rows(), 2);
  std::vector<double> values(results.size());
  for (Eigen::Index i = 0; i < shape.rows(); ++i) {
    for (int c = 0; c < 2; ++c) {
      for (size_t k = 0; k < results.size(); ++k) values[k] = results[k](i, c);
      shape(i, c) = Median(values);
    }
  }
  if (IsLost(shape, size, nullptr)) return r;
  r.found = true;
  r.points = shape;
  m.previous = shape;
  return r;
}

}  // namespace crease
