#include "synth/studio.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <string_view>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/mesh_ops.h"
#include "core/mesh_primitives.h"
#include "synth/ict_head.h"

namespace crease {

namespace {

// The numbers of a light spec "PREFIX:A:B[:…]" (`usage` names the expected form);
// nullopt when `spec` does not start with `prefix`.
std::optional<std::vector<double>> LightSpecNumbers(const std::string& spec, std::string_view prefix,
                                                    std::string_view usage, size_t min_count, size_t max_count) {
  if (spec.rfind(prefix, 0) != 0) return std::nullopt;
  std::vector<double> values;
  std::stringstream ss(spec.substr(prefix.size()));
  for (std::string item; std::getline(ss, item, ':');) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    Require(!item.empty() && end == item.c_str() + item.size() && std::isfinite(v),
            fmt::format("light '{}': '{}' is not a number (expected {})", spec, item, usage));
    values.push_back(v);
  }
  Require(values.size() >= min_count && values.size() <= max_count,
          fmt::format("light '{}': expected {} in degrees", spec, usage));
  return values;
}

// Sets the ambient of a one-light rig from a spec's optional last number.
void SetSpecAmbient(const std::string& spec, const std::vector<double>& values, size_t index, LightRig* rig) {
  if (values.size() <= index) return;
  Require(values[index] >= 0.0, fmt::format("light '{}': ambient {} must be >= 0", spec, values[index]));
  std::get<AmbientOcclusionLight>(rig->lights[1]).color = Eigen::Vector3d::Constant(values[index]);
}

// "directional:AZ:EL[:AMBIENT]" → DirectionalRig(AZ, EL) with its ambient set;
// "sphere:AZ:EL:DIAMETER[:AMBIENT]" → the same light from a sphere (a lamp or softbox)
// seen DIAMETER degrees wide, as bright on a surface facing it: its shadows have a
// penumbra. nullopt for any other spec.
std::optional<LightRig> OneLightRigFromSpec(const std::string& spec) {
  if (auto v = LightSpecNumbers(spec, "directional:", "directional:AZIMUTH:ELEVATION[:AMBIENT]", 2, 3)) {
    LightRig rig = DirectionalRig((*v)[0], (*v)[1]);
    SetSpecAmbient(spec, *v, 2, &rig);
    rig.name = spec;
    return rig;
  }
  if (auto v = LightSpecNumbers(spec, "sphere:", "sphere:AZIMUTH:ELEVATION:DIAMETER[:AMBIENT]", 3, 4)) {
    const double diameter = (*v)[2];
    Require(diameter > 0.0 && diameter < 120.0,
            fmt::format("light '{}': diameter {} must be in (0, 120) degrees", spec, diameter));
    LightRig rig = DirectionalRig((*v)[0], (*v)[1]);
    SphereLight sphere;
    const double distance = 1500.0;
    sphere.centre = distance * std::get<DirectionalLight>(rig.lights[0]).direction;
    sphere.radius = distance * std::sin(0.5 * diameter * std::numbers::pi / 180.0);
    sphere.color = std::get<DirectionalLight>(rig.lights[0]).color;
    sphere.samples = 16;
    rig.lights[0] = sphere;
    SetSpecAmbient(spec, *v, 3, &rig);
    rig.name = spec;
    return rig;
  }
  return std::nullopt;
}

}  // namespace

LightRig LightRigFromSpec(const std::string& spec) {
  if (auto rig = OneLightRigFromSpec(spec)) return *rig;
  const std::string ext = LowerExtension(spec);
  if (ext != ".exr" && ext != ".hdr") return MakeLightRig(spec);
  LightRig rig;
  rig.name = spec;
  EnvironmentLight env;
  env.map = std::make_shared<const EnvironmentMap>(ReadImage(spec), spec);
  env.samples = 16;
  rig.lights.push_back(env);
  return rig;
}

void StudioOptions::VisitFields(OptionVisitor& v) {
  v.Field("width", width);
  v.Field("height", height);
  v.Field("fov_deg", fov_deg);
  v.Field("distance_mm", distance_mm);
  v.Field("light", light);
  v.Field("light_fill", light_fill);
  v.Field("samples_per_axis", samples_per_axis);
  v.Field("subsurface_mm", subsurface_mm);
  v.Field("motion_blur_subframes", motion_blur_subframes);
  v.Field("shutter", shutter);
  v.Field("occluder", occluder);
  v.Field("background", background);
  v.Field("seed", seed);
  v.Section("sensor", sensor);
}

void StudioOptions::Check() const {
  const char* o = "StudioOptions";
  CheckGe(o, "width", width, 16);
  CheckGe(o, "height", height, 16);
  CheckLe(o, "width", width, 8192);
  CheckLe(o, "height", height, 8192);
  CheckGt(o, "fov_deg", fov_deg, 1.0);
  CheckLt(o, "fov_deg", fov_deg, 150.0);
  CheckGt(o, "distance_mm", distance_mm, 100.0);
  CheckGe(o, "light_fill", light_fill, 0.0);
  CheckGe(o, "samples_per_axis", samples_per_axis, 1);
  CheckLe(o, "samples_per_axis", samples_per_axis, 16);
  CheckGe(o, "subsurface_mm", subsurface_mm, 0.0);
  CheckLe(o, "subsurface_mm", subsurface_mm, 20.0);
  CheckGe(o, "motion_blur_subframes", motion_blur_subframes, 1);
  CheckGt(o, "shutter", shutter, 0.0);
  CheckLe(o, "shutter", shutter, 1.0);
  Require(background.size() == 3 && std::all_of(background.begin(), background.end(),
                                                 [](double c) { return std::isfinite(c) && c >= 0.0; }),
          fmt::format("StudioOptions: background needs 3 finite values >= 0 (linear RGB), got {}",
                      fmt::join(background, ",")));
  LightRigFromSpec(light);  // throws for unknown presets and unreadable maps, naming them
  sensor.Check();
}

namespace {

// The underlay lies kUnderlayDepthMm inside the face, except near the face part's
// rim (the seam with the cranium, neck, hair or ears): there its depth is
// kUnderlayRimDepthMm plus kUnderlayDepthSlope × the distance from the rim (along
// the mesh's edges), so the texel-wide gap between the hi-res grid's stair-stepped
// edge and the rim shows skin almost on the surface, not a dark slit 3 mm deep
// (which showed along the jaw and temples when the head turns). The actor's static
// shape fades out towards the rim (synth/actor.cc), so the hi-res face stays
// outside the shallow underlay there.
constexpr double kUnderlayDepthMm = 3.0;
constexpr double kUnderlayRimDepthMm = 0.0;
constexpr double kUnderlayDepthSlope = 0.3;  // mm of depth per mm from the rim
constexpr double kSkinRimBlendMm = 8.0;      // the face's skin maps blend into the parts' material

// Material of a rig part, by its name.
Material PartMaterial(const std::string& name, const Eigen::Vector3f& skin_tone) {
  auto has = [&](const char* s) { return name.find(s) != std::string::npos; };
  Material m = MaterialPreset("skin");
  m.textured = false;
  m.albedo = skin_tone;
  if (has("lash")) {  // eyelash strips (ICT-FaceKit)
    m.albedo = {0.02f, 0.014f, 0.01f};
    m.specular = 0.3f;
    m.roughness = 0.5f;
  } else if (has("pupil")) {
    m.albedo = {0.01f, 0.01f, 0.012f};
    m.specular = 1.0f;
    m.roughness = 0.1f;
  } else if (has("iris")) {
    m.albedo = {0.12f, 0.07f, 0.03f};
    m.specular = 1.0f;
    m.roughness = 0.1f;
  } else if (has("socket")) {  // the flesh behind the eyeballs (ICT-FaceKit)
    m.albedo = {0.16f, 0.05f, 0.045f};
    m.specular = 0.6f;
    m.roughness = 0.3f;
  } else if (has("gums") || has("tongue")) {
    m.albedo = {0.32f, 0.06f, 0.065f};
    m.specular = 0.8f;
    m.roughness = 0.25f;
  } else if (has("eye")) {  // eyeballs: sclera
    m.albedo = {0.62f, 0.58f, 0.55f};
    m.specular = 1.0f;
    m.roughness = 0.12f;
  } else if (has("mouth") || has("cavity")) {
    m.albedo = {0.05f, 0.01f, 0.01f};
    m.specular = 0.2f;
  } else if (has("teeth")) {
    m.albedo = {0.6f, 0.58f, 0.5f};
  } else if (has("hair") || has("brow")) {
    m.albedo = {0.035f, 0.022f, 0.014f};
    m.specular = 0.6f;
    m.roughness = 0.5f;
  }
  return m;
}

// Texture padding: texels outside the chart (`inside` = 0) take the mean of their
// covered neighbours, one ring per pass, so that bilinear lookups at the chart's
// edge (the hi-res surface's last texels, the underlay) do not mix in black.
void PadOutsideChart(const cv::Mat& inside, int rings, const std::vector<cv::Mat*>& maps) {
  cv::Mat mask;
  inside.convertTo(mask, CV_32F, 1.0 / 255.0);
  for (int r = 0; r < rings; ++r) {
    cv::Mat count;
    cv::boxFilter(mask, count, -1, cv::Size(3, 3), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    const cv::Mat ring = (mask == 0.0f) & (count > 0.0f);
    for (cv::Mat* map : maps) {
      std::vector<cv::Mat> masks(static_cast<size_t>(map->channels()), mask), counts(masks.size(), count);
      cv::Mat m, c, sum;
      cv::merge(masks, m);
      cv::merge(counts, c);
      cv::boxFilter(map->mul(m), sum, -1, cv::Size(3, 3), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
      cv::Mat mean;
      cv::divide(sum, c, mean);
      mean.copyTo(*map, ring);
    }
    mask.setTo(1.0f, ring);
  }
}


// True when rig vertex v belongs to the face part (every vertex does when the rig
// has no face part or no parts).
bool IsFaceVertex(const FaceRig& rig, int face_part, int v) {
  return face_part < 0 || rig.vertex_part.empty() || rig.vertex_part[v] == face_part;
}

bool IsFaceTriangle(const FaceRig& rig, int face_part, const Eigen::Vector3i& t) {
  return IsFaceVertex(rig, face_part, t[0]) && IsFaceVertex(rig, face_part, t[1]) &&
         IsFaceVertex(rig, face_part, t[2]);
}

// Camera: looking at the landmarks' centre (or the face's) from the front.
// `head_centre`: the centre of the head's bounding box, at the landmarks' height.
Camera FrontCamera(const FaceRig& rig, const StudioOptions& options, Eigen::Vector3d* head_centre) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  if (!rig.landmarks.empty()) {
    for (const auto& l : rig.landmarks) centre += rig.neutral.V.row(l.vertex).transpose();
    centre /= static_cast<double>(rig.landmarks.size());
  } else {
    const auto [lo, hi] = BoundingBox(rig.neutral);
    centre = 0.5 * (lo + hi);
  }
  const auto [lo, hi] = BoundingBox(rig.neutral);
  *head_centre = Eigen::Vector3d(0.5 * (lo.x() + hi.x()), centre.y(), 0.5 * (lo.z() + hi.z()));
  return LookAtCamera(CameraIntrinsics::FromFov(options.fov_deg, options.width, options.height),
                      centre + Eigen::Vector3d(0, 0, options.distance_mm), centre, Eigen::Vector3d::UnitY());
}

// The rig's triangles split: the non-face ones appended to `faces`, their vertices
// after the hi-res face's `hires_vertices`; the face ones to `underlay_faces`, over
// new underlay vertices whose rig vertex is appended to `underlay_source`.
void SplitRigTriangles(const FaceRig& rig, int face_part, int hires_vertices, std::vector<Eigen::Vector3i>* faces,
                       std::vector<Eigen::Vector3i>* underlay_faces, std::vector<int>* underlay_source) {
  std::vector<int> underlay_of(rig.num_vertices(), -1);
  for (int f = 0; f < rig.neutral.num_faces(); ++f) {
    const Eigen::Vector3i t = rig.neutral.F.row(f).transpose();
    if (IsFaceTriangle(rig, face_part, t)) {
      Eigen::Vector3i u;
      for (int k = 0; k < 3; ++k) {
        if (underlay_of[t[k]] < 0) {
          underlay_of[t[k]] = static_cast<int>(underlay_source->size());
          underlay_source->push_back(t[k]);
        }
        u[k] = underlay_of[t[k]];
      }
      underlay_faces->push_back(u);
    } else {
      faces->emplace_back(t + Eigen::Vector3i::Constant(hires_vertices));
    }
  }
}

// Each rig vertex's distance from the face's rim over the edges of the
// `num_face_triangles` face triangles (Dijkstra, neutral lengths). The rim: face
// vertices that also belong to a non-face triangle, or that sit exactly where a
// non-face vertex sits (rigs, like crease's procedural head, may give the face its
// own copies of the seam's vertices). A rig that is all face has no seam: the
// distance is infinite, and the underlay stays deep everywhere.
Eigen::VectorXd RimDistance(const FaceRig& rig, int face_part, size_t num_face_triangles) {
  const int nr = rig.num_vertices();
  std::vector<uint8_t> rim(nr, 0);
  std::set<std::array<double, 3>> seam;
  for (int f = 0; f < rig.neutral.num_faces(); ++f) {
    const Eigen::Vector3i t = rig.neutral.F.row(f).transpose();
    if (!IsFaceTriangle(rig, face_part, t)) {
      for (int k = 0; k < 3; ++k) {
        rim[t[k]] = 1;
        seam.insert({rig.neutral.V(t[k], 0), rig.neutral.V(t[k], 1), rig.neutral.V(t[k], 2)});
      }
    }
  }
  for (int v = 0; v < nr; ++v) {
    if (seam.count({rig.neutral.V(v, 0), rig.neutral.V(v, 1), rig.neutral.V(v, 2)})) rim[v] = 1;
  }
  TriMesh face_mesh;  // the face triangles, rig vertex ids
  face_mesh.V = rig.neutral.V;
  face_mesh.F.resize(static_cast<Eigen::Index>(num_face_triangles), 3);
  Eigen::Index face_rows = 0;
  for (int f = 0; f < rig.neutral.num_faces(); ++f) {
    const Eigen::Vector3i t = rig.neutral.F.row(f).transpose();
    if (IsFaceTriangle(rig, face_part, t)) face_mesh.F.row(face_rows++) = t.transpose();
  }
  std::vector<int> rim_vertices;
  for (int v = 0; v < nr; ++v) {
    if (rim[v] && IsFaceVertex(rig, face_part, v)) rim_vertices.push_back(v);
  }
  return rim_vertices.empty() ? Eigen::VectorXd::Constant(nr, std::numeric_limits<double>::infinity())
                              : DijkstraDistance(face_mesh, rim_vertices);
}

// Towards the seam the face's maps blend into the uniform material of the parts
// it meets (the mean albedo `skin_tone`, the nominal specular and roughness), so
// the seam shows no change of colour or sheen; then texels outside the chart
// (`red` = 0) are padded.
void BlendSkinTowardsSeam(const FaceRig& rig, const ActorModel& model, const cv::Mat& red,
                          const Eigen::Vector3f& skin_tone, SceneMaterials* materials) {
  const float nominal_specular = MaterialPreset("skin").specular;
  const Eigen::Vector3f hair_tone = model.skin().hair_color;
  const cv::Mat& painted_hair_map = model.skin().hair;
  const int size = materials->albedo.rows;
  const cv::Mat fade = ChartRimFade(rig, size, model.anchors().mm_per_uv, kSkinRimBlendMm, /*outer_rim_only=*/true);
  const float nominal_roughness = MaterialPreset("skin").roughness;
  for (int j = 0; j < size; ++j) {
    for (int i = 0; i < size; ++i) {
      const float w = fade.at<float>(j, i);
      if (w >= 1.0f) continue;
      cv::Vec3f& a = materials->albedo.at<cv::Vec3f>(j, i);
      if (a[0] <= 0.0f) continue;  // outside the chart
      // The scalp's painted hair meets the part "scalp_hair", the rest the skin-toned parts.
      const float h = painted_hair_map.empty() ? 0.0f : painted_hair_map.at<float>(j, i);
      for (int k = 0; k < 3; ++k) a[k] = w * a[k] + (1.0f - w) * ((1.0f - h) * skin_tone[k] + h * hair_tone[k]);
      float& sp = materials->specular.at<float>(j, i);
      sp = w * sp + (1.0f - w) * nominal_specular;
      float& ro = materials->roughness.at<float>(j, i);
      ro = w * ro + (1.0f - w) * nominal_roughness;
    }
  }
  PadOutsideChart(red > 0, 4, {&materials->albedo, &materials->specular, &materials->roughness});
}

// Materials of the scene's `total` vertices: part 0 = textured skin (hi-res face,
// underlay, the rig's face part), 1 + p = rig part p, last = occluder (from
// vertex `occluder_first`, -1: none).
SceneMaterials StudioMaterials(const FaceRig& rig, const ActorModel& model, int total, int hires_vertices,
                               int occluder_first) {
  SceneMaterials materials;
  materials.albedo = model.skin().albedo.clone();  // blended towards the seam below
  // The actor's skin maps are in physical terms (synth/skin.h): a specular weight
  // with 1 = nominal skin, and GGX α. The renderer takes the specular intensity ρ_s
  // in [0, 1] (nominal skin 0.5, MaterialPreset("skin")) and the perceptual
  // roughness r with α = r².
  const float nominal_specular = MaterialPreset("skin").specular;
  cv::Mat spec = model.skin().specular * nominal_specular;
  cv::min(spec, 1.0, materials.specular);
  cv::max(materials.specular, 0.0, materials.specular);
  cv::Mat alpha;
  cv::max(model.skin().roughness, 0.02f * 0.02f, alpha);
  cv::sqrt(alpha, materials.roughness);
  cv::Mat red;
  cv::extractChannel(materials.albedo, red, 0);
  const cv::Scalar mean_albedo = cv::mean(materials.albedo, red > 0);
  const Eigen::Vector3f skin_tone(static_cast<float>(mean_albedo[0]), static_cast<float>(mean_albedo[1]),
                                  static_cast<float>(mean_albedo[2]));
  const Eigen::Vector3f hair_tone = model.skin().hair_color;
  BlendSkinTowardsSeam(rig, model, red, skin_tone, &materials);

  Material face = MaterialPreset("skin");
  face.textured = true;
  materials.part_materials.push_back(face);
  const bool painted_hair = !model.skin().hair.empty() && cv::countNonZero(model.skin().hair > 0.5f) > 0;
  for (const auto& name : rig.part_names) {
    Material m = name == "face" ? face : PartMaterial(name, skin_tone);
    if (name == "scalp_hair" && painted_hair) m.albedo = hair_tone;  // the same colour as the chart's painted hair
    materials.part_materials.push_back(m);
  }
  Material occluder = MaterialPreset("grey");
  occluder.textured = false;
  materials.part_materials.push_back(occluder);
  const int occluder_part = static_cast<int>(materials.part_materials.size()) - 1;
  const int nr = rig.num_vertices();
  materials.vertex_part.assign(total, 0);
  for (int v = 0; v < nr; ++v) {
    materials.vertex_part[hires_vertices + v] = rig.vertex_part.empty() ? 0 : 1 + rig.vertex_part[v];
  }
  for (int v = occluder_first >= 0 ? occluder_first : total; v < total; ++v) materials.vertex_part[v] = occluder_part;
  return materials;
}

}  // namespace

struct Studio::Scene {
  FaceRig rig;
  int hires_vertices = 0;
  int face_part = -1;                 // the rig's face part (-1: every vertex is face)
  std::vector<int> underlay_source;   // rig vertex of each underlay vertex
  std::vector<double> underlay_depth; // its depth inside the face, mm
  int occluder_first = -1;            // first occluder vertex (-1: none)
  TriMesh occluder_unit;              // unit sphere
  std::unique_ptr<Renderer> renderer;
};

Studio::~Studio() = default;

Studio::Studio(const FaceRig& rig, const Actor& actor, const StudioOptions& options)
    : options_(options), scene_(std::make_unique<Scene>()) {
  options_.Check();
  RequireDressedIfIct(rig, "studio rig");
  default_lights_ = LightRigFromSpec(options_.light);
  model_ = std::make_unique<ActorModel>(rig, actor);
  Scene& s = *scene_;
  s.rig = rig;
  s.face_part = rig.PartIndex("face");
  camera_ = FrontCamera(rig, options_, &head_centre_);

  // Topology: hi-res face | rig (non-face triangles) | underlay (face triangles, pushed in) | occluder.
  const ActorFrame f0 = model_->Frame(Eigen::VectorXd::Zero(rig.num_expressions()), true);
  s.hires_vertices = f0.hires.num_vertices();
  const int nr = rig.num_vertices();
  std::vector<Eigen::Vector3i> faces;
  for (int f = 0; f < f0.hires.num_faces(); ++f) faces.emplace_back(f0.hires.F.row(f).transpose());
  std::vector<Eigen::Vector3i> underlay_faces;
  SplitRigTriangles(rig, s.face_part, s.hires_vertices, &faces, &underlay_faces, &s.underlay_source);
  const Eigen::VectorXd rim_distance = RimDistance(rig, s.face_part, underlay_faces.size());
  for (int v : s.underlay_source) {
    s.underlay_depth.push_back(std::min(kUnderlayDepthMm, kUnderlayRimDepthMm + kUnderlayDepthSlope * rim_distance[v]));
  }
  const int underlay_first = s.hires_vertices + nr;
  for (const auto& u : underlay_faces) faces.emplace_back(u + Eigen::Vector3i::Constant(underlay_first));
  const int nu = static_cast<int>(s.underlay_source.size());
  int total = underlay_first + nu;
  if (options_.occluder) {
    s.occluder_unit = MakeIcosphere(1.0, 3);
    s.occluder_first = total;
    for (int f = 0; f < s.occluder_unit.num_faces(); ++f) {
      faces.emplace_back(s.occluder_unit.F.row(f).transpose() + Eigen::Vector3i::Constant(total));
    }
    total += s.occluder_unit.num_vertices();
  }

  TriMesh mesh;
  mesh.F.resize(static_cast<int>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) mesh.F.row(static_cast<int>(f)) = faces[f].transpose();
  mesh.UV = MatX2d::Constant(total, 2, 2.0);  // outside the face chart: per-part materials
  mesh.UV.topRows(s.hires_vertices) = f0.hires.UV;
  mesh.UV.middleRows(s.hires_vertices, nr) = rig.neutral.UV;
  for (int i = 0; i < nu; ++i) mesh.UV.row(underlay_first + i) = rig.neutral.UV.row(s.underlay_source[i]);

  SceneMaterials materials = StudioMaterials(rig, *model_, total, s.hires_vertices, s.occluder_first);
  SequenceFrame rest;
  mesh.V = SceneVertices(f0, rest, WorldFromHead(rest));
  s.renderer = std::make_unique<Renderer>(mesh, std::move(materials), RendererOptions{}, "studio scene");
}

Rigid3d Studio::WorldFromHead(const SequenceFrame& f) const {
  const double d = std::numbers::pi / 180.0;
  const Eigen::Quaterniond q = Eigen::AngleAxisd(f.yaw_deg * d, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(f.pitch_deg * d, Eigen::Vector3d::UnitX()) *
                               Eigen::AngleAxisd(f.roll_deg * d, Eigen::Vector3d::UnitZ());
  // Rotation about the head centre, then the translation.
  const Eigen::Vector3d t = head_centre_ - q * head_centre_ + Eigen::Vector3d(f.tx_mm, f.ty_mm, f.tz_mm);
  return Rigid3d(q, t);
}

LightRig Studio::FrameLights(const Sequence& sequence, const SequenceFrame& f) const {
  bool keyed = false;
  for (const auto& k : sequence.keys) {
    for (const auto& [channel, v] : k.values) keyed = keyed || channel.rfind("light:", 0) == 0;
  }
  if (!keyed) return default_lights_;
  LightRig rig;
  rig.name = fmt::format("directional az {:.1f} el {:.1f}", f.light_azimuth_deg, f.light_elevation_deg);
  rig.lights.push_back(DirectionalFromAzimuthElevation(f.light_azimuth_deg, f.light_elevation_deg, f.light_intensity));
  if (options_.light_fill > 0) {
    AmbientOcclusionLight fill;
    fill.color = Eigen::Vector3d::Constant(options_.light_fill);
    rig.lights.push_back(fill);
  }
  return rig;
}

MatX3d Studio::SceneVertices(const ActorFrame& frame, const SequenceFrame& f, const Rigid3d& world_from_head,
                             MatX3d* normals) const {
  const Scene& s = *scene_;
  const int nr = s.rig.num_vertices(), nu = static_cast<int>(s.underlay_source.size());
  const int total = s.hires_vertices + nr + nu + (s.occluder_first >= 0 ? s.occluder_unit.num_vertices() : 0);
  MatX3d V(total, 3);
  V.topRows(s.hires_vertices) = frame.hires.V;
  V.middleRows(s.hires_vertices, nr) = frame.coarse.V;
  const MatX3d& N = frame.coarse.N;
  for (int i = 0; i < nu; ++i) {
    const int v = s.underlay_source[i];
    V.row(s.hires_vertices + nr + i) = frame.coarse.V.row(v) - s.underlay_depth[i] * N.row(v);
  }
  const Eigen::Matrix3d R = world_from_head.rotation.toRotationMatrix();
  const int posed = s.hires_vertices + nr + nu;
  for (int i = 0; i < posed; ++i) V.row(i) = (R * V.row(i).transpose() + world_from_head.translation).transpose();
  if (normals) {
    // The layers carry their normals (the hi-res grid's from central differences,
    // the coarse rig's area-weighted): rotating them is far cheaper than recomputing.
    MatX3d& Nn = *normals;
    Nn.resize(total, 3);
    Nn.topRows(s.hires_vertices) = frame.hires.N;
    Nn.middleRows(s.hires_vertices, nr) = frame.coarse.N;
    for (int i = 0; i < nu; ++i) Nn.row(s.hires_vertices + nr + i) = frame.coarse.N.row(s.underlay_source[i]);
    Nn.topRows(posed) = Nn.topRows(posed) * R.transpose();
    if (s.occluder_first >= 0) Nn.bottomRows(s.occluder_unit.num_vertices()) = s.occluder_unit.N;
  }
  if (s.occluder_first >= 0) {
    // Sequences place the occluder relative to the head centre; without one it is parked behind the camera.
    const Eigen::Vector3d c = f.has_occluder ? Eigen::Vector3d(head_centre_ + Eigen::Vector3d(f.occluder_x_mm, f.occluder_y_mm, f.occluder_z_mm))
                                             : Eigen::Vector3d(camera_.CentreInHead() + Eigen::Vector3d(0, 0, 5000));
    const double r = f.has_occluder ? std::max(1.0, f.occluder_radius_mm) : 1.0;
    for (int i = 0; i < s.occluder_unit.num_vertices(); ++i) {
      V.row(s.occluder_first + i) = (c + r * s.occluder_unit.V.row(i).transpose()).transpose();
    }
  }
  return V;
}

StudioFrame Studio::RenderFrame(const Sequence& sequence, int index) const {
  const SequenceFrame f = sequence.Frame(index);
  Eigen::VectorXd w(scene_->rig.num_expressions());
  const std::vector<double> weights = ExpressionWeightsForRig(f, scene_->rig);
  for (int i = 0; i < w.size(); ++i) w[i] = weights[i];
  return Render(w, f, FrameLights(sequence, f), camera_, sequence.motion_blur, 1.0 / sequence.fps, &sequence,
                static_cast<uint64_t>(index));
}

StudioFrame Studio::RenderStill(const Eigen::VectorXd& expression, const SequenceFrame& f,
                                const LightRig* light_override, const Camera* camera_override, uint64_t seed) const {
  const LightRig& lights = light_override ? *light_override : default_lights_;
  return Render(expression, f, lights, camera_override ? *camera_override : camera_, false, 0.0, nullptr, seed);
}

StudioFrame Studio::Render(const Eigen::VectorXd& expression, const SequenceFrame& f, const LightRig& lights,
                           const Camera& camera, bool motion_blur, double frame_dt, const Sequence* sequence,
                           uint64_t seed) const {
  Scene& s = *scene_;
  StudioFrame out;
  ScopedTimer t_surface(timing_.get(), "actor surface");
  out.actor = model_->Frame(expression, true);
  t_surface.Stop();
  ScopedTimer t_render(timing_.get(), "scene update + render");
  const Rigid3d world_from_head = WorldFromHead(f);
  RenderOptions ro;
  ro.samples_per_axis = options_.samples_per_axis;
  ro.subsurface_mm = options_.subsurface_mm;
  ro.passes = true;
  ro.background = options_.background;
  Rng rng = Rng(options_.seed).Fork(seed);
  if (motion_blur && sequence && options_.motion_blur_subframes > 1) {
    // Over the shutter the head moves (pose sampled from the sequence); the
    // expression is held at the frame's (its change within 1/60 s is small).
    auto frame_at = [&](double u) {
      SequenceFrame g = sequence->At(f.time_s + (u - 0.5) * options_.shutter * frame_dt);
      g.has_occluder = f.has_occluder;
      return MotionBlurFrame{SceneVertices(out.actor, g, WorldFromHead(g)), camera};
    };
    out.render = RenderMotionBlurred(*s.renderer, frame_at, options_.motion_blur_subframes, lights, ro, rng);
  } else {
    MatX3d N;
    const MatX3d V = SceneVertices(out.actor, f, world_from_head, &N);
    if (out.actor.hires.N.rows() == out.actor.hires.V.rows() && N.allFinite()) {
      s.renderer->UpdateGeometry(V, N);
    } else {
      s.renderer->UpdateGeometry(V);
    }
    out.render = s.renderer->Render(camera, lights, ro, rng);
  }
  t_render.Stop();
  ScopedTimer t_sensor(timing_.get(), "sensor");
  out.image = ApplySensor(out.render.image, options_.sensor, rng);
  t_sensor.Stop();
  ScopedTimer t_truth(timing_.get(), "ground truth");

  // Ground truth: projections of every coarse vertex and landmark, and their visibility
  // from the depth pass (visible = in the image and not behind the rendered surface).
  StudioFrameTruth& t = out.truth;
  t.index = f.index;
  t.time_s = f.time_s;
  t.expression = expression;
  t.yaw_deg = f.yaw_deg;
  t.pitch_deg = f.pitch_deg;
  t.roll_deg = f.roll_deg;
  t.translation_mm = Eigen::Vector3d(f.tx_mm, f.ty_mm, f.tz_mm);
  t.cam_from_head = camera.cam_from_head * world_from_head;
  t.light_description = lights.name;
  const Camera head_camera(camera.intrinsics, t.cam_from_head);
  const MatX3d& V = out.actor.coarse.V;
  t.vertex_pixels = head_camera.ProjectAll(V);
  t.vertex_visible.assign(V.rows(), 0);
  const cv::Mat& depth = out.render.depth;
  for (int v = 0; v < V.rows(); ++v) {
    const Eigen::Vector2d p = t.vertex_pixels.row(v).transpose();
    if (!p.allFinite() || !head_camera.InImage(p)) continue;
    const double z = (t.cam_from_head * V.row(v).transpose()).z();
    const int x = std::clamp(static_cast<int>(std::lround(p.x())), 0, depth.cols - 1);
    const int y = std::clamp(static_cast<int>(std::lround(p.y())), 0, depth.rows - 1);
    const float d = depth.at<float>(y, x);
    t.vertex_visible[v] = d > 0 && z <= d + 2.5 + 0.005 * z;
  }
  const auto& lms = s.rig.landmarks;
  t.landmark_pixels.resize(static_cast<int>(lms.size()), 2);
  t.landmark_visible.resize(lms.size());
  for (size_t i = 0; i < lms.size(); ++i) {
    t.landmark_pixels.row(static_cast<int>(i)) = t.vertex_pixels.row(lms[i].vertex);
    t.landmark_visible[i] = t.vertex_visible[lms[i].vertex];
  }
  return out;
}

}  // namespace crease
