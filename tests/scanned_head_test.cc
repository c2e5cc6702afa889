#include "synth/scanned_head.h"

#include <gtest/gtest.h>

#include "core/image_io.h"
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
  RigImportOptions ro;
  ro.units_to_mm = 10.0;
  const FaceRig rig = ImportObjRig(fs::path(CREASE_DATA_DIR) / "sample_rig", ro);
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
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "head.gltf", dir / "albedo.png", "", so); }).find("glTF"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { LoadScannedHead(dir / "head.obj", dir / "missing.png", "", so); }).find("missing.png"),
            std::string::npos);
}

}  // namespace
}  // namespace crease
