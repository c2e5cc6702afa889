#include "synth/scanned_head.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <numbers>
#include <tiny_gltf.h>

#include "core/image_io.h"
#include "core/mesh_primitives.h"
#include "core/mesh_io.h"
#include "core/rig_import.h"
#include "synth/actor.h"
#include "tests/test_util.h"

namespace crease {
namespace {
namespace fs = std::filesystem;
using testing::ErrorOf;
using testing::TestDir;

// Importing one of the studio's own actors as a "scan" (its coarse neutral as OBJ,
// its skin as PNG, its static + pore displacement as EXR) rebuilds the actor's own
// high-resolution neutral surface.
TEST(ScannedHead, ReproducesTheStudiosOwnActorSurface) {
  const fs::path dir = TestDir();
  const FaceRig& rig = testing::SampleRig();
  ActorOptions ao;
  ao.resolution = 256;
  ao.surface_min_vertices = 0;
  const Actor actor = GenerateActor(rig, 11, ao);
  const ActorModel model(rig, actor);
  const ActorFrame f = model.Frame(Eigen::VectorXd::Zero(rig.num_expressions()), true);
  TriMesh scan = f.coarse;
  scan.N.resize(0, 3);
  scan.UV.col(1) = (1.0 - scan.UV.col(1).array()).matrix();  // OBJ convention: v up
  WriteObj(dir / "head.obj", scan);
  WriteImage(dir / "albedo.png", model.skin().albedo);
  WriteImage(dir / "displacement.exr", cv::Mat(f.static_displacement + f.mesoscopic_displacement + f.expression_displacement));

  ScannedHeadOptions so;
  so.grid_resolution = 256;
  so.phong_alpha = actor.options.phong_alpha;
  const ScannedHead head = LoadScannedHead(dir / "head.obj", dir / "albedo.png", dir / "displacement.exr", so);
  ASSERT_EQ(head.surface.num_vertices(), f.hires.num_vertices());
  EXPECT_LT((head.surface.V - f.hires.V).cwiseAbs().maxCoeff(), 1e-3);  // µm
  EXPECT_EQ(head.materials.albedo.size(), model.skin().albedo.size());

  // Without a displacement map the scan is the mesh itself.
  const ScannedHead plain = LoadScannedHead(dir / "head.obj", dir / "albedo.png", "", so);
  EXPECT_EQ(plain.surface.num_vertices(), scan.num_vertices());

  // Errors name the file.
  TriMesh no_uv = scan;
  no_uv.UV.resize(0, 2);
  WritePly(dir / "no_uv.ply", no_uv);
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "no_uv.ply", dir / "albedo.png", "", so); }).find("no UV coordinates"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "head.fbx", dir / "albedo.png", "", so); }).find("OBJ, PLY or glTF"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "head.obj", dir / "missing.png", "", so); }).find("missing.png"),
            std::string::npos);
}

// A normal map sets the shading normals: on a plane (UV = (x, y) / 100 mm, normal +z)
// a constant tangent-space normal tilted 30° towards +u (red) tilts every normal towards
// +x; towards the file's +v (green, OpenGL) towards −y here (v grows downwards in
// crease), +y for a DirectX map; an object-space map is taken as it is.
TEST(ScannedHead, NormalMapSetsTheShadingNormals) {
  const fs::path dir = TestDir();
  TriMesh plane = MakeGrid(4, 4, 100.0, 100.0);
  plane.N.resize(0, 3);
  TriMesh file = plane;
  file.UV.col(1) = (1.0 - file.UV.col(1).array()).matrix();  // OBJ: v up
  WriteObj(dir / "plane.obj", file);
  WriteImage(dir / "albedo.png", cv::Mat(8, 8, CV_32FC3, cv::Scalar(0.5, 0.4, 0.3)));
  const double s = std::sin(30.0 * std::numbers::pi / 180.0), c = std::cos(30.0 * std::numbers::pi / 180.0);
  auto write_map = [&](const std::string& name, double x, double y, double z) {
    WriteImage(dir / name, cv::Mat(16, 16, CV_32FC3, cv::Scalar(0.5 * (x + 1), 0.5 * (y + 1), 0.5 * (z + 1))));
  };
  write_map("red.exr", s, 0, c);
  write_map("green.exr", 0, s, c);
  write_map("flat.exr", 0, 0, 1);
  write_map("object.exr", 0, -1, 0);
  ScannedHeadOptions so;
  so.grid_resolution = 32;
  auto normals = [&](const std::string& map, const ScannedHeadOptions& o) {
    const ScannedHead h = LoadScannedHead(dir / "plane.obj", dir / "albedo.png", "", o, dir / map);
    EXPECT_GT(h.surface.num_vertices(), 500);  // resampled on the 32² grid
    EXPECT_EQ(h.surface.N.rows(), h.surface.num_vertices());
    return h.surface.N;
  };
  auto expect_all = [](const MatX3d& N, const Eigen::Vector3d& want, const char* what) {
    EXPECT_LT((N.rowwise() - want.transpose()).rowwise().norm().maxCoeff(), 1e-6) << what;
  };
  expect_all(normals("flat.exr", so), {0, 0, 1}, "flat");
  expect_all(normals("red.exr", so), {s, 0, c}, "red");
  expect_all(normals("green.exr", so), {0, -s, c}, "green, OpenGL");
  ScannedHeadOptions dx = so;
  dx.normal_map_green_down = true;
  expect_all(normals("green.exr", dx), {0, s, c}, "green, DirectX");
  ScannedHeadOptions object = so;
  object.normal_map_space = NormalMapSpace::kObject;
  expect_all(normals("object.exr", object), {0, -1, 0}, "object space");

  // Errors name the file.
  WriteImage(dir / "gray.exr", cv::Mat(16, 16, CV_32FC1, cv::Scalar(0.5)));
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "plane.obj", dir / "albedo.png", "", so, dir / "gray.exr"); })
                .find("gray.exr: a normal map must have three channels"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "plane.obj", dir / "albedo.png", "", so, dir / "none.exr"); })
                .find("none.exr"),
            std::string::npos);
}

// A glTF 2.0 file (metres, embedded buffer and base colour image) reads as mm with its texture.
TEST(ScannedHead, ReadsGltfWithItsBaseColourTexture) {
  const fs::path dir = TestDir();
  const TriMesh grid = MakeGrid(3, 3, 0.3, 0.3);  // metres
  tinygltf::Model model;
  std::vector<unsigned char> bytes;
  auto append = [&](const void* data, size_t n) {
    const size_t off = bytes.size();
    bytes.resize(off + n);
    std::memcpy(bytes.data() + off, data, n);
    return off;
  };
  std::vector<float> pos, uv;
  for (int v = 0; v < grid.num_vertices(); ++v) {
    for (int k = 0; k < 3; ++k) pos.push_back(static_cast<float>(grid.V(v, k)));
    for (int k = 0; k < 2; ++k) uv.push_back(static_cast<float>(grid.UV(v, k)));
  }
  std::vector<uint32_t> idx(grid.F.data(), grid.F.data() + grid.F.size());
  const size_t o_pos = append(pos.data(), pos.size() * 4), o_uv = append(uv.data(), uv.size() * 4),
               o_idx = append(idx.data(), idx.size() * 4);
  model.buffers.push_back({});
  model.buffers[0].data = bytes;
  auto view = [&](size_t off, size_t len) {
    tinygltf::BufferView v;
    v.buffer = 0;
    v.byteOffset = off;
    v.byteLength = len;
    model.bufferViews.push_back(v);
    return static_cast<int>(model.bufferViews.size()) - 1;
  };
  auto accessor = [&](int view_index, int type, int component, size_t count, std::vector<double> mn = {},
                      std::vector<double> mx = {}) {
    tinygltf::Accessor a;
    a.bufferView = view_index;
    a.componentType = component;
    a.type = type;
    a.count = count;
    a.minValues = mn;
    a.maxValues = mx;
    model.accessors.push_back(a);
    return static_cast<int>(model.accessors.size()) - 1;
  };
  const int a_pos = accessor(view(o_pos, pos.size() * 4), TINYGLTF_TYPE_VEC3, TINYGLTF_COMPONENT_TYPE_FLOAT,
                             grid.num_vertices(), {0, 0, 0}, {0.3, 0.3, 0});
  const int a_uv = accessor(view(o_uv, uv.size() * 4), TINYGLTF_TYPE_VEC2, TINYGLTF_COMPONENT_TYPE_FLOAT, grid.num_vertices());
  const int a_idx = accessor(view(o_idx, idx.size() * 4), TINYGLTF_TYPE_SCALAR, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, idx.size());
  tinygltf::Image image;
  image.width = image.height = 4;
  image.component = 4;
  image.bits = 8;
  image.pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
  image.mimeType = "image/png";
  image.image.assign(4 * 4 * 4, 0);
  for (int i = 0; i < 16; ++i) {
    image.image[4 * i] = 255;      // red
    image.image[4 * i + 3] = 255;  // opaque
  }
  model.images.push_back(image);
  tinygltf::Texture texture;
  texture.source = 0;
  model.textures.push_back(texture);
  tinygltf::Material material;
  material.pbrMetallicRoughness.baseColorTexture.index = 0;
  model.materials.push_back(material);
  tinygltf::Primitive prim;
  prim.attributes["POSITION"] = a_pos;
  prim.attributes["TEXCOORD_0"] = a_uv;
  prim.indices = a_idx;
  prim.material = 0;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  tinygltf::Mesh mesh;
  mesh.primitives.push_back(prim);
  model.meshes.push_back(mesh);
  tinygltf::Node node;
  node.mesh = 0;
  model.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  model.defaultScene = 0;
  model.asset.version = "2.0";
  tinygltf::TinyGLTF writer;
  ASSERT_TRUE(writer.WriteGltfSceneToFile(&model, (dir / "head.gltf").string(), true, true, true, false));

  const ScannedHead head = LoadScannedHead(dir / "head.gltf", "", "", ScannedHeadOptions{});
  ASSERT_EQ(head.surface.num_vertices(), grid.num_vertices());
  EXPECT_LT((head.surface.V - grid.V * 1000.0).cwiseAbs().maxCoeff(), 1e-3);  // metres → mm (float precision)
  EXPECT_LT((head.surface.UV - grid.UV).cwiseAbs().maxCoeff(), 1e-6);        // no v flip for glTF
  EXPECT_TRUE(head.warnings.empty());                                         // 300 mm: a head's size
  // A three.js-style asset: the same file in centimetres with v up, as the user says.
  ScannedHeadOptions cm;
  cm.units_to_mm = 10.0;
  cm.v_up = TextureVUp::kYes;
  const ScannedHead small = LoadScannedHead(dir / "head.gltf", "", "", cm);
  EXPECT_LT((small.surface.V - grid.V * 10.0).cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_LT((small.surface.UV.col(1) - (1.0 - grid.UV.col(1).array()).matrix()).cwiseAbs().maxCoeff(), 1e-6);
  // 3 mm across: not a person's head, and the warning says to check the units.
  ASSERT_EQ(small.warnings.size(), 1u);
  EXPECT_NE(small.warnings[0].find("the head is 3 mm across"), std::string::npos) << small.warnings[0];
  EXPECT_NE(small.warnings[0].find("--units"), std::string::npos);
  ASSERT_EQ(head.materials.albedo.rows, 4);
  const cv::Vec3f red = head.materials.albedo.at<cv::Vec3f>(1, 1);
  EXPECT_NEAR(red[0], 1.0f, 1e-6);
  EXPECT_NEAR(red[1], 0.0f, 1e-6);
  // Node transforms place the mesh: a child node (scale 2, then +0.1 m in x) under a
  // parent turned 90° about z.
  tinygltf::Node parent;
  parent.rotation = {0, 0, std::sin(std::numbers::pi / 4), std::cos(std::numbers::pi / 4)};  // x, y, z, w
  parent.children = {0};
  model.nodes[0].translation = {0.1, 0, 0};
  model.nodes[0].scale = {2, 2, 2};
  model.nodes.push_back(parent);
  model.scenes[0].nodes = {1};
  ASSERT_TRUE(writer.WriteGltfSceneToFile(&model, (dir / "placed.gltf").string(), true, true, true, false));
  const ScannedHead placed = LoadScannedHead(dir / "placed.gltf", "", "", ScannedHeadOptions{});
  ASSERT_EQ(placed.surface.num_vertices(), grid.num_vertices());
  for (int v = 0; v < grid.num_vertices(); ++v) {
    const Eigen::Vector3d q = 2.0 * grid.V.row(v).transpose() + Eigen::Vector3d(0.1, 0, 0);
    const Eigen::Vector3d want = 1000.0 * Eigen::Vector3d(-q.y(), q.x(), q.z());  // 90° about z
    EXPECT_LT((placed.surface.V.row(v).transpose() - want).norm(), 1e-3) << v;
  }
  model.nodes[0].scale.clear();
  model.nodes[0].translation.clear();
  model.nodes.pop_back();
  model.scenes[0].nodes = {0};
  // A glTF without texture coordinates is refused by name.
  model.meshes[0].primitives[0].attributes.erase("TEXCOORD_0");
  ASSERT_TRUE(writer.WriteGltfSceneToFile(&model, (dir / "no_uv.gltf").string(), true, true, true, false));
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "no_uv.gltf", "", "", ScannedHeadOptions{}); }).find("TEXCOORD_0"),
            std::string::npos);
}

// Issue 19 (fuzz/gltf_fuzzer): sizes and indices in a glTF that lie are clear errors
// naming the file. A buffer view naming a missing buffer was std::out_of_range (an
// internal error), an accessor count near 2^64 wrapped the bounds check around, and an
// index beyond the vertices reached the mesh as an int conversion of any double.
TEST(ScannedHead, GltfWithLyingSizesIsAClearError) {
  const fs::path dir = TestDir();
  // One triangle: 3 positions (float VEC3), 3 UVs (float VEC2), 3 uint16 indices.
  const std::string triangle = "AAAAAAAAAAAAAAAACtcjPAAAAAAAAAAAAAAAAArXIzwAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAIA/AAABAAIAAAA=";
  const std::string index_7 = "AAAAAAAAAAAAAAAACtcjPAAAAAAAAAAAAAAAAArXIzwAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAIA/AAABAAcAAAA=";
  auto gltf = [&](const std::string& name, const std::string& data, int position_buffer, const std::string& position_count) {
    const fs::path path = dir / name;
    std::ofstream(path) << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2}]}],
      "buffers": [{"byteLength": 68, "uri": "data:application/octet-stream;base64,)" << data << R"("}],
      "bufferViews": [{"buffer": )" << position_buffer << R"(, "byteOffset": 0, "byteLength": 36},
                      {"buffer": 0, "byteOffset": 36, "byteLength": 24}, {"buffer": 0, "byteOffset": 60, "byteLength": 6}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": )" << position_count << R"(, "type": "VEC3"},
                    {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"},
                    {"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}]})";
    return path;
  };
  EXPECT_EQ(ReadGltfMesh(gltf("ok.gltf", triangle, 0, "3")).num_faces(), 1);
  const fs::path missing = gltf("missing_buffer.gltf", triangle, 5, "3");
  EXPECT_NE(ErrorOf([&] { ReadGltfMesh(missing); }).find(missing.string() + ": the buffer view of POSITION refers to a missing buffer 5"),
            std::string::npos);
  const fs::path huge = gltf("huge_count.gltf", triangle, 0, "4611686018427387904");
  EXPECT_NE(ErrorOf([&] { ReadGltfMesh(huge); }).find(huge.string() + ": POSITION runs past the end of its buffer"),
            std::string::npos);
  const fs::path beyond = gltf("index_7.gltf", index_7, 0, "3");
  EXPECT_NE(ErrorOf([&] { ReadGltfMesh(beyond); }).find(beyond.string() + ": mesh '' has a triangle index 7 beyond its 3 vertices"),
            std::string::npos);
}

// A sphere of radius 50 mm centred off the origin, with outward shading normals.
ScannedHead SphereHead() {
  ScannedHead head;
  head.surface = MakeUVSphere(50.0, 12, 16);
  head.surface.N = head.surface.V.rowwise().normalized();
  head.surface.V.rowwise() += Eigen::RowVector3d(10.0, -20.0, 30.0);
  return head;
}

// TurnedHead turns about +y through the bounding box's centre: 0° changes nothing,
// 90° keeps heights and distances from the centre, sends +x to −z, and turns the
// shading normals with the surface.
TEST(ScannedHead, TurnedHeadTurnsAboutTheBoxCentre) {
  const ScannedHead head = SphereHead();
  EXPECT_EQ(TurnedHead(head, 0.0).V, head.surface.V);
  const TriMesh t = TurnedHead(head, 90.0);
  const Eigen::RowVector3d centre(10.0, -20.0, 30.0);
  ASSERT_EQ(t.num_vertices(), head.surface.num_vertices());
  int east = 0;
  for (int v = 0; v < t.num_vertices(); ++v) {
    const Eigen::RowVector3d before = head.surface.V.row(v) - centre, after = t.V.row(v) - centre;
    EXPECT_NEAR(after.y(), before.y(), 1e-9);
    EXPECT_NEAR(after.norm(), before.norm(), 1e-9);
    EXPECT_NEAR(after.z(), -before.x(), 1e-9);
    EXPECT_NEAR(after.x(), before.z(), 1e-9);
    EXPECT_LT((t.N.row(v) - after / after.norm()).norm(), 1e-9);  // normals turned alike
    east += before.x() > 49.0;
  }
  EXPECT_GT(east, 0);
}

// FramingCamera looks at the box centre from +z: the centre projects to the principal
// point, every vertex lands in the image, and the box's bounding sphere just fits the
// narrower (vertical, for 4:3) field of view.
TEST(ScannedHead, FramingCameraFramesTheBoundingSphere) {
  const ScannedHead head = SphereHead();
  const int width = 160, height = 120;
  const Camera camera = FramingCamera(head.surface, 40.0, width, height);
  const auto [lo, hi] = BoundingBox(head.surface);
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  const double radius = 0.5 * (hi - lo).norm();
  const Eigen::Vector2d c = camera.Project(centre);
  EXPECT_NEAR(c.x(), camera.intrinsics.cx, 1e-6);
  EXPECT_NEAR(c.y(), camera.intrinsics.cy, 1e-6);
  const Eigen::Vector3d eye = camera.CentreInHead() - centre;
  EXPECT_NEAR(eye.x(), 0.0, 1e-9);
  EXPECT_NEAR(eye.y(), 0.0, 1e-9);
  EXPECT_GT(eye.z(), radius);
  for (int v = 0; v < head.surface.num_vertices(); ++v) {
    EXPECT_TRUE(camera.InImage(camera.Project(head.surface.V.row(v).transpose()))) << v;
  }
  // The tangent ray to the bounding sphere makes (nearly) half the vertical field of view.
  const double half_vertical = std::atan(0.5 * height / camera.intrinsics.fy);
  EXPECT_LE(std::asin(radius / eye.z()), half_vertical);
  EXPECT_GT(std::asin(radius / eye.z()), half_vertical - 1e-2);
}

}  // namespace
}  // namespace crease
