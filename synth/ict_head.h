// The studio's realistic head: the ICT-FaceKit "Light" face model (USC ICT
// Vision and Graphics Lab, MIT licence; data/ict/LICENSE and CREDITS.md), a
// light-stage head with 53 ARKit-named expression shapes and 100 identity PCA
// modes. scripts/vendor_ict.sh imports it with crease's own importer
// (core/rig_import.h: `crease rig import --parts data/ict/ict_parts.json
// --landmarks vertex_indices.json --compact`) into data/ict/ict_face_light.crig;
// this unit dresses that import for the studio:
//   * the eyes are made opaque-renderable: the sclera's cap over the cornea
//     (transparent in a game engine) is removed, and the model's inner eye mesh
//     is split into iris, pupil and sclera (the Light model ships no textures);
//   * the scalp above a hairline becomes hair (the part "scalp_hair" and the actor's
//     skin maps, with one hairline: synth/skin.h, ScalpHairline);
//   * the identity basis is kept to the first IctHeadOptions::identity_modes
//     modes (the model's modes are scaled to unit standard deviation: a unit
//     coefficient moves the surface by up to 5–13 mm for the first modes).
//
// Conventions as in the rest of the studio: mm, x = the subject's left, y up,
// z forward out of the face (the model's own frame, scaled from cm).
//
// Differences from reality:
//   1. No hair geometry: the model is bald; short-cropped hair is a dark material on
//      the head-and-neck part above the scalp hairline (synth/skin.h,
//      ScalpHairline; the part "scalp_hair") and painted by the actor's skin maps on the
//      face chart's share of the scalp; eyebrows and the lash line are painted too.
//   2. The iris and pupil are uniform materials on the model's iris mesh.
//   3. No eyelashes (see IctHeadOptions::eyelashes).
#pragma once

#include <filesystem>

#include "core/face_rig.h"
#include "core/options.h"

namespace crease {

struct IctHeadOptions {
  int identity_modes = 100;      // identity PCA modes kept (the first N of the model's 100)
  // The model's eyelashes are card strips meant for an alpha-tested texture; an
  // opaque renderer draws them as black slabs over the lids, so they are left out.
  bool eyelashes = false;
  double iris_radius_mm = 5.9;    // visible iris (an adult's is 11.5–12 mm across)
  double pupil_radius_mm = 1.9;   // pupil under studio light (3–4 mm across)
  double cornea_radius_mm = 6.3;  // the sclera's cap within this distance of the gaze axis is removed

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// The vendored rig, data/ict/ict_face_light.crig: $CREASE_DATA/ict/… when the
// environment variable CREASE_DATA is set, else the source checkout's data/.
std::filesystem::path VendoredIctRigPath();

// Dresses an imported ICT-FaceKit rig (parts "face", "head_neck", "iris_left",
// "iris_right", "eyeball_left", "eyeball_right", 68 landmarks) for the studio
// as described above. Throws Error naming a missing part.
FaceRig BuildIctStudioRig(const FaceRig& imported, const IctHeadOptions& options = {});

// Throws Error when `rig` is an ICT-FaceKit import that BuildIctStudioRig has not
// dressed (it has eye sockets and irises but no pupils): rendered opaque, its
// cornea caps hide the irises (blank white eyes) and its lash cards are black slabs
// over the lids. `what` names the rig in the message, which says how to dress it.
void RequireDressedIfIct(const FaceRig& rig, const std::string& what);

}  // namespace crease
