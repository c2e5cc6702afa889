// A real scanned head as a studio actor (issue 3, part 7): a mesh with UVs (OBJ, PLY
// or glTF 2.0 .gltf/.glb), an albedo texture (for glTF, the material's base colour
// texture unless one is given) and optionally a displacement map in the same UV layout,
// relit by the studio renderer like any synthetic actor. For example a neutral head
// scan with a 1024² colour map and a 4096² displacement map.
//
// The displacement is applied the way the studio builds its own actors
// (synth/hires_surface.h): the mesh is resampled on a regular grid in its UV
// layout (`grid_resolution`², one vertex per covered texel centre, Phong-rounded),
// and each grid vertex moves along the interpolated normal by
//   d = (value − displacement_midlevel) · displacement_scale_mm.
// Without a displacement map the scan is rendered as it is.
//
// Units and UV convention default to the format's: glTF positions are metres and
// its v grows downwards (as crease's), OBJ/PLY are taken as mm with v upwards.
// `units_to_mm` and `v_up` override the default for any format (three.js assets
// such as the Lee Perry-Smith head are glTF in other units with v up). A head whose
// largest extent is not between 120 and 600 mm gives a warning naming the units.
// glTF: the triangle primitives of every mesh instance of the default scene are read, placed by their
// nodes' transforms (matrix or translation-rotation-scale, composed down the node
// tree); a file without a scene gives every mesh once, untransformed.
//
// A normal map (RGB, n = 2·value − 1, read without sRGB decoding) sets the shading
// normals: the scan is resampled on the grid as for a displacement map (a flat one if
// none is given) and each grid vertex takes the map's normal at its UV. Tangent-space
// maps (the default; OpenGL convention, green = +v of the file, i.e. up in the
// image; `normal_map_green_down` for DirectX maps) are turned into the mesh frame with
// the per-vertex tangent frame of the UV layout (T = ∂p/∂u, B from ∂p/∂v,
// orthonormalised against the geometric normal); object-space maps are taken as they
// are. The grid has one vertex per texel, so the map's detail is shaded at the grid's
// resolution.
//
// Differences from a full importer: the scan is static (no blendshapes), so it can be
// relit, posed and rendered, not animated.
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/options.h"
#include "core/tri_mesh.h"
#include "synth/renderer.h"
#include "synth/sensor.h"

namespace crease {

// ScannedHeadOptions::v_up and ::normal_map_space (see there).
enum class TextureVUp { kAuto, kYes, kNo };
constexpr std::array<const char*, 3> OptionEnumNames(TextureVUp) { return {"auto", "yes", "no"}; }
enum class NormalMapSpace { kTangent, kObject };
constexpr std::array<const char*, 2> OptionEnumNames(NormalMapSpace) { return {"tangent", "object"}; }

struct ScannedHeadOptions {
  double units_to_mm = 0.0;            // scale of the mesh file's coordinates; 0 = the format's (glTF m, else mm)
  TextureVUp v_up = TextureVUp::kAuto;  // the file's texture v grows upwards: yes | no | auto (OBJ/PLY yes, glTF no)
  double displacement_scale_mm = 1.0;  // mm per unit of the displacement map's values
  double displacement_midlevel = 0.0;  // map value meaning "no displacement" (0.5 for 8-bit maps)
  int grid_resolution = 1024;          // resampling grid for displacement, texels per side
  double phong_alpha = 0.75;           // rounding of the scan's facets under the displacement
  NormalMapSpace normal_map_space = NormalMapSpace::kTangent;  // tangent | object
  bool normal_map_green_down = false;        // tangent space, DirectX convention (green = −v of the file)

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct ScannedHead {
  TriMesh surface;           // what is rendered (mm, crease UV convention)
  SceneMaterials materials;  // albedo from the texture, skin specular
  int source_vertices = 0;   // of the scan mesh
  std::vector<std::string> warnings;  // e.g. an implausible head size for the units
};

// Errors name the file and the problem: a mesh without UVs, a texture that cannot be
// read, a displacement map with several channels, a normal map without three channels
// or with NaNs. `albedo` may be empty for a glTF file whose material has a base colour
// texture; `displacement` and `normal_map` may be empty.
ScannedHead LoadScannedHead(const std::filesystem::path& mesh, const std::filesystem::path& albedo,
                            const std::filesystem::path& displacement, const ScannedHeadOptions& options,
                            const std::filesystem::path& normal_map = {});

// The head's surface turned by `yaw_deg` about +y through the centre of its
// bounding box (positions and, when present, shading normals).
TriMesh TurnedHead(const ScannedHead& head, double yaw_deg);

// A camera of horizontal field of view `fov_deg` on the +z axis from the centre of
// the mesh's bounding box, looking at that centre (up +y), at the distance where the
// box's bounding sphere fills the narrower field of view.
Camera FramingCamera(const TriMesh& mesh, double fov_deg, int width, int height);

// One still of a scanned head (`crease synth render-scan`).
struct ScanRenderOptions {
  double yaw_deg = 0.0;           // TurnedHead
  double fov_deg = 30.0;          // horizontal; FramingCamera of the head before turning
  int width = 640, height = 480;  // pixels
  int samples_per_axis = 2;       // anti-aliasing: N×N samples per pixel
  std::string light = "studio";   // a light rig spec (synth/studio.h LightRigFromSpec)
  SensorOptions sensor;           // the studio's sensor
  uint64_t seed = 1;              // sensor noise
};

struct ScanRender {
  RenderResult render;      // linear, noiseless
  SensorImage image;        // through the sensor
  int rendered_vertices = 0;
};

// Renders the head turned by options.yaw_deg under options.light, seen by the
// framing camera, through the sensor. `name` names the scene in errors.
ScanRender RenderScannedHead(const ScannedHead& head, const ScanRenderOptions& options, const std::string& name);

// The shading normals a normal map gives `mesh` (with UVs, crease convention: v
// downwards; normals computed when absent), per vertex, unit length; see above.
MatX3d NormalsFromNormalMap(const TriMesh& mesh, const cv::Mat& normal_map, const ScannedHeadOptions& options);

// The triangles of a glTF 2.0 file, scaled by `units_to_mm` (glTF's metres by
// default), with the file's UVs, and, when `base_color` is given, its first
// material's base colour texture (linear RGB float; empty when it has none).
TriMesh ReadGltfMesh(const std::filesystem::path& path, cv::Mat* base_color = nullptr, double units_to_mm = 1000.0);

// The plausible size of a head: its largest extent in [120, 600] mm (a head with
// neck and shoulders stays under 600); "" when plausible, else a warning naming
// `what` and the extent.
std::string HeadSizeWarning(const TriMesh& mesh, const std::string& what);

}  // namespace crease
