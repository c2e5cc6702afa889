// The studio's procedural face rig: a full human head built from a signed
// distance field, written as a crease FaceRig (core/face_rig.h). It is the global
// tracker's blendshape prior (paper Sec. 5, "DDE"-style rig) and the base of every
// synthetic actor (synth/actor*).
//
// Conventions (DESIGN.md): millimetres; head frame x = the subject's left (the
// viewer's right when the face looks at the camera), y up, z forward out of the
// face; origin near the centre of the head (eye centres at y = 0). Adult
// proportions: ~150 mm head breadth, ~230 mm chin (menton) to crown, eyes ~63 mm
// apart.
//
// Parts (FaceRig::part_names, in this order):
//   face           the skin of the face (forehead from the hairline, temples,
//                  cheeks up to the ears, jaw line, under the chin); carries the
//                  one UV chart inside [0,1]² (u = subject's left at larger u,
//                  v down: forehead at small v, chin at large v)
//   cranium        the rest of the scalp, the back of the head and the skin under
//                  the jaw not covered by hair
//   hair           a hair cap: the scalp above the hairline, raised by up to
//                  ProceduralRigOptions::hair_thickness_mm
//   neck           the neck below the jaw and the occiput
//   ears           two simple ears (closed shells pushed into the side of the head)
//   eyeball_left, eyeball_right   sclera (the subject's left = +x)
//   iris_left, iris_right         iris annulus, vertices of its own
//   pupil_left, pupil_right       pupil disc, vertices of its own
//   mouth_cavity   a dark closed bag behind the lips; its lower half follows the jaw
//   teeth_upper, teeth_lower      two arches of (box-shaped) teeth between the lips
//                  and the cavity; the lower one follows the jaw
// Every part but the face has UVs outside [0,1]² (u in [1,2] cranium/hair/neck,
// [2,3] eyes, [3,4] ears, [4,5] mouth cavity, [5,6] teeth), so UV-space stages
// ignore them.
// The eyelids and the lips are slits in the face mesh: the upper and lower lid
// (lip) rims are distinct vertices at the same grid node, so blinks close and
// jawOpen parts the lips onto the mouth cavity.
//
// Brows and lips are flagged by extra region masks "brow_left", "brow_right"
// and "lips" (besides StandardRegionNames(): forehead, glabella and eyes from
// RegionsFromLandmarks, cheeks re-derived so that they stop at their own ala).
//
// Expressions (ARKit names; _L/_R = the subject's left/right, exact mirror images):
// browInnerUp, browOuterUp, browDown, eyeBlink, eyeWide, eyeSquint, cheekSquint,
// noseSneer, mouthSmile, mouthFrown, mouthStretch, mouthPress, mouthUpperUp,
// mouthLowerDown, mouthDimple, eyeLookUp/Down/In/Out (each _L and _R);
// mouthLeft/mouthRight, jawLeft/jawRight (mirror pairs); jawOpen, jawForward,
// cheekPuff, mouthPucker, mouthFunnel, mouthShrugLower, mouthShrugUpper.
// Identity modes (±1 ≈ ±1 std, a few mm): head_width, face_width, face_length,
// head_depth, head_height, forehead_slope, brow_ridge, eye_spacing, eye_size,
// eye_depth, nose_length, nose_width, nose_projection, nose_bridge,
// nose_tip_rotation, cheekbones, cheek_fullness, jaw_width, chin_projection,
// chin_height, lip_fullness, mouth_width, upper_lip_height, midface_depth,
// ear_protrusion, neck_width.
//
// Measured with the default options (tests/procedural_rig_test.cc checks the bounds):
//   14,817 vertices, 28,592 triangles (face part: 14,256 triangles), built in ~0.4 s;
//   26 identity modes, 49 expressions (ARKit names), 68 iBUG landmarks, 12 regions.
//   Face UV chart (LSCM, then ARAP): no flipped triangles, no overlapping texels at
//   1024²; per-triangle (3D area / UV area) relative to the chart mean: 5th / 50th /
//   95th percentile 0.81 / 0.92 / 1.39 (min 0.28, max 3.3, at the lid rims,
//   which are opened slightly in UV after the solve); conformal distortion
//   σmax/σmin mean 1.19, 95th percentile 1.45.
//   Test bounds: area ratio p05 > 0.5, p95 < 2; conformal p95 < 1.6.
//
// Differences from reality (see also procedural_rig.cc):
//   1. The head is a smooth union of ellipsoids and cones: no skin folds at
//      neutral (nasolabial fold, lid crease), no eyelashes, box-shaped teeth,
//      no gums or tongue; the cornea is not a separate bulge and the iris lies on
//      the eyeball sphere.
//   2. Blendshapes are hand-made smooth displacement fields, not muscle
//      simulations or scans; they are linear (jawOpen is exact at weight 1 and a
//      chord of the rotation in between).
//   3. The identity basis is a set of named, hand-made modes with independent unit
//      standard deviations, not a PCA of scans (no correlations between modes).
#pragma once

#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/options.h"

namespace crease {

struct ProceduralRigOptions {
  // Columns of the face grid across the face (±79.2° of azimuth about the head's
  // vertical axis); even, in [24, 96]. 88 gives ~2.7 mm between columns at the cheeks.
  int face_columns = 88;
  // Scales the number of grid rows in each horizontal band of the face (the eye
  // and mouth bands are twice as dense as the rest), in [0.5, 1.2]. 1 gives 1–2 mm rows.
  double face_row_density = 1.0;
  // Columns per side behind the face (azimuth 79.2° … 180°), in [4, 40].
  int back_columns = 18;
  // Eyeball sphere resolution: segments around the gaze axis, in [8, 64].
  int eyeball_segments = 32;
  // Height of the hair cap above the scalp at the crown, mm (0 = bald, the part
  // "hair" is then only a colour flag).
  double hair_thickness_mm = 7.0;
  // Rotation of the jaw about the hinge (temporomandibular axis) at jawOpen = 1, degrees.
  double jaw_open_deg = 16.0;
  // Resolution of the region masks (RegionsFromLandmarks), texels.
  int region_mask_size = 512;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Builds the rig; deterministic (same options, same bytes). Calls rig.Validate.
// Throws Error for invalid options.
FaceRig BuildProceduralRig(const ProceduralRigOptions& options = {});

// Distortion of the face part's UV chart (triangles whose three vertices are in
// the part "face"), for reports and tests.
struct ChartDistortion {
  int triangles = 0;
  // Per triangle, (3D area / UV area) divided by the chart's total 3D / UV area
  // ratio (1 = the chart's mean scale): percentiles and extremes.
  double area_ratio_p05 = 0.0, area_ratio_p50 = 0.0, area_ratio_p95 = 0.0;
  double area_ratio_min = 0.0, area_ratio_max = 0.0;
  // Per triangle, the conformal (angle) distortion σ_max/σ_min of the UV→3D
  // Jacobian (1 = angles kept): mean and 95th percentile.
  double conformal_mean = 0.0, conformal_p95 = 0.0;
  int flipped = 0;  // triangles with negative UV orientation relative to the others
};
ChartDistortion MeasureFaceChartDistortion(const FaceRig& rig);

// The part colours used by previews (linear RGB per vertex): skin, lips and brows
// (by region mask), hair, sclera, iris, pupil, mouth cavity.
MatX3d ProceduralRigPreviewColors(const FaceRig& rig);

// A contact sheet of the rig (`crease synth rig --preview`; linear RGB, CV_32FC3):
// 2 rows × 3 columns of `tile`-pixel square previews (core/preview_render.h)
// coloured by ProceduralRigPreviewColors: the neutral from the front, three-quarter
// and side, then a smile, a jaw drop with raised brows and an asymmetric frown.
// Expressions the rig lacks are left out of their tile.
cv::Mat RigContactSheet(const FaceRig& rig, int tile);

}  // namespace crease
