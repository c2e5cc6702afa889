// Test helper: the PCA and fern cascade of a tiny detail model (paper Sec. 4.3),
// trained on the pairs of a given patch layout (Sec. 4.2), for the capture tests.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "pipeline/training/detail_model.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/pca.h"

namespace crease::testing {

// Fits m->pca (`pca_dimensions`) and m->cascade (`num_ferns`, P = 30, β = 5) to the
// training pairs of `layout` on the textures T^j, their DoG responses r_j and the
// displacements D^j (m->wrinkle gives α), then validates the model. Returns the
// number of training pairs.
inline int FitTinyRegressor(const PatchLayout& layout, const std::vector<cv::Mat>& textures,
                            const std::vector<cv::Mat>& responses, const std::vector<cv::Mat>& displacements,
                            int pca_dimensions, int num_ferns, DetailModel* m) {
  const TrainingPatches pairs = ExtractTrainingPatches(layout, textures, responses, displacements, m->wrinkle);
  PcaOptions po;
  po.dimensions = pca_dimensions;
  m->pca = FitPatchPca(pairs.displacement, po);
  FernOptions fo;
  fo.num_ferns = num_ferns;
  fo.num_sampled_pixels = 30;
  fo.shrinkage = 5;
  m->cascade = TrainFernCascade(pairs.texture, m->pca.ProjectPatches(pairs.displacement), fo).cascade;
  m->Validate("tiny detail model");
  return pairs.size();
}

}  // namespace crease::testing
