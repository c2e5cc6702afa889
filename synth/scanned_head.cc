#include "synth/scanned_head.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <numbers>
#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <tiny_gltf.h>

#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "synth/hires_surface.h"
#include "synth/studio.h"
#include "synth/wrinkles.h"

namespace crease {

void ScannedHeadOptions::VisitFields(OptionVisitor& v) {
  v.Field("units_to_mm", units_to_mm);
  v.Field("v_up", v_up);
  v.Field("displacement_scale_mm", displacement_scale_mm);
  v.Field("displacement_midlevel", displacement_midlevel);
  v.Field("grid_resolution", grid_resolution);
  v.Field("phong_alpha", phong_alpha);
  v.Field("normal_map_space", normal_map_space);
  v.Field("normal_map_green_down", normal_map_green_down);
}

void ScannedHeadOptions::Check() const {
  const char* o = "ScannedHeadOptions";
  CheckGe(o, "units_to_mm", units_to_mm, 0.0);
  CheckGe(o, "grid_resolution", grid_resolution, 16);
  CheckLe(o, "grid_resolution", grid_resolution, 8192);
  CheckGe(o, "phong_alpha", phong_alpha, 0.0);
  CheckLe(o, "phong_alpha", phong_alpha, 1.0);
}

namespace {

// The UV grid the scan is resampled on, the way the studio builds its actors: the scan
// is a rig without blendshapes.
HiResLayout GridLayoutOf(const TriMesh& scan, const ScannedHeadOptions& options, int map_size,
                         const std::filesystem::path& mesh_path) {
  FaceRig as_rig;
  as_rig.neutral = scan;
  as_rig.neutral.N.resize(0, 3);
  HiResLayout layout = BuildHiResLayout(as_rig, options.grid_resolution, map_size);
  Require(layout.num_vertices() > 0, fmt::format("{}: no triangle of the UV layout lies inside [0,1]²", mesh_path.string()));
  return layout;
}

// Reads `count` elements of an accessor as doubles (`components` each).
std::vector<double> ReadAccessor(const tinygltf::Model& model, int index, int components, const std::string& what,
                                 const char* name) {
  Require(index >= 0 && index < static_cast<int>(model.accessors.size()),
          fmt::format("{}: {} refers to a missing accessor {}", what, name, index));
  const tinygltf::Accessor& acc = model.accessors[index];
  Require(tinygltf::GetNumComponentsInType(acc.type) == components,
          fmt::format("{}: {} must have {} components per element", what, name, components));
  Require(acc.bufferView >= 0 && acc.bufferView < static_cast<int>(model.bufferViews.size()),
          fmt::format("{}: {} has no buffer view (sparse accessors are not supported)", what, name));
  const tinygltf::BufferView& view = model.bufferViews[acc.bufferView];
  Require(view.buffer >= 0 && view.buffer < static_cast<int>(model.buffers.size()),
          fmt::format("{}: the buffer view of {} refers to a missing buffer {}", what, name, view.buffer));
  const tinygltf::Buffer& buffer = model.buffers[view.buffer];
  const int csize = tinygltf::GetComponentSizeInBytes(acc.componentType);
  Require(csize > 0, fmt::format("{}: {} has an unknown component type", what, name));
  const size_t element = static_cast<size_t>(csize) * components;
  const size_t stride = view.byteStride > 0 ? view.byteStride : element;
  // Bounds as "what is left", so that no offset or count can overflow them (a count near
  // 2^64 passed a wrapped-around check before: fuzz/gltf_fuzzer, issue 19).
  const size_t size = buffer.data.size();
  const auto past_end = [&] { return Error(fmt::format("{}: {} runs past the end of its buffer", what, name)); };
  if (view.byteOffset > size || acc.byteOffset > size - view.byteOffset) throw past_end();
  const size_t start = view.byteOffset + acc.byteOffset;
  if (acc.count > 0 && (element > size - start || (acc.count - 1) > (size - start - element) / stride)) throw past_end();
  std::vector<double> out(acc.count * components);
  for (size_t i = 0; i < acc.count; ++i) {
    const unsigned char* p = buffer.data.data() + start + i * stride;
    for (int c = 0; c < components; ++c) {
      const unsigned char* q = p + c * csize;
      double v = 0;
      switch (acc.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, q, 4); v = f; break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { uint32_t u; std::memcpy(&u, q, 4); v = u; break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t u; std::memcpy(&u, q, 2); v = acc.normalized ? u / 65535.0 : u; break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: { v = acc.normalized ? *q / 255.0 : *q; break; }
        default: throw Error(fmt::format("{}: {} has an unsupported component type {}", what, name, acc.componentType));
      }
      out[i * components + c] = v;
    }
  }
  return out;
}

}  // namespace

TriMesh ReadGltfMesh(const std::filesystem::path& path, cv::Mat* base_color, double units_to_mm) {
  RequireReadableFile(path);
  const std::string what = path.string();
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  const bool ok = LowerExtension(path) == ".glb" ? loader.LoadBinaryFromFile(&model, &err, &warn, what)
                                                  : loader.LoadASCIIFromFile(&model, &err, &warn, what);
  Require(ok, fmt::format("{}: cannot read glTF: {}", what, err.empty() ? warn : err));
  std::vector<Eigen::Vector3d> V;
  std::vector<Eigen::Vector2d> UV;
  std::vector<Eigen::Vector3i> F;
  int material = -1;
  // The mesh instances of the default scene (the first if none is marked) with their
  // nodes' world transforms; every mesh once, untransformed, if the file has no scene.
  std::vector<std::pair<int, Eigen::Affine3d>> instances;
  const auto local = [](const tinygltf::Node& n) {
    Eigen::Affine3d T = Eigen::Affine3d::Identity();
    if (n.matrix.size() == 16) {
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) T.matrix()(i, j) = n.matrix[4 * j + i];  // column-major
      return T;
    }
    if (n.translation.size() == 3) T.translate(Eigen::Vector3d(n.translation[0], n.translation[1], n.translation[2]));
    if (n.rotation.size() == 4) T.rotate(Eigen::Quaterniond(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]).normalized());
    if (n.scale.size() == 3) T.scale(Eigen::Vector3d(n.scale[0], n.scale[1], n.scale[2]));
    return T;
  };
  const std::function<void(int, const Eigen::Affine3d&, size_t)> visit = [&](int index, const Eigen::Affine3d& parent,
                                                                             size_t depth) {
    Require(index >= 0 && index < static_cast<int>(model.nodes.size()) && depth <= model.nodes.size(),
            fmt::format("{}: the scene refers to a missing node {} or its nodes form a cycle", what, index));
    const tinygltf::Node& node = model.nodes[index];
    const Eigen::Affine3d world = parent * local(node);
    if (node.mesh >= 0) {
      Require(node.mesh < static_cast<int>(model.meshes.size()), fmt::format("{}: node {} refers to a missing mesh", what, index));
      instances.emplace_back(node.mesh, world);
    }
    for (int child : node.children) visit(child, world, depth + 1);
  };
  if (!model.scenes.empty()) {
    const int scene = model.defaultScene >= 0 && model.defaultScene < static_cast<int>(model.scenes.size()) ? model.defaultScene : 0;
    for (int root : model.scenes[scene].nodes) visit(root, Eigen::Affine3d::Identity(), 0);
  } else {
    for (int m = 0; m < static_cast<int>(model.meshes.size()); ++m) instances.emplace_back(m, Eigen::Affine3d::Identity());
  }
  for (const auto& [mesh_index, transform] : instances) {
    const tinygltf::Mesh& mesh = model.meshes[mesh_index];
    for (const auto& prim : mesh.primitives) {
      if (prim.mode != TINYGLTF_MODE_TRIANGLES) continue;
      auto pos = prim.attributes.find("POSITION");
      auto tex = prim.attributes.find("TEXCOORD_0");
      Require(pos != prim.attributes.end(), fmt::format("{}: a primitive of mesh '{}' has no POSITION", what, mesh.name));
      Require(tex != prim.attributes.end(),
              fmt::format("{}: mesh '{}' has no texture coordinates (TEXCOORD_0); crease needs a UV layout", what, mesh.name));
      const std::vector<double> p = ReadAccessor(model, pos->second, 3, what, "POSITION");
      const std::vector<double> t = ReadAccessor(model, tex->second, 2, what, "TEXCOORD_0");
      Require(p.size() / 3 == t.size() / 2, fmt::format("{}: POSITION and TEXCOORD_0 differ in length", what));
      const int base = static_cast<int>(V.size());
      for (size_t i = 0; i < p.size() / 3; ++i) {
        V.emplace_back(units_to_mm * (transform * Eigen::Vector3d(p[3 * i], p[3 * i + 1], p[3 * i + 2])));
        UV.emplace_back(t[2 * i], t[2 * i + 1]);  // glTF's v already grows downwards
      }
      const int n = static_cast<int>(p.size() / 3);
      if (prim.indices >= 0) {
        const std::vector<double> idx = ReadAccessor(model, prim.indices, 1, what, "indices");
        Require(idx.size() % 3 == 0, fmt::format("{}: triangle indices are not a multiple of 3", what));
        for (double k : idx) {
          Require(k < n, fmt::format("{}: mesh '{}' has a triangle index {} beyond its {} vertices", what, mesh.name, k, n));
        }
        for (size_t i = 0; i < idx.size(); i += 3) {
          F.emplace_back(base + static_cast<int>(idx[i]), base + static_cast<int>(idx[i + 1]), base + static_cast<int>(idx[i + 2]));
        }
      } else {
        for (int i = 0; i + 2 < n; i += 3) F.emplace_back(base + i, base + i + 1, base + i + 2);
      }
      if (material < 0) material = prim.material;
    }
  }
  Require(!F.empty(), fmt::format("{}: the file has no triangle primitives", what));
  TriMesh m;
  m.V.resize(static_cast<int>(V.size()), 3);
  m.UV.resize(static_cast<int>(UV.size()), 2);
  m.F.resize(static_cast<int>(F.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) {
    m.V.row(static_cast<int>(i)) = V[i].transpose();
    m.UV.row(static_cast<int>(i)) = UV[i].transpose();
  }
  for (size_t f = 0; f < F.size(); ++f) m.F.row(static_cast<int>(f)) = F[f].transpose();
  ValidateMesh(m, what, {.uv = true});
  if (base_color) {
    *base_color = cv::Mat();
    if (material >= 0 && material < static_cast<int>(model.materials.size())) {
      const int tex_index = model.materials[material].pbrMetallicRoughness.baseColorTexture.index;
      if (tex_index >= 0 && tex_index < static_cast<int>(model.textures.size())) {
        const int source = model.textures[tex_index].source;
        Require(source >= 0 && source < static_cast<int>(model.images.size()),
                fmt::format("{}: the base colour texture has no image", what));
        const tinygltf::Image& img = model.images[source];
        Require(img.bits == 8 && (img.component == 3 || img.component == 4) && img.width > 0 && img.height > 0 &&
                    img.image.size() == static_cast<size_t>(img.width) * img.height * img.component,
                fmt::format("{}: the base colour image must be 8-bit RGB(A)", what));
        cv::Mat rgba(img.height, img.width, CV_8UC(img.component), const_cast<unsigned char*>(img.image.data()));
        cv::Mat rgb;
        if (img.component == 4) {
          cv::cvtColor(rgba, rgb, cv::COLOR_RGBA2RGB);
        } else {
          rgb = rgba.clone();
        }
        rgb.convertTo(*base_color, CV_32FC3, 1.0 / 255.0);
        // sRGB-encoded like every 8-bit colour image: decode to linear.
        base_color->forEach<cv::Vec3f>([](cv::Vec3f& px, const int*) {
          for (int k = 0; k < 3; ++k) px[k] = SrgbToLinear(px[k]);
        });
      }
    }
  }
  return m;
}

MatX3d NormalsFromNormalMap(const TriMesh& mesh, const cv::Mat& normal_map, const ScannedHeadOptions& options) {
  Require(normal_map.type() == CV_32FC3, "NormalsFromNormalMap: the normal map must be CV_32FC3");
  Require(mesh.has_uv(), "NormalsFromNormalMap: the mesh has no UV coordinates");
  const MatX3d N = mesh.N.rows() == mesh.num_vertices() ? mesh.N : VertexNormals(mesh);
  const int nv = mesh.num_vertices();
  // Per-vertex ∂p/∂u and ∂p/∂v (v downwards), area-weighted over the adjacent faces.
  MatX3d Tu = MatX3d::Zero(nv, 3), Tv = MatX3d::Zero(nv, 3);
  if (options.normal_map_space == NormalMapSpace::kTangent) {
    for (int f = 0; f < mesh.num_faces(); ++f) {
      const int a = mesh.F(f, 0), b = mesh.F(f, 1), c = mesh.F(f, 2);
      const Eigen::Vector3d e1 = (mesh.V.row(b) - mesh.V.row(a)).transpose(), e2 = (mesh.V.row(c) - mesh.V.row(a)).transpose();
      const double du1 = mesh.UV(b, 0) - mesh.UV(a, 0), dv1 = mesh.UV(b, 1) - mesh.UV(a, 1);
      const double du2 = mesh.UV(c, 0) - mesh.UV(a, 0), dv2 = mesh.UV(c, 1) - mesh.UV(a, 1);
      const double det = du1 * dv2 - du2 * dv1;
      if (std::abs(det) < 1e-14) continue;
      // e = ∂p/∂u · du + ∂p/∂v · dv for both edges, solved for the two derivatives;
      // weighted by the face's UV area (|det| / 2) so large faces count more.
      const Eigen::Vector3d pu = (e1 * dv2 - e2 * dv1) / det, pv = (e2 * du1 - e1 * du2) / det;
      const double w = 0.5 * std::abs(det);
      for (int k : {a, b, c}) {
        Tu.row(k) += w * pu.transpose();
        Tv.row(k) += w * pv.transpose();
      }
    }
  }
  MatX3d out(nv, 3);
  for (int i = 0; i < nv; ++i) {
    // Bilinear at the UV (DESIGN.md texel convention), decoded n = 2·value − 1.
    const Eigen::Vector3d m = 2.0 * SampleMetric(normal_map, mesh.UV(i, 0), mesh.UV(i, 1)) - Eigen::Vector3d::Ones();
    const Eigen::Vector3d n = N.row(i).transpose();
    Eigen::Vector3d s;
    if (options.normal_map_space == NormalMapSpace::kObject) {
      s = m;
    } else {
      Eigen::Vector3d t = Tu.row(i).transpose();
      t -= n.dot(t) * n;
      // OpenGL maps: green along +v of the file, which is −v here (v downwards).
      Eigen::Vector3d up = options.normal_map_green_down ? Eigen::Vector3d(Tv.row(i).transpose())
                                                        : Eigen::Vector3d(-Tv.row(i).transpose());
      if (t.norm() < 1e-12) {  // no UV derivative here: keep the geometric normal
        out.row(i) = n.transpose();
        continue;
      }
      t.normalize();
      Eigen::Vector3d b = n.cross(t);
      if (b.dot(up) < 0) b = -b;  // mirrored UVs
      s = m.x() * t + m.y() * b + m.z() * n;
    }
    out.row(i) = (s.norm() > 1e-12 ? s.normalized() : n).transpose();
  }
  return out;
}

std::string HeadSizeWarning(const TriMesh& mesh, const std::string& what) {
  if (mesh.num_vertices() == 0) return "";
  const auto [lo, hi] = BoundingBox(mesh);
  const double extent = (hi - lo).maxCoeff();
  if (extent >= 120.0 && extent <= 600.0) return "";
  return fmt::format("{}: the head is {:.4g} mm across, not a person's 120-600 mm; are the units right "
                     "(--units mm|cm|m)?", what, extent);
}

ScannedHead LoadScannedHead(const std::filesystem::path& mesh_path, const std::filesystem::path& albedo_path,
                            const std::filesystem::path& displacement_path, const ScannedHeadOptions& options,
                            const std::filesystem::path& normal_path) {
  options.Check();
  const std::string ext = LowerExtension(mesh_path);
  Require(ext == ".obj" || ext == ".ply" || ext == ".gltf" || ext == ".glb",
          fmt::format("{}: scanned heads are read from OBJ, PLY or glTF (.gltf, .glb)", mesh_path.string()));
  const bool gltf = ext == ".gltf" || ext == ".glb";
  cv::Mat embedded_albedo;
  const double units_to_mm = options.units_to_mm > 0 ? options.units_to_mm : gltf ? 1000.0 : 1.0;
  TriMesh scan = gltf ? ReadGltfMesh(mesh_path, &embedded_albedo, units_to_mm) : ReadMesh(mesh_path);
  ValidateMesh(scan, mesh_path.string(), {.uv = true});
  if (!gltf) scan.V *= units_to_mm;
  const bool v_up = options.v_up == TextureVUp::kYes || (options.v_up == TextureVUp::kAuto && !gltf);
  if (v_up) scan.UV.col(1) = (1.0 - scan.UV.col(1).array()).matrix();
  scan.N = VertexNormals(scan);

  ScannedHead head;
  if (std::string w = HeadSizeWarning(scan, mesh_path.string()); !w.empty()) head.warnings.push_back(std::move(w));
  head.source_vertices = scan.num_vertices();
  Require(!albedo_path.empty() || !embedded_albedo.empty(),
          fmt::format("{}: no albedo texture (give one; only glTF files can carry their own)", mesh_path.string()));
  cv::Mat albedo = albedo_path.empty() ? embedded_albedo : ReadImage(albedo_path);
  Require(albedo.channels() == 3 || albedo.channels() == 4 || albedo.channels() == 1,
          fmt::format("{}: the albedo texture must be grey, RGB or RGBA", albedo_path.string()));
  if (albedo.channels() == 4) cv::cvtColor(albedo, albedo, cv::COLOR_RGBA2RGB);
  if (albedo.channels() == 1) cv::cvtColor(albedo, albedo, cv::COLOR_GRAY2RGB);
  cv::min(albedo, 1.0, albedo);
  cv::max(albedo, 0.0, albedo);
  head.materials.albedo = albedo;
  head.materials.specular = cv::Mat(albedo.size(), CV_32FC1, cv::Scalar(MaterialPreset("skin").specular));
  head.materials.roughness = cv::Mat(albedo.size(), CV_32FC1, cv::Scalar(MaterialPreset("skin").roughness));
  head.materials.face = MaterialPreset("skin");
  head.materials.face.textured = true;

  cv::Mat normal_map;
  if (!normal_path.empty()) {
    normal_map = ReadImage(normal_path, /*srgb=*/false);
    Require(normal_map.channels() == 3 || normal_map.channels() == 4,
            fmt::format("{}: a normal map must have three channels (RGB), not {}", normal_path.string(),
                        normal_map.channels()));
    if (normal_map.channels() == 4) cv::cvtColor(normal_map, normal_map, cv::COLOR_RGBA2RGB);
    Require(cv::checkRange(normal_map),
            fmt::format("{}: the normal map holds NaN or infinite values", normal_path.string()));
  }
  if (displacement_path.empty() && normal_map.empty()) {
    head.surface = scan;
    return head;
  }
  if (displacement_path.empty()) {  // a normal map alone: resample on the grid, flat
    head.surface = BuildHiResSurface(GridLayoutOf(scan, options, options.grid_resolution, mesh_path), scan,
                                     cv::Mat::zeros(options.grid_resolution, options.grid_resolution, CV_32F),
                                     options.phong_alpha);
    head.surface.N = NormalsFromNormalMap(head.surface, normal_map, options);
    return head;
  }
  cv::Mat disp = ReadImage(displacement_path, /*srgb=*/false);
  Require(disp.channels() == 1 || disp.channels() == 3,
          fmt::format("{}: a displacement map must have one channel (or three equal ones)", displacement_path.string()));
  if (disp.channels() == 3) cv::extractChannel(disp, disp, 0);
  Require(disp.rows == disp.cols,
          fmt::format("{}: displacement maps must be square ({}x{})", displacement_path.string(), disp.cols, disp.rows));
  Require(cv::checkRange(disp), fmt::format("{}: the displacement map holds NaN or infinite values", displacement_path.string()));
  disp = (disp - options.displacement_midlevel) * options.displacement_scale_mm;
  head.surface = BuildHiResSurface(GridLayoutOf(scan, options, disp.rows, mesh_path), scan, disp, options.phong_alpha);
  if (!normal_map.empty()) head.surface.N = NormalsFromNormalMap(head.surface, normal_map, options);
  return head;
}

TriMesh TurnedHead(const ScannedHead& head, double yaw_deg) {
  TriMesh m = head.surface;
  const auto [lo, hi] = BoundingBox(m);
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  const double r = yaw_deg * std::numbers::pi / 180.0;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(r, Eigen::Vector3d::UnitY()).toRotationMatrix();
  for (int v = 0; v < m.num_vertices(); ++v) m.V.row(v) = (R * (m.V.row(v).transpose() - centre) + centre).transpose();
  if (m.N.rows() == m.num_vertices()) m.N = m.N * R.transpose();  // the normal map's shading normals turn too
  return m;
}

Camera FramingCamera(const TriMesh& m, double fov_deg, int width, int height) {
  const auto [lo, hi] = BoundingBox(m);
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  const double radius = 0.5 * (hi - lo).norm();
  const CameraIntrinsics K = CameraIntrinsics::FromFov(fov_deg, width, height);
  const double distance =
      radius / std::sin(0.5 * std::min(fov_deg, fov_deg * height / width) * std::numbers::pi / 180.0);
  return LookAtCamera(K, centre + Eigen::Vector3d(0, 0, distance), centre, Eigen::Vector3d::UnitY());
}

ScanRender RenderScannedHead(const ScannedHead& head, const ScanRenderOptions& o, const std::string& name) {
  const TriMesh m = TurnedHead(head, o.yaw_deg);
  const Camera camera = FramingCamera(head.surface, o.fov_deg, o.width, o.height);  // the head before turning
  Renderer renderer(m, head.materials, RendererOptions{}, name);
  RenderOptions ro;
  ro.samples_per_axis = o.samples_per_axis;
  Rng rng(o.seed);
  ScanRender out;
  out.render = renderer.Render(camera, LightRigFromSpec(o.light), ro, rng);
  out.image = ApplySensor(out.render.image, o.sensor, rng);
  out.rendered_vertices = m.num_vertices();
  return out;
}

}  // namespace crease
