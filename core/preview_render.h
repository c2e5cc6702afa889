// A quick ray-traced preview of a mesh (Embree): the mesh framed by a camera
// orbiting its bounding box, smooth-shaded with a key light that casts shadows,
// a fill light and ambient. For looking at meshes, rigs and outputs
// (`crease mesh render`), not the studio's physically based renderer (synth/).
#pragma once

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/options.h"
#include "core/tri_mesh.h"

namespace crease {

struct PreviewRenderOptions {
  int width = 800;                  // image width, pixels
  int height = 800;                 // image height, pixels
  double fov_deg = 30.0;            // horizontal field of view, degrees
  double azimuth_deg = 20.0;        // camera orbit about the head's +y axis; 0 = looking along −z
  double elevation_deg = 10.0;      // camera orbit upwards, degrees
  double margin = 1.1;              // framing: bounding sphere radius × margin fills the view
  std::vector<double> base_color = {0.72, 0.56, 0.48};  // linear RGB albedo
  std::vector<double> background = {0.08, 0.09, 0.11};  // linear RGB
  std::vector<double> key_light_dir = {-0.5, 0.6, 0.8};  // towards the key light, head frame
  double key_intensity = 0.85;
  double fill_intensity = 0.25;     // headlight
  double ambient = 0.08;
  bool shadows = true;              // shadow rays for the key light

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct PreviewRender {
  cv::Mat image;        // CV_32FC3 linear RGB, height × width
  cv::Mat triangle_id;  // CV_32SC1, -1 for background
  Camera camera;        // the camera used (head frame = mesh frame)
  int covered_pixels = 0;
};

// `vertex_colors`: optional #V×3 linear RGB albedo per vertex (e.g. region colours
// or an error field mapped to colours); empty = options.base_color.
PreviewRender RenderPreview(const TriMesh& mesh, const PreviewRenderOptions& options,
                            const MatX3d& vertex_colors = MatX3d());

// Maps a scalar per vertex to colours (a perceptual blue–white–red diverging map
// when `diverging`, else a viridis-like sequential map) over [lo, hi].
MatX3d ScalarToColors(const Eigen::VectorXd& values, double lo, double hi, bool diverging);

}  // namespace crease
