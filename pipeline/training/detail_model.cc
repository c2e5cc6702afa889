#include "pipeline/training/detail_model.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include "core/array_file.h"
#include "core/error.h"
#include "core/options.h"

namespace crease {

namespace {
constexpr char kMagic[] = "CREASDML";
using nlohmann::json;
}  // namespace

void DetailModel::Validate(const std::string& what) const {
  const int w = patch.patch_size;
  Require(w > 0 && pca.patch_pixels() == w * w,
          fmt::format("{}: the PCA has {} pixels per patch but the patch size is {}", what, pca.patch_pixels(), w));
  Require(pca.dimensions() > 0 && pca.basis.rows() == w * w,
          fmt::format("{}: the PCA basis is {}×{}", what, pca.basis.rows(), pca.basis.cols()));
  Require(cascade.patch_pixels == w * w,
          fmt::format("{}: the fern cascade reads {} pixels per patch but the patch size is {}", what,
                      cascade.patch_pixels, w));
  Require(cascade.dimensions == pca.dimensions(),
          fmt::format("{}: the fern cascade predicts {} coefficients but the PCA has {} dimensions", what,
                      cascade.dimensions, pca.dimensions()));
  // Issue 19: NaN in the PCA passed `model info` and failed later, inside capture.
  Require(pca.mean.allFinite() && pca.basis.allFinite() && pca.variances.allFinite(),
          fmt::format("{}: the PCA's mean, basis or variances hold NaN or infinite values", what));
  cascade.Check(what);
  if (!baseline.empty()) {
    baseline.Check(what);
    Require(baseline.patch_pixels == w * w && baseline.dimensions == pca.dimensions(),
            fmt::format("{}: the {} baseline maps {} pixels to {} coefficients, the model {} to {}", what,
                        baseline.kind, baseline.patch_pixels, baseline.dimensions, w * w, pca.dimensions()));
  }
}

void DetailModel::RegressBatch(float* patches, int N, float* c) const {
  const int n = pca.patch_pixels();
  const TextureNormalization mode = cascade.options.fern_texture_normalization;
  if (mode != TextureNormalization::kNone) {
    for (int i = 0; i < N; ++i) NormalizeTexturePatch(patches + static_cast<size_t>(i) * n, n, mode);
  }
  if (baseline.empty()) {
    cascade.PredictBatch(patches, N, c);
  } else {  // the detail-accuracy experiment's baselines (patch_baselines.h)
    baseline.PredictBatch(patches, N, c);
  }
}

void WriteDetailModel(const std::filesystem::path& path, const DetailModel& model) {
  model.Validate(path.string());
  json header;
  header["format"] = "crease detail model";
  header["map_resolution"] = model.map_resolution;
  header["wrinkle"] = json::parse(OptionsToJson(model.wrinkle));
  header["patch"] = json::parse(OptionsToJson(model.patch));
  header["detail"] = json::parse(OptionsToJson(model.detail));
  header["pca_options"] = {{"dimensions", model.pca.dimensions()}};
  header["ferns"] = json::parse(OptionsToJson(model.cascade.options));
  header["patch_pixels"] = model.cascade.patch_pixels;
  header["dimensions"] = model.cascade.dimensions;
  header["training"] = json::parse(model.training_json);
  if (!model.baseline.empty()) header["baseline"] = model.baseline.kind;
  ArrayFileWriter w(header.dump());
  const int64_t n = model.pca.patch_pixels(), D = model.pca.dimensions();
  w.Add("pca_mean", model.pca.mean.data(), {n});
  w.Add("pca_basis", model.pca.basis.data(), {D, n});  // column-major n×D: each eigen-patch contiguous
  w.Add("pca_variances", model.pca.variances.data(), {static_cast<int64_t>(model.pca.variances.size())});
  w.Add("pca_energy", model.pca.energy.data(), {static_cast<int64_t>(model.pca.energy.size())});
  const int64_t K = model.cascade.num_ferns(), F = model.cascade.depth();
  w.Add("fern_mean", model.cascade.mean.data(), {D});
  w.Add("fern_pixel_a", model.cascade.pixel_a.data(), {K, F});
  w.Add("fern_pixel_b", model.cascade.pixel_b.data(), {K, F});
  w.Add("fern_thresholds", model.cascade.thresholds.data(), {K, F});
  w.Add("fern_outputs", model.cascade.outputs.data(), {K, int64_t{1} << F, D});
  // Optional baseline arrays, row-major.
  using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  if (model.baseline.kind == "ridge") {
    const RowMajor W = model.baseline.weights;
    w.Add("baseline_weights", W.data(), {W.rows(), W.cols()});
  } else if (model.baseline.kind == "nearest") {
    const RowMajor E = model.baseline.examples, C = model.baseline.coefficients;
    w.Add("baseline_examples", E.data(), {E.rows(), E.cols()});
    w.Add("baseline_coefficients", C.data(), {C.rows(), C.cols()});
  }
  w.Write(path, kMagic, DetailModel::kFormatVersion);
}

DetailModel ReadDetailModel(const std::filesystem::path& path) {
  const std::string what = path.string();
  const ArrayFile file = ReadArrayFile(path, kMagic, DetailModel::kFormatVersion, "detail model");
  DetailModel m;
  try {
    const json header = json::parse(file.header_json);
    Require(header.value("format", "") == "crease detail model",
            fmt::format("{}: header format is not \"crease detail model\"", what));
    m.map_resolution = header.at("map_resolution").get<int>();
    SetOptionsFromStoredJson(header.at("wrinkle").dump(), what + " (wrinkle options)", &m.wrinkle);
    SetOptionsFromStoredJson(header.at("patch").dump(), what + " (patch options)", &m.patch);
    SetOptionsFromStoredJson(header.at("detail").dump(), what + " (detail options)", &m.detail);
    SetOptionsFromStoredJson(header.at("ferns").dump(), what + " (fern options)", &m.cascade.options);
    m.cascade.patch_pixels = header.at("patch_pixels").get<int>();
    m.cascade.dimensions = header.at("dimensions").get<int>();
    m.training_json = header.at("training").dump();
    m.baseline.kind = header.value("baseline", "");
  } catch (const json::exception& e) {
    throw Error(fmt::format("{}: malformed detail model header: {}", what, e.what()));
  }
  const int n = m.cascade.patch_pixels, D = m.cascade.dimensions;
  Require(n > 0 && D > 0, fmt::format("{}: invalid patch_pixels {} or dimensions {}", what, n, D));
  const auto mean = file.Get<float>("pca_mean", n, what);
  m.pca.mean = Eigen::Map<const Eigen::VectorXf>(mean.data(), n);
  const auto basis = file.Get<float>("pca_basis", int64_t{n} * D, what);
  m.pca.basis = Eigen::Map<const Eigen::MatrixXf>(basis.data(), n, D);
  const auto var = file.Get<double>("pca_variances", -1, what);
  m.pca.variances = Eigen::Map<const Eigen::VectorXd>(var.data(), static_cast<int>(var.size()));
  m.pca.energy = file.Get<double>("pca_energy", -1, what);
  const int64_t K = m.cascade.num_ferns(), F = m.cascade.depth();
  m.cascade.mean = file.Get<float>("fern_mean", D, what);
  m.cascade.pixel_a = file.Get<uint16_t>("fern_pixel_a", K * F, what);
  m.cascade.pixel_b = file.Get<uint16_t>("fern_pixel_b", K * F, what);
  m.cascade.thresholds = file.Get<float>("fern_thresholds", K * F, what);
  m.cascade.outputs = file.Get<float>("fern_outputs", K * (int64_t{1} << F) * D, what);
  if (!m.baseline.empty()) {
    using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    auto matrix = [&](const char* name) -> Eigen::MatrixXf {
      const auto it = file.arrays.find(name);
      Require(it != file.arrays.end() && it->second.shape.size() == 2,
              fmt::format("{}: the {} baseline lacks its 2D array '{}'", what, m.baseline.kind, name));
      const int64_t rows = it->second.shape[0], cols = it->second.shape[1];
      const auto v = file.Get<float>(name, rows * cols, what);
      return Eigen::Map<const RowMajor>(v.data(), rows, cols);
    };
    m.baseline.patch_pixels = n;
    m.baseline.dimensions = D;
    if (m.baseline.kind == "ridge") {
      m.baseline.weights = matrix("baseline_weights");
    } else if (m.baseline.kind == "nearest") {
      m.baseline.examples = matrix("baseline_examples");
      m.baseline.coefficients = matrix("baseline_coefficients");
    }
  }
  m.Validate(what);
  return m;
}

std::string DescribeDetailModel(const DetailModel& m) {
  std::string s;
  s += fmt::format("detail model (format version {})\n", DetailModel::kFormatVersion);
  s += fmt::format("  maps              {}×{} texels\n", m.map_resolution, m.map_resolution);
  s += fmt::format("  patches           w = {}, rho = {}\n", m.patch.patch_size, m.patch.patch_density);
  s += fmt::format("  wrinkle map       DoG sigma {} / {} texels at {}², alpha = {}, regions: {}\n",
                   m.wrinkle.dog_small_sigma, m.wrinkle.dog_large_sigma, m.wrinkle.dog_reference_resolution,
                   m.wrinkle.wrinkle_threshold, fmt::join(m.wrinkle.patch_regions, ", "));
  s += fmt::format("  lowpass G         {} mm (G^HF {} mm)\n", m.detail.lowpass_bandwidth_mm,
                   m.detail.high_frequency_bandwidth_mm);
  const double energy = m.pca.dimensions() <= static_cast<int>(m.pca.energy.size())
                            ? m.pca.energy[m.pca.dimensions() - 1]
                            : 0.0;
  s += fmt::format("  PCA               {} dimensions of {}, {:.1f} % of the energy\n", m.pca.dimensions(),
                   m.pca.patch_pixels(), 100.0 * energy);
  s += fmt::format("  fern cascade      K = {}, F = {}, P = {}, beta = {}\n", m.cascade.num_ferns(),
                   m.cascade.depth(), m.cascade.options.num_sampled_pixels, m.cascade.options.shrinkage);
  try {
    const json t = json::parse(m.training_json);
    if (t.contains("actors")) s += fmt::format("  trained on        {} actors, {} scans, {} patches\n",
                                               t.value("actors", 0), t.value("scans", 0), t.value("training_pairs", 0));
    if (t.contains("scan_set")) s += fmt::format("  scan set          {}\n", t.value("scan_set", ""));
  } catch (const json::exception&) {
  }
  if (!m.baseline.empty()) {
    s += fmt::format("  regressor         the '{}' baseline (not the cascade; pipeline/training/patch_baselines.h)\n",
                     m.baseline.kind);
  }
  return s;
}

}  // namespace crease
