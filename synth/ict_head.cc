#include "synth/ict_head.h"

#include <cstdlib>
#include <fmt/format.h>

#include "core/error.h"
#include "synth/skin.h"

namespace crease {
namespace fs = std::filesystem;

void IctHeadOptions::VisitFields(OptionVisitor& v) {
  v.Field("identity_modes", identity_modes);
  v.Field("eyelashes", eyelashes);
  v.Field("iris_radius_mm", iris_radius_mm);
  v.Field("pupil_radius_mm", pupil_radius_mm);
  v.Field("cornea_radius_mm", cornea_radius_mm);
}

void IctHeadOptions::Check() const {
  CheckGe("IctHeadOptions", "identity_modes", identity_modes, 0);
  CheckGt("IctHeadOptions", "pupil_radius_mm", pupil_radius_mm, 0.0);
  CheckGt("IctHeadOptions", "iris_radius_mm", iris_radius_mm, pupil_radius_mm);
  CheckGe("IctHeadOptions", "cornea_radius_mm", cornea_radius_mm, 0.0);
}

fs::path VendoredIctRigPath() {
  if (const char* dir = std::getenv("CREASE_DATA"); dir && *dir) return fs::path(dir) / "ict" / "ict_face_light.crig";
  return fs::path(CREASE_SOURCE_DATA_DIR) / "ict" / "ict_face_light.crig";
}

namespace {

int RequirePart(const FaceRig& rig, const std::string& name) {
  const int p = rig.PartIndex(name);
  Require(p >= 0, fmt::format("{}: the rig has no part '{}' (expected an ICT-FaceKit import, "
                              "scripts/vendor_ict.sh)", rig.source, name));
  return p;
}

// Moves vertex v to part `to`, onto that part's own UV tile (u in [2 + p, 3 + p),
// as core/rig_import.h lays out the non-face parts).
void MoveToPart(FaceRig* rig, int v, int to) {
  rig->neutral.UV(v, 0) += to - rig->vertex_part[v];
  rig->vertex_part[v] = static_cast<uint8_t>(to);
}

// The eye of one side, as the model builds it: a sclera sphere that also covers
// the cornea (a game engine makes that cap transparent), and an "iris" mesh
// inside it whose front is the iris disc and whose back lines the eyeball.
// Dressed for an opaque renderer: the sclera's cap in front of the iris is
// removed, the iris mesh's front within the iris radius is the iris (within the
// pupil radius the pupil), the rest of it is sclera. The gaze axis runs from the
// sclera's centre to its frontmost (+z) vertex.
void DressEye(FaceRig* rig, const std::string& side, const IctHeadOptions& options, std::vector<uint8_t>* drop) {
  const int iris = RequirePart(*rig, "iris_" + side);
  const int ball = RequirePart(*rig, "eyeball_" + side);
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  int n = 0, front = -1;
  for (int v = 0; v < rig->num_vertices(); ++v) {
    if (rig->vertex_part[v] != ball) continue;
    centre += rig->neutral.V.row(v).transpose();
    ++n;
    if (front < 0 || rig->neutral.V(v, 2) > rig->neutral.V(front, 2)) front = v;
  }
  Require(n > 0, fmt::format("{}: the part eyeball_{} is empty", rig->source, side));
  centre /= n;
  const Eigen::Vector3d axis = (rig->neutral.V.row(front).transpose() - centre).normalized();
  auto axis_distance = [&](int v) {
    const Eigen::Vector3d d = rig->neutral.V.row(v).transpose() - centre;
    return (d - d.dot(axis) * axis).norm();
  };
  auto in_front = [&](int v) { return (rig->neutral.V.row(v).transpose() - centre).dot(axis) > 0.0; };
  const int pupil = static_cast<int>(rig->part_names.size());
  rig->part_names.push_back("pupil_" + side);
  for (int v = 0; v < rig->num_vertices(); ++v) {
    const int part = rig->vertex_part[v];
    if (part == ball && in_front(v) && axis_distance(v) < options.cornea_radius_mm) (*drop)[v] = 1;
    if (part != iris) continue;
    int to = ball;
    if (in_front(v) && axis_distance(v) < options.iris_radius_mm) {
      to = axis_distance(v) < options.pupil_radius_mm ? pupil : iris;
    }
    MoveToPart(rig, v, to);
  }
}

// Removes the triangles with a corner flagged in `drop` (the vertices stay, unused).
void DropTriangles(FaceRig* rig, const std::vector<uint8_t>& drop) {
  MatX3i F(rig->neutral.F.rows(), 3);
  Eigen::Index n = 0;
  for (Eigen::Index f = 0; f < rig->neutral.F.rows(); ++f) {
    const auto t = rig->neutral.F.row(f);
    if (!drop[t[0]] && !drop[t[1]] && !drop[t[2]]) F.row(n++) = t;
  }
  rig->neutral.F = F.topRows(n);
}

// The head-and-neck part's vertices above the scalp hairline (synth/skin.h) form
// the part "scalp_hair"; the face chart's share of the scalp is painted by the actor's
// skin maps with the same hairline.
void HairOnTheScalp(FaceRig* rig) {
  const int head = RequirePart(*rig, "head_neck");
  const int rim = rig->PartIndex("face_rim");  // the face's ring of polygons textured as the back of the head
  const ScalpHairline line = ScalpHairlineOf(*rig);
  const int hair = static_cast<int>(rig->part_names.size());
  rig->part_names.push_back("scalp_hair");
  for (int v = 0; v < rig->num_vertices(); ++v) {
    const int part = rig->vertex_part[v];
    if ((part != head && part != rim) || line.Weight(rig->neutral.V.row(v).transpose()) < 0.5) continue;
    MoveToPart(rig, v, hair);
  }
}

}  // namespace

FaceRig BuildIctStudioRig(const FaceRig& imported, const IctHeadOptions& options) {
  options.Check();
  FaceRig rig = imported;
  RequirePart(rig, "face");
  RequirePart(rig, "head_neck");
  Require(rig.LandmarkIndex("ibug_68") >= 0,
          fmt::format("{}: the rig lacks the 68 iBUG landmarks the studio anchors actors to", rig.source));
  if (rig.num_identity() > options.identity_modes) {
    rig.identity_basis.conservativeResize(Eigen::NoChange, options.identity_modes);
    rig.identity_names.resize(static_cast<size_t>(options.identity_modes));
  }
  std::vector<uint8_t> drop(static_cast<size_t>(rig.num_vertices()), 0);
  DressEye(&rig, "left", options, &drop);
  DressEye(&rig, "right", options, &drop);
  if (!options.eyelashes) {
    for (const char* part : {"eyelashes_left", "eyelashes_right"}) {
      const int p = rig.PartIndex(part);
      for (int v = 0; v < rig.num_vertices(); ++v) {
        if (p >= 0 && rig.vertex_part[v] == p) drop[v] = 1;
      }
    }
  }
  DropTriangles(&rig, drop);
  HairOnTheScalp(&rig);
  rig.source += "; dressed for the studio (synth/ict_head.h)";
  rig.Validate("ICT studio rig");
  return rig;
}

void RequireDressedIfIct(const FaceRig& rig, const std::string& what) {
  const bool undressed = rig.PartIndex("socket_left") >= 0 && rig.PartIndex("iris_left") >= 0 &&
                         rig.PartIndex("pupil_left") < 0;
  Require(!undressed, fmt::format("{} ({}): an imported ICT-FaceKit head not dressed for the studio (its cornea "
                                  "caps would hide the irises and its lash cards render as black slabs); make "
                                  "the studio rig with `crease synth rig --head ict --from THIS.crig -o STUDIO.crig`",
                                  what, rig.source));
}

}  // namespace crease
