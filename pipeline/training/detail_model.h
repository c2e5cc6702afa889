// The trained detail model (paper Sec. 4): what online capture (Sec. 5.2) needs
// to regress wrinkle displacements from texture patches — the patch layout
// parameters (the layout itself is per user, from the wrinkle map of the first
// frames), the PCA basis and mean of the displacement patches, and the fern
// cascade — plus the lowpass that makes the tracker's rig compatible (Sec. 4.1).
//
// File: core/array_file.h container, magic "CREASDML", version kFormatVersion;
// the header holds the options as JSON and a short training summary; arrays hold
// the PCA and the cascade. Loading a file of another version is a clear error.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "pipeline/training/detail_extraction.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/patch_baselines.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/pca.h"
#include "pipeline/training/wrinkle_map.h"

namespace crease {

struct DetailModel {
  static constexpr uint32_t kFormatVersion = 1;

  int map_resolution = 1024;       // R of the texture and displacement maps, Sec. 4.2
  WrinkleMapOptions wrinkle;       // DoG kernels, α, regions, Sec. 4.2
  PatchLayoutOptions patch;        // w, ρ, Sec. 4.2
  DetailExtractionOptions detail;  // G, G^HF (the rig is made compatible with G), Sec. 4.1
  PatchPca pca;                    // Sec. 4.3
  FernCascade cascade;             // Sec. 4.3, Eq. 6
  // A baseline regressor used instead of the cascade when not empty (the
  // detail-accuracy experiment; not in the paper).
  PatchBaseline baseline;
  std::string training_json = "{}";  // provenance: scan set, options, summary figures

  // Throws Error (starting with `what`) when the parts disagree: patch size vs PCA
  // pixels vs cascade inputs, PCA dimensions vs cascade outputs.
  void Validate(const std::string& what) const;

  // Eq. 6 for N texture patches (N × n floats, one after another): each is
  // normalised in place (cascade.options.fern_texture_normalization), then mapped
  // to D coefficients (N × D floats in `c`) by the baseline when there is one, else
  // by the cascade.
  void RegressBatch(float* patches, int N, float* c) const;
};

void WriteDetailModel(const std::filesystem::path& path, const DetailModel& model);
DetailModel ReadDetailModel(const std::filesystem::path& path);

// Human-readable summary for `crease model info`.
std::string DescribeDetailModel(const DetailModel& model);

}  // namespace crease
