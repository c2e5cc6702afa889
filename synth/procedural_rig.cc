// The procedural head (synth/procedural_rig.h).
//
// Construction:
//   1. The skin is the zero set of a signed distance field (a smooth union of
//      ellipsoids and cones: cranium, mid-face, mandible, chin, cheekbones, brow
//      ridge, nose, lips, neck; carved eye sockets with the closed lids hugging
//      the eyeballs). It is star-shaped about the origin, so it is sampled on a
//      latitude–longitude grid of rays from the origin (elevation ψ, azimuth φ
//      about +y, φ = 0 looking out of the face): each grid node is the point where
//      its ray meets the surface. The grid is dense over the face and coarse
//      behind it, and mirror-symmetric (columns ±φ, mirrored diagonals).
//   2. Eyes and mouth are slits along grid rows (ψ = 0 at the eyes, the stomion
//      row at the mouth): slit nodes have an upper and a lower vertex. The eyes
//      are opened by warping the rays' elevation near the slit (upper rows move
//      up, lower rows down), so the lid rims slide over the eyeball sphere;
//      blinks are the same warp with the upper rim sent to the lower one.
//   3. The face part is the grid cells with |φ| ≤ 79.2° between the hairline
//      (ψ = 42°) and a lower edge that runs under the chin at the midline (ψ = −72°)
//      and along the jaw at the sides (ψ = −58°). Its UVs are a least-squares
//      conformal map (LSCM, Lévy et al. 2002) relaxed by ARAP (Liu et al. 2008) to
//      keep areas, scaled into [0,1]²; the slits are welded for the solve.
//   4. Eyeballs (with iris and pupil as bands of their own vertices), ears and
//      the mouth cavity are separate closed meshes.
//   5. Identity modes and expressions are smooth displacement fields of the
//      neutral positions (Gaussian falloffs in the head frame), lid expressions
//      are re-sampled rays, jawOpen is a rotation about the temporomandibular
//      axis weighted by a jaw mask. Left/right expressions are exact mirrors.
//
// Differences from reality (numbered; see also procedural_rig.h):
//   4. Eye corners lie on one grid row (no canthal tilt) and the lid margin has no
//      thickness beyond a 1.2 mm gap to the eyeball.
//   5. The lips meet in a recessed fold instead of rolling inward; the mouth cavity
//      is a bag with two arches of box-shaped teeth, no gums and no tongue.
//   6. Ears are deformed ellipsoids (no helix, antihelix or canal); the hair is a
//      raised scalp, not strands; the neck ends in a flat cut like a bust, whose
//      edge the steep rays near the bottom pole sample coarsely (a jagged rim).
//   7. Wrinkle-relevant compression comes from the displacement fields' gradients
//      (e.g. browInnerUp lifts the brows more than the hairline, so the forehead
//      shortens vertically); the magnitudes are plausible, not measured.
//   8. The rays of the latitude–longitude grid meet the sides of the nose and the
//      alae at grazing angles, so there one cell spans a wall of up to 15 mm: the
//      nose is terraced and casts blocky shadows under a raking light. (Sliding the
//      nodes along the skin towards even 3D spacing was tried: a tangential
//      Laplacian depletes the nose's front, and per-row redistribution of the
//      azimuths shears the cells into visible striations on the nose's sides.)
#include "synth/procedural_rig.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <map>
#include <numbers>
#include <tuple>

#include <Eigen/SVD>
#include <Eigen/SparseCholesky>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/preview_render.h"

namespace crease {

void ProceduralRigOptions::VisitFields(OptionVisitor& v) {
  v.Field("face_columns", face_columns);
  v.Field("face_row_density", face_row_density);
  v.Field("back_columns", back_columns);
  v.Field("eyeball_segments", eyeball_segments);
  v.Field("hair_thickness_mm", hair_thickness_mm);
  v.Field("jaw_open_deg", jaw_open_deg);
  v.Field("region_mask_size", region_mask_size);
}

void ProceduralRigOptions::Check() const {
  const char* o = "ProceduralRigOptions";
  CheckGe(o, "face_columns", face_columns, 24);
  // Upper bounds: the ranges over which the face chart was verified free of flipped
  // triangles (finer grids resolve small folds of the ray-sampled surface at the temples).
  CheckLe(o, "face_columns", face_columns, 96);
  Require(face_columns % 2 == 0, fmt::format("{}.face_columns = {} must be even (the grid is mirror-symmetric)",
                                             o, face_columns));
  CheckGe(o, "face_row_density", face_row_density, 0.5);
  CheckLe(o, "face_row_density", face_row_density, 1.2);
  CheckGe(o, "back_columns", back_columns, 4);
  CheckLe(o, "back_columns", back_columns, 40);
  CheckGe(o, "eyeball_segments", eyeball_segments, 8);
  CheckLe(o, "eyeball_segments", eyeball_segments, 64);
  CheckGe(o, "hair_thickness_mm", hair_thickness_mm, 0.0);
  CheckLe(o, "hair_thickness_mm", hair_thickness_mm, 20.0);
  CheckGe(o, "jaw_open_deg", jaw_open_deg, 5.0);
  CheckLe(o, "jaw_open_deg", jaw_open_deg, 30.0);
  CheckGe(o, "region_mask_size", region_mask_size, 64);
  CheckLe(o, "region_mask_size", region_mask_size, 4096);
}

namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
constexpr double kDeg = std::numbers::pi / 180.0;

// ---------------------------------------------------------------------------
// Anatomy constants (mm, head frame, left side x > 0; mirrored by |x|).

const Vector3d kEyeCentre(32.0, 0.0, 69.0);  // eyeball centre (interpupillary distance 64 mm)
constexpr double kEyeballRadius = 12.0;      // adult eyeball ~24 mm across
constexpr double kLidGap = 1.2;              // lid margin above the eyeball surface
const Vector3d kJawHinge(0.0, -22.0, 0.0);   // temporomandibular axis (along x), just before the ears
// Rows and columns that carry features (degrees of elevation ψ / azimuth φ).
constexpr double kFaceTopPsi = 42.0;      // hairline
constexpr double kFaceBottomPsi = -72.0;  // under the chin (at the midline; higher at the sides)
constexpr double kFaceHalfPhi = 79.2;     // face part reaches just in front of the ears
constexpr double kEyePsi = 0.0;           // eye slit row
constexpr double kMouthPsi = -41.0;       // stomion row
constexpr double kEyeInnerPhi = 12.3;     // inner canthus (x ≈ 17 mm)
constexpr double kEyeOuterPhi = 34.5;     // outer canthus (x ≈ 45 mm)
constexpr double kMouthCornerPhi = 17.0;  // cheilion (x ≈ 24 mm, mouth ~48 mm wide)
// Lid warp: neutral opening of the upper / lower lid (degrees of ψ at the middle
// of the slit, ~5 mm and ~4 mm: the upper lid covers the top of the iris) and the
// bands over which the warp decays.
constexpr double kUpperLidOpen = 3.4, kLowerLidOpen = 2.6;
constexpr double kUpperLidBand = 10.0, kLowerLidBand = 7.0;
constexpr double kLipRecess = 2.5;  // mm: the lips meet this far inside their fronts

double Smoothstep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}
double Gauss(double v, double c, double s) {
  const double d = (v - c) / s;
  return std::exp(-0.5 * d * d);
}

// ---------------------------------------------------------------------------
// Signed distance field of the skin (eyes closed over the eyeballs).

double SdEllipsoid(const Vector3d& p, const Vector3d& c, const Vector3d& r) {
  const Vector3d q = p - c;
  const double k0 = q.cwiseQuotient(r).norm();
  const double k1 = q.cwiseQuotient(r.cwiseProduct(r)).norm();
  if (k1 < 1e-12) return -r.minCoeff();
  return k0 * (k0 - 1.0) / k1;  // Quilez's bound; exact on the surface
}
// Capsule from a (radius ra) to b (radius rb), radius interpolated along the axis.
double SdCone(const Vector3d& p, const Vector3d& a, const Vector3d& b, double ra, double rb) {
  const Vector3d ab = b - a;
  const double h = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
  return (p - a - h * ab).norm() - (ra + h * (rb - ra));
}
double SMin(double a, double b, double k) {
  const double h = std::max(k - std::abs(a - b), 0.0) / k;
  return std::min(a, b) - h * h * k * 0.25;
}
double SMax(double a, double b, double k) { return -SMin(-a, -b, k); }

double HeadSdf(const Vector3d& p) {
  const Vector3d q(std::abs(p.x()), p.y(), p.z());  // exact mirror symmetry
  double d = SdEllipsoid(q, {0, 20, -6}, {74, 96, 97});                  // cranium
  d = SMin(d, SdEllipsoid(q, {0, -30, 24}, {60, 52, 60}), 22);          // mid-face (maxilla)
  d = SMin(d, SdEllipsoid(q, {0, -66, 16}, {52, 56, 64}), 24);          // lower face and jaw
  d = SMin(d, SdEllipsoid(q, {0, -106, 62}, {21, 14, 17}), 14);         // chin
  d = SMin(d, SdEllipsoid(q, {46, -10, 58}, {17, 12, 16}), 12);         // cheekbone
  d = SMin(d, SdCone(q, {10, 22, 88}, {44, 23, 74}, 7, 6), 10);         // brow ridge
  d = SMax(d, -SdEllipsoid(q, {32, 6, 78}, {19, 12, 14}), 7);           // eye socket
  d = SMin(d, (q - kEyeCentre).norm() - (kEyeballRadius + kLidGap), 3);  // lids over the eyeball
  d = SMin(d, SdCone(q, {0, 4, 86}, {0, -40, 104}, 4.5, 7.5), 6);       // nasal dorsum and tip
  d = SMin(d, SdEllipsoid(q, {13, -47, 85}, {8, 6.5, 8}), 5);           // ala
  d = SMin(d, SdCone(q, {0, -42, 103}, {0, -54, 88}, 4.5, 3.5), 3);     // columella
  // Lips, bent back around the dental arch (radius 40 mm at the front) instead of
  // flat-fronted ellipsoids whose square ends looked boxy from the side.
  const Vector3d q_arch(q.x(), q.y(), q.z() + q.x() * q.x() / 80.0);
  d = SMin(d, SdEllipsoid(q_arch, {0, -70, 80}, {22, 6.5, 8}), 6);      // upper lip
  d = SMin(d, SdEllipsoid(q_arch, {0, -83, 78}, {19, 6.5, 8}), 6);      // lower lip
  // Neck, widening towards the shoulders and cut flat like a bust at y = −165.
  d = SMin(d, SMax(SdCone(q, {0, -105, -24}, {0, -200, -32}, 50, 62), -(q.y() + 165.0), 10), 14);
  return d;
}

// Distance from the origin to the skin along the unit direction `dir` (the
// outermost crossing, found by sphere tracing from outside and bisection).
double MarchRadius(const Vector3d& dir) {
  double t = 340.0, t_out = t;
  for (int i = 0; i < 600; ++i) {
    const double d = HeadSdf(t * dir);
    if (d < 0.02) break;
    t_out = t;
    t -= std::max(0.6 * d, 0.01);
  }
  double t_in = t;
  while (HeadSdf(t_in * dir) > 0.0) t_in -= 0.05;
  for (int i = 0; i < 50; ++i) {
    const double m = 0.5 * (t_in + t_out);
    (HeadSdf(m * dir) > 0.0 ? t_out : t_in) = m;
  }
  return 0.5 * (t_in + t_out);
}

Vector3d Direction(double psi_deg, double phi_deg) {
  if (psi_deg >= 90.0) return Vector3d(0, 1, 0);
  if (psi_deg <= -90.0) return Vector3d(0, -1, 0);
  const double c = std::cos(psi_deg * kDeg);
  return Vector3d(c * std::sin(phi_deg * kDeg), std::sin(psi_deg * kDeg), c * std::cos(phi_deg * kDeg));
}

// ---------------------------------------------------------------------------
// The latitude–longitude grid.

struct Grid {
  std::vector<double> psi;  // rows, degrees, from +90 (top pole) to −90 (bottom pole)
  std::vector<double> phi;  // columns, degrees, ascending, periodic (last = 180)
  int fr0 = 0, fr1 = 0, fc0 = 0, fc1 = 0;  // face node block (inclusive)
  int r_eye = -1, r_mouth = -1, c_centre = -1;
  int eye_ci = -1, eye_co = -1, mouth_c = -1;  // left (φ > 0) corner columns
  int rows() const { return static_cast<int>(psi.size()); }
  int cols() const { return static_cast<int>(phi.size()); }
  int Mirror(int c) const { return c == cols() - 1 ? c : cols() - 2 - c; }
  // The face part's lower edge follows the jaw: under the chin at the midline,
  // along the jaw line at the sides.
  static double BottomPsi(double abs_phi) {
    const double t = abs_phi / kFaceHalfPhi;
    return kFaceBottomPsi + 14.0 * t * t;
  }
  // Its upper edge is the hairline, receding less at the temples (lower there).
  static double TopPsi(double abs_phi) { return kFaceTopPsi - 12.0 * Smoothstep(35.0, kFaceHalfPhi, abs_phi); }
  // Cell between rows r, r+1 and columns c, c+1 (not wrapping) belongs to the face:
  // a block of rows and columns, whose top and bottom rows NodePsi bends onto the
  // hairline and the jaw line.
  bool FaceCell(int r, int c) const { return r >= fr0 && r + 1 <= fr1 && c >= fc0 && c + 1 <= fc1; }
  // All four cells around node (r, c) are face cells.
  bool InteriorFaceNode(int r, int c) const {
    return FaceCell(r - 1, c - 1) && FaceCell(r - 1, c) && FaceCell(r, c - 1) && FaceCell(r, c);
  }
  // Strictly inside a slit (these nodes have an upper and a lower vertex).
  bool EyeSlit(int r, int c) const {
    if (r != r_eye) return false;
    return (c > eye_ci && c < eye_co) || (c > Mirror(eye_co) && c < Mirror(eye_ci));
  }
  bool MouthSlit(int r, int c) const { return r == r_mouth && c > Mirror(mouth_c) && c < mouth_c; }
};

int NearestIndex(const std::vector<double>& values, double x) {
  int best = 0;
  for (int i = 1; i < static_cast<int>(values.size()); ++i) {
    if (std::abs(values[i] - x) < std::abs(values[best] - x)) best = i;
  }
  return best;
}

Grid MakeGrid(const ProceduralRigOptions& o) {
  Grid g;
  g.psi.push_back(90.0);
  auto band = [&](double from, double to, int n, bool scaled) {
    if (scaled) n = std::max(1, static_cast<int>(std::lround(n * o.face_row_density)));
    for (int i = 1; i <= n; ++i) g.psi.push_back(from + (to - from) * i / n);
  };
  band(90, kFaceTopPsi, 14, false);  // NodePsi spreads these over up to 112° at the back
  band(kFaceTopPsi, 12, 17, true);
  band(12, kEyePsi, 12, true);  // eye band: ~1° rows
  band(kEyePsi, -10, 10, true);
  band(-10, -34, 15, true);
  band(-34, kMouthPsi, 7, true);  // mouth band
  band(kMouthPsi, -48, 7, true);
  band(-48, kFaceBottomPsi, 13, true);
  band(kFaceBottomPsi, -90, 6, false);
  // Columns: positive half 0 … 180, then mirrored.
  std::vector<double> pos;
  const int half = o.face_columns / 2;
  for (int k = 0; k <= half; ++k) pos.push_back(kFaceHalfPhi * k / half);
  // Behind the face the columns widen with distance from it (denser at the temples and ears).
  for (int k = 1; k <= o.back_columns; ++k) {
    pos.push_back(kFaceHalfPhi + (180.0 - kFaceHalfPhi) * std::pow(static_cast<double>(k) / o.back_columns, 1.5));
  }
  const int m = static_cast<int>(pos.size()) - 1;  // pos[m] = 180
  for (int k = m - 1; k >= 1; --k) g.phi.push_back(-pos[k]);
  for (int k = 0; k <= m; ++k) g.phi.push_back(pos[k]);
  g.c_centre = m - 1;
  g.fc0 = g.c_centre - half;
  g.fc1 = g.c_centre + half;
  for (int r = 0; r < g.rows(); ++r) {
    if (g.psi[r] == kFaceTopPsi) g.fr0 = r;
    if (g.psi[r] == kFaceBottomPsi) g.fr1 = r;
    if (g.psi[r] == kEyePsi) g.r_eye = r;
    if (g.psi[r] == kMouthPsi) g.r_mouth = r;
  }
  g.eye_ci = NearestIndex(g.phi, kEyeInnerPhi);
  g.eye_co = NearestIndex(g.phi, kEyeOuterPhi);
  g.mouth_c = NearestIndex(g.phi, kMouthCornerPhi);
  Require(g.r_eye > 0 && g.r_mouth > 0 && g.fr1 > g.fr0 && g.eye_co > g.eye_ci + 2,
          "BuildProceduralRig: internal grid construction failed");
  return g;
}

// Opening of each eye's lids, degrees of elevation at the middle of the slit.
struct LidState {
  double upper[2] = {kUpperLidOpen, kUpperLidOpen};  // [0] left eye (φ > 0), [1] right
  double lower[2] = {kLowerLidOpen, kLowerLidOpen};
  double close[2] = {0.0, 0.0};  // 1 = the upper rim lies on the (neutral) lower rim
};

// Elevation warp of the ray of node (ψ, φ) for open lids. `side`: +1 the upper
// rim vertex of a slit node, −1 the lower one, 0 any other node.
double EyeWarp(double psi, double phi, int side, const LidState& lids) {
  const int eye = phi > 0 ? 0 : 1;
  const double t = (std::abs(phi) - kEyeInnerPhi) / (kEyeOuterPhi - kEyeInnerPhi);
  if (t <= 0.0 || t >= 1.0) return 0.0;
  // Almond: the upper lid peaks medially of centre, the lower one laterally.
  const double prof_u = std::sin(std::numbers::pi * std::pow(t, 0.85));
  const double prof_l = std::sin(std::numbers::pi * std::pow(t, 1.15));
  const double d = psi - kEyePsi;
  if (side > 0 || d > 0.0) {
    const double rim = (1.0 - lids.close[eye]) * lids.upper[eye] * prof_u - lids.close[eye] * kLowerLidOpen * prof_l;
    return rim * (1.0 - Smoothstep(0.0, kUpperLidBand, d));
  }
  if (side < 0 || d < 0.0) return -lids.lower[eye] * prof_l * (1.0 - Smoothstep(0.0, kLowerLidBand, -d));
  return 0.0;
}

// Hairline elevation as a function of |φ| (front: the face part's top; sides:
// above the ears; back: the nape).
double HairlinePsi(double abs_phi) {
  if (abs_phi <= kFaceHalfPhi) return Grid::TopPsi(abs_phi);
  static const double kPhi[] = {0.0, kFaceHalfPhi, 92.0, 130.0, 160.0, 180.0};
  static const double kPsi[] = {kFaceTopPsi, kFaceTopPsi - 12.0, 22.0, 16.0, -10.0, -22.0};
  for (int i = 1; i < 6; ++i) {
    if (abs_phi <= kPhi[i]) {
      const double t = (abs_phi - kPhi[i - 1]) / (kPhi[i] - kPhi[i - 1]);
      return kPsi[i - 1] + t * (kPsi[i] - kPsi[i - 1]);
    }
  }
  return kPsi[5];
}

// Elevation of node (r, c), degrees: the row's ψ, bent so that the face's top row
// (kFaceTopPsi at the midline) runs exactly along the hairline — over the face and on
// round to the nape — and its bottom row (kFaceBottomPsi) along the jaw line, instead
// of the face and the hair ending in staircases of whole cells (which showed as a
// stepped hairline on every turned head, and as a row of wrinkle-map patches along
// it). The bend is Δ(φ) · T(ψ), T a tent about the row: 35° each side of the top
// row over the face, widening behind it (up to the pole, which stays, and down to
// −38° at the back), and 25° above the jaw row (18° below it, which the bottom pole
// bounds), so rows keep their order (|Δ| ≤ 0.8 × the tent's half-width); the eyes
// and the mouth are where Δ is 0 or nearly. Cells on the back of the head, whose
// rows the bend spreads, are coarser than the face's.
double NodePsi(const Grid& g, int r, int c) {
  const double psi = g.psi[r], a = std::abs(g.phi[c]);
  double out = psi;
  const double back = Smoothstep(kFaceHalfPhi, 180.0, a);
  const double top_up = 35.0 + 13.0 * back;    // up to the pole at 90°
  const double top_down = 35.0 + 45.0 * back;  // down to −38° at the back (hairline −22°: a bend of −64°)
  const double d_top = std::clamp(HairlinePsi(a) - kFaceTopPsi, -0.8 * top_down, 0.0);
  out += d_top * std::max(0.0, psi >= kFaceTopPsi ? 1.0 - (psi - kFaceTopPsi) / top_up
                                                  : 1.0 - (kFaceTopPsi - psi) / top_down);
  // The jaw line, fading out behind the face (no colour changes there).
  constexpr double kBottomUp = 25.0, kBottomDown = 18.0;
  const double d_bottom = (Grid::BottomPsi(std::min(a, kFaceHalfPhi)) - kFaceBottomPsi) *
                          (1.0 - Smoothstep(kFaceHalfPhi, 110.0, a));
  const double t = psi >= kFaceBottomPsi ? 1.0 - (psi - kFaceBottomPsi) / kBottomUp
                                         : 1.0 - (kFaceBottomPsi - psi) / kBottomDown;
  out += d_bottom * std::max(0.0, t);
  return out;
}

// ---------------------------------------------------------------------------
// The mesh under construction.

enum Part : uint8_t {
  kFace, kCranium, kHair, kNeck, kEars, kEyeballL, kEyeballR, kIrisL, kIrisR, kPupilL, kPupilR, kMouthCavity,
  kTeethUpper, kTeethLower, kNumParts
};
const std::vector<std::string>& PartNames() {
  static const std::vector<std::string> names = {"face",       "cranium",       "hair",       "neck",
                                                 "ears",       "eyeball_left",  "eyeball_right",
                                                 "iris_left",  "iris_right",    "pupil_left", "pupil_right",
                                                 "mouth_cavity", "teeth_upper",   "teeth_lower"};
  return names;
}
bool IsEyePart(int part) { return part >= kEyeballL && part <= kPupilR; }
bool IsLeftEyePart(int part) { return part == kEyeballL || part == kIrisL || part == kPupilL; }

struct VertexInfo {
  int part = kFace;
  bool grid = false;   // a node of the head grid
  int r = -1, c = -1;  // grid node
  int eye_side = 0;    // +1 / −1: upper / lower rim vertex of an eye slit node
  int mouth_side = 0;  // +1 / −1: upper / lower lip vertex of the mouth slit
};

struct Builder {
  std::vector<Vector3d> V;
  std::vector<Vector2d> UV;
  std::vector<VertexInfo> info;
  std::vector<Eigen::Vector3i> F;

  int Add(const Vector3d& p, const Vector2d& uv, const VertexInfo& vi) {
    V.push_back(p);
    UV.push_back(uv);
    info.push_back(vi);
    return static_cast<int>(V.size()) - 1;
  }
};

// A band θ ∈ [θ0, θ1] (degrees from +z) of a unit sphere, `rings` × `segments`
// quads, poles as single vertices; positions mapped by `place`, triangles facing
// away from the sphere's centre. Returns the first vertex id.
int AddSphereBand(Builder& b, double theta0, double theta1, int rings, int segments,
                  const std::function<Vector3d(const Vector3d&)>& place, const VertexInfo& vi,
                  const Vector2d& uv_origin, const Vector2d& uv_size) {
  const int first = static_cast<int>(b.V.size());
  const bool pole0 = theta0 <= 0.0, pole1 = theta1 >= 180.0;
  std::vector<std::vector<int>> ring_ids;
  std::vector<Vector3d> unit;
  for (int i = 0; i <= rings; ++i) {
    const double th = (theta0 + (theta1 - theta0) * i / rings) * kDeg;
    std::vector<int> ids;
    const bool pole = (i == 0 && pole0) || (i == rings && pole1);
    const int n = pole ? 1 : segments;
    for (int j = 0; j < n; ++j) {
      const double ph = 2.0 * std::numbers::pi * j / segments;
      const Vector3d s = pole ? Vector3d(0, 0, i == 0 ? 1.0 : -1.0)
                              : Vector3d(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
      const Vector2d uv = uv_origin + Vector2d(uv_size.x() * (pole ? 0.5 : static_cast<double>(j) / segments),
                                               uv_size.y() * i / rings);
      ids.push_back(b.Add(place(s), uv, vi));
      unit.push_back(s);
    }
    ring_ids.push_back(ids);
  }
  auto tri = [&](int a, int c, int d) {
    // Orient outwards on the unit sphere.
    const Vector3d& pa = unit[a - first];
    const Vector3d& pc = unit[c - first];
    const Vector3d& pd = unit[d - first];
    const Vector3d n = (pc - pa).cross(pd - pa);
    if (n.dot(pa + pc + pd) >= 0.0) {
      b.F.emplace_back(a, c, d);
    } else {
      b.F.emplace_back(a, d, c);
    }
  };
  for (int i = 0; i < rings; ++i) {
    const auto& A = ring_ids[i];
    const auto& B = ring_ids[i + 1];
    for (int j = 0; j < segments; ++j) {
      const int j1 = (j + 1) % segments;
      if (A.size() == 1) {
        tri(A[0], B[j], B[j1]);
      } else if (B.size() == 1) {
        tri(A[j], B[0], A[j1]);
      } else {
        tri(A[j], B[j], B[j1]);
        tri(A[j], B[j1], A[j1]);
      }
    }
  }
  return first;
}

// Mirrors the vertices [first, end) and the triangles [first_tri, end) into new
// ones (x → −x, winding reversed), with part `part_map`ped and UVs shifted.
void AddMirrored(Builder& b, int first, int first_tri, const std::function<int(int)>& part_map,
                 const Vector2d& uv_shift) {
  const int end = static_cast<int>(b.V.size()), end_tri = static_cast<int>(b.F.size());
  const int offset = end - first;
  for (int v = first; v < end; ++v) {
    VertexInfo vi = b.info[v];
    vi.part = part_map(vi.part);
    const Vector3d p = b.V[v];
    b.Add(Vector3d(-p.x(), p.y(), p.z()), b.UV[v] + uv_shift, vi);
  }
  for (int f = first_tri; f < end_tri; ++f) {
    const Eigen::Vector3i t = b.F[f];
    b.F.emplace_back(t[0] + offset, t[2] + offset, t[1] + offset);
  }
}

// ---------------------------------------------------------------------------
// Positions of grid nodes.

struct HeadModel {
  Grid grid;
  double hair_mm = 0.0;

  Vector3d NodePosition(const VertexInfo& vi, const LidState& lids) const {
    const double psi0 = NodePsi(grid, vi.r, vi.c), phi = grid.phi[vi.c];
    double psi = psi0;
    if (vi.r > 0 && vi.r < grid.rows() - 1) psi += EyeWarp(psi0, phi, vi.eye_side, lids);
    const Vector3d dir = Direction(psi, phi);
    double rho = MarchRadius(dir);
    if (vi.r == grid.r_mouth && std::abs(phi) < kMouthCornerPhi) {
      const double t = std::abs(phi) / kMouthCornerPhi;
      rho -= kLipRecess * (1.0 - t * t);
    }
    if (vi.part == kHair) {
      rho += hair_mm * Smoothstep(0.0, 14.0, psi0 - HairlinePsi(std::abs(phi)));
    }
    return rho * dir;
  }
};

// ---------------------------------------------------------------------------
// Least-squares conformal map of the face part (Lévy et al. 2002), two vertices
// pinned. Returns (u, w) with w growing upwards.
std::vector<Vector2d> Lscm(const std::vector<Vector3d>& P, const std::vector<Eigen::Vector3i>& tris,
                           int pin_a, const Vector2d& uv_a, int pin_b, const Vector2d& uv_b) {
  const int n = static_cast<int>(P.size());
  // Unknown index of u_i is 2i, of w_i 2i+1; pinned ones are moved to the right side.
  std::vector<int> col(2 * n, -1);
  int m = 0;
  for (int i = 0; i < n; ++i) {
    if (i == pin_a || i == pin_b) continue;
    col[2 * i] = m++;
    col[2 * i + 1] = m++;
  }
  auto pinned = [&](int i, int k) { return i == pin_a ? uv_a[k] : uv_b[k]; };
  std::vector<Eigen::Triplet<double>> trip;
  std::vector<double> rhs;
  int row = 0;
  for (const auto& t : tris) {
    const Vector3d p0 = P[t[0]], p1 = P[t[1]], p2 = P[t[2]];
    const Vector3d ex = (p1 - p0).normalized();
    const Vector3d nrm = (p1 - p0).cross(p2 - p0);
    if (nrm.norm() < 1e-12) continue;
    const Vector3d ey = nrm.normalized().cross(ex);
    const Vector2d q[3] = {Vector2d(0, 0), Vector2d((p1 - p0).norm(), 0), Vector2d((p2 - p0).dot(ex), (p2 - p0).dot(ey))};
    const double s = 1.0 / std::sqrt(std::max(q[1].x() * q[2].y(), 1e-12));
    double b_re = 0.0, b_im = 0.0;
    for (int j = 0; j < 3; ++j) {
      // W_j = q_{j−1} − q_{j+1} (complex); row: Σ W_j (u_j + i w_j) = 0.
      const Vector2d W = (q[(j + 2) % 3] - q[(j + 1) % 3]) * s;
      const double a = W.x(), bb = W.y();
      const int v = t[j];
      // real: a u − b w ; imaginary: b u + a w
      if (col[2 * v] >= 0) {
        trip.emplace_back(row, col[2 * v], a);
        trip.emplace_back(row, col[2 * v + 1], -bb);
        trip.emplace_back(row + 1, col[2 * v], bb);
        trip.emplace_back(row + 1, col[2 * v + 1], a);
      } else {
        const double u = pinned(v, 0), w = pinned(v, 1);
        b_re += a * u - bb * w;
        b_im += bb * u + a * w;
      }
    }
    rhs.push_back(-b_re);
    rhs.push_back(-b_im);
    row += 2;
  }
  SpMat A(row, m);
  A.setFromTriplets(trip.begin(), trip.end());
  const Eigen::VectorXd b = Eigen::Map<Eigen::VectorXd>(rhs.data(), static_cast<Eigen::Index>(rhs.size()));
  const SpMat AtA = A.transpose() * A;
  Eigen::SimplicialLDLT<SpMat> solver(AtA);
  Require(solver.info() == Eigen::Success, "BuildProceduralRig: the UV (LSCM) factorisation failed");
  const Eigen::VectorXd x = solver.solve(A.transpose() * b);
  std::vector<Vector2d> uv(n);
  for (int i = 0; i < n; ++i) {
    if (col[2 * i] < 0) {
      uv[i] = Vector2d(pinned(i, 0), pinned(i, 1));
    } else {
      uv[i] = Vector2d(x[col[2 * i]], x[col[2 * i + 1]]);
    }
  }
  return uv;
}


// As-rigid-as-possible refinement of a planar parameterisation (Liu et al. 2008,
// "A Local/Global Approach to Mesh Parameterization"): alternates the best
// rotation per triangle (local) with a cotangent-Laplacian solve (global). It
// trades the conformal map's large area distortion over a strongly curved chart
// for a small angle distortion. A spring holds vertex `pin` at its start.
std::vector<Vector2d> Arap(const std::vector<Vector3d>& P, const std::vector<Eigen::Vector3i>& tris,
                           std::vector<Vector2d> uv, int pin, int iterations) {
  const int n = static_cast<int>(P.size());
  struct Local {
    Vector2d q[3];
    double cot[3];  // cot of the angle opposite edge (k+1, k+2)
  };
  std::vector<Local> loc(tris.size());
  std::vector<Eigen::Triplet<double>> trip;
  for (size_t t = 0; t < tris.size(); ++t) {
    const Vector3d p0 = P[tris[t][0]], p1 = P[tris[t][1]], p2 = P[tris[t][2]];
    const Vector3d ex = (p1 - p0).normalized();
    const Vector3d ey = (p1 - p0).cross(p2 - p0).normalized().cross(ex);
    Local& l = loc[t];
    l.q[0] = Vector2d(0, 0);
    l.q[1] = Vector2d((p1 - p0).norm(), 0);
    l.q[2] = Vector2d((p2 - p0).dot(ex), (p2 - p0).dot(ey));
    for (int k = 0; k < 3; ++k) {
      const Vector2d a = l.q[(k + 1) % 3] - l.q[k], b = l.q[(k + 2) % 3] - l.q[k];
      const double cross = a.x() * b.y() - a.y() * b.x();
      l.cot[k] = std::clamp(a.dot(b) / std::max(std::abs(cross), 1e-12), -1e3, 1e3);
      const int i = tris[t][(k + 1) % 3], j = tris[t][(k + 2) % 3];
      const double w = 0.5 * l.cot[k];
      trip.emplace_back(i, i, w);
      trip.emplace_back(j, j, w);
      trip.emplace_back(i, j, -w);
      trip.emplace_back(j, i, -w);
    }
  }
  // The Laplacian's null space (translation) is removed by a unit spring holding `pin`.
  trip.emplace_back(pin, pin, 1.0);
  const Vector2d pin_uv = uv[pin];
  SpMat L(n, n);
  L.setFromTriplets(trip.begin(), trip.end());
  Eigen::SimplicialLDLT<SpMat> solver(L);
  Require(solver.info() == Eigen::Success, "BuildProceduralRig: the UV (ARAP) factorisation failed");
  std::vector<Eigen::Matrix2d> R(tris.size());
  for (int it = 0; it < iterations; ++it) {
    for (size_t t = 0; t < tris.size(); ++t) {
      Eigen::Matrix2d S = Eigen::Matrix2d::Zero();
      for (int k = 0; k < 3; ++k) {
        const int a = (k + 1) % 3, b = (k + 2) % 3;
        S += loc[t].cot[k] * (uv[tris[t][a]] - uv[tris[t][b]]) * (loc[t].q[a] - loc[t].q[b]).transpose();
      }
      const Eigen::JacobiSVD<Eigen::Matrix2d> svd(S, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix2d U = svd.matrixU();
      if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(1) *= -1.0;
      R[t] = U * svd.matrixV().transpose();
    }
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, 2);
    for (size_t t = 0; t < tris.size(); ++t) {
      for (int k = 0; k < 3; ++k) {
        const int a = (k + 1) % 3, b = (k + 2) % 3;
        const Vector2d e = 0.5 * loc[t].cot[k] * (R[t] * (loc[t].q[a] - loc[t].q[b]));
        rhs.row(tris[t][a]) += e.transpose();
        rhs.row(tris[t][b]) -= e.transpose();
      }
    }
    rhs.row(pin) += pin_uv.transpose();
    const Eigen::MatrixXd x = solver.solve(rhs);
    for (int i = 0; i < n; ++i) uv[i] = x.row(i).transpose();
  }
  return uv;
}

// ---------------------------------------------------------------------------
// Displacement fields.

double Front(const Vector3d& p) { return Smoothstep(15.0, 55.0, p.z()); }
// Vertical profile of a brow raise: 0 at the lid crease, 1 at the brow, 0 at the hairline.
double BrowProfile(double y) { return Smoothstep(3.0, 20.0, y) * (1.0 - Smoothstep(28.0, 68.0, y)); }

Vector3d RotateX(const Vector3d& p, const Vector3d& centre, double angle_rad) {
  return centre + Eigen::AngleAxisd(angle_rad, Vector3d::UnitX()) * (p - centre);
}

// Expression definition: a displacement field for the subject's left side (or the
// centre), optional lid openings (per eye) and the jaw weight use.
struct ExpressionDef {
  std::string name;     // for a pair: the _L name (or "...Left"); the mirror gets _R / "Right"
  std::string mirror;   // "" = unpaired
  std::function<Vector3d(const Vector3d&, const VertexInfo&)> field;  // may be empty
  std::function<void(LidState&)> lids;                                // may be empty
};

using VI = VertexInfo;

// ---------------------------------------------------------------------------
// The head's meshes.

// Vertex ids of the head grid's nodes (-1 = none): the face vertex (on a slit,
// the upper rim), the lower rim vertex of a slit node, and the scalp vertex.
struct GridNodes {
  int cols = 0;
  std::vector<int> face, lower, skull;

  size_t Node(int r, int c) const { return static_cast<size_t>(r) * cols + c; }
  int Face(int r, int c) const { return face[Node(r, c)]; }
  int Lower(int r, int c) const { return lower[Node(r, c)]; }
};

// The head grid: face, cranium, hair and neck, at the neutral's positions; UVs
// on the scalp's tile (the face chart replaces them for the face).
GridNodes AddHeadGrid(const HeadModel& head, Builder& b) {
  const Grid& g = head.grid;
  const int R = g.rows(), C = g.cols();
  GridNodes nodes;
  nodes.cols = C;
  nodes.face.assign(static_cast<size_t>(R) * C, -1);
  nodes.skull.assign(static_cast<size_t>(R) * C, -1);
  nodes.lower.assign(static_cast<size_t>(R) * C, -1);
  // Hair above the hairline; the rest of the scalp is split into cranium and neck
  // once positions are known.
  auto skull_part = [&](int r, int c) {
    return NodePsi(g, r, c) >= HairlinePsi(std::abs(g.phi[c])) - 1e-9 ? kHair : kCranium;
  };
  auto vertex = [&](int r, int c, bool face, bool lower) {
    if (r == 0) c = 0;  // poles: one vertex each
    if (r == R - 1) c = 0;
    std::vector<int>& ids = face ? (lower ? nodes.lower : nodes.face) : nodes.skull;
    int& id = ids[nodes.Node(r, c)];
    if (id < 0) {
      VertexInfo vi;
      vi.grid = true;
      vi.r = r;
      vi.c = c;
      vi.part = face ? kFace : skull_part(r, c);
      if (face && g.EyeSlit(r, c)) vi.eye_side = lower ? -1 : 1;
      if (face && g.MouthSlit(r, c)) vi.mouth_side = lower ? -1 : 1;
      id = b.Add(Vector3d::Zero(), Vector2d::Zero(), vi);
    }
    return id;
  };
  for (int r = 0; r + 1 < R; ++r) {
    for (int c = 0; c < C; ++c) {
      const int c1 = (c + 1) % C;
      const bool face = c1 > c && g.FaceCell(r, c);
      // Cells just below a slit use the slit's lower vertices.
      auto lower = [&](int rr, int cc) { return face && rr == r && (g.EyeSlit(rr, cc) || g.MouthSlit(rr, cc)); };
      const int tl = vertex(r, c, face, lower(r, c)), tr = vertex(r, c1, face, lower(r, c1));
      const int bl = vertex(r + 1, c, face, false), br = vertex(r + 1, c1, face, false);
      double mid = 0.5 * (g.phi[c] + g.phi[c1] + (c1 < c ? 360.0 : 0.0));
      if (mid > 180.0) mid -= 360.0;
      if (r == 0) {
        b.F.emplace_back(tl, bl, br);
      } else if (r + 1 == R - 1) {
        b.F.emplace_back(tl, br, tr);
      } else if (mid < 0.0) {  // diagonal TL–BR left of the midline, mirrored on the right
        b.F.emplace_back(tl, bl, br);
        b.F.emplace_back(tl, br, tr);
      } else {
        b.F.emplace_back(tl, bl, tr);
        b.F.emplace_back(bl, br, tr);
      }
    }
  }
  const int num_grid_vertices = static_cast<int>(b.V.size());
  const LidState neutral_lids;
  for (int v = 0; v < num_grid_vertices; ++v) {
    b.V[v] = head.NodePosition(b.info[v], neutral_lids);
    if (b.info[v].part == kCranium || b.info[v].part == kNeck) {
      b.info[v].part = b.V[v].y() < -125.0 ? kNeck : kCranium;
    }
    const double psi = NodePsi(g, b.info[v].r, b.info[v].c), phi = g.phi[b.info[v].c];
    b.UV[v] = Vector2d(1.0 + (phi + 180.0) / 360.0, (90.0 - psi) / 180.0);  // replaced below for the face
  }
  return nodes;
}

// Eyeballs: pupil disc, iris annulus, sclera; the left one, then mirrored.
void AddEyeballs(const ProceduralRigOptions& options, Builder& b) {
  constexpr double kPupilDeg = 10.0, kIrisDeg = 30.0;  // half-angles: ~2 mm pupil, ~6 mm iris radius
  const int first = static_cast<int>(b.V.size()), first_tri = static_cast<int>(b.F.size());
  const int segs = options.eyeball_segments;
  auto place = [&](const Vector3d& s) { return Vector3d(kEyeCentre + kEyeballRadius * s); };
  VertexInfo vi;
  vi.part = kPupilL;
  AddSphereBand(b, 0.0, kPupilDeg, 2, segs, place, vi, {2.0, 0.0}, {0.5, kPupilDeg / 180.0});
  vi.part = kIrisL;
  AddSphereBand(b, kPupilDeg, kIrisDeg, 4, segs, place, vi, {2.0, kPupilDeg / 180.0},
                {0.5, (kIrisDeg - kPupilDeg) / 180.0});
  vi.part = kEyeballL;
  AddSphereBand(b, kIrisDeg, 180.0, std::max(8, segs / 3), segs, place, vi, {2.0, kIrisDeg / 180.0},
                {0.5, (180.0 - kIrisDeg) / 180.0});
  AddMirrored(b, first, first_tri, [](int p) { return p + 1; }, {0.5, 0.0});  // *_left → *_right
}

// Ears: flattened ellipsoids with a concha, leaning back, the back edge flared.
void AddEars(Builder& b) {
  const int first = static_cast<int>(b.V.size()), first_tri = static_cast<int>(b.F.size());
  const Vector3d radii(5.0, 31.0, 16.0), centre(71.0, -14.0, -13.0);
  const Eigen::Matrix3d rot = (Eigen::AngleAxisd(-26.0 * kDeg, Vector3d::UnitY()) *
                               Eigen::AngleAxisd(-15.0 * kDeg, Vector3d::UnitX()))
                                  .toRotationMatrix();
  // Unit sphere with its poles along the ear's local x (outwards).
  auto place = [&](const Vector3d& s) {
    Vector3d l(s.z() * radii.x(), s.y() * radii.y(), s.x() * radii.z());  // local: x out, y up, z forward
    if (s.z() > 0.0) {
      // Concha: a dip in the outer face, low and forward; a raised rim (helix)
      // around the upper and back edge; a thicker lobe at the bottom.
      const double dip = 5.0 * std::exp(-0.5 * (std::pow((l.y() + 6.0) / 9.0, 2) + std::pow((l.z() - 1.0) / 6.0, 2)));
      const double rim_t = std::sqrt(s.x() * s.x() + s.y() * s.y());
      const double helix = 3.0 * Gauss(rim_t, 0.9, 0.09) * Smoothstep(-0.6, 0.2, s.y() - 0.5 * s.x());
      const double lobe = 2.0 * Gauss(s.y(), -0.85, 0.15);
      l.x() += -dip + helix + lobe;
    }
    return Vector3d(centre + rot * l);
  };
  VertexInfo vi;
  vi.part = kEars;
  AddSphereBand(b, 0.0, 180.0, 14, 24, place, vi, {3.0, 0.0}, {0.5, 1.0});
  AddMirrored(b, first, first_tri, [](int p) { return p; }, {0.5, 0.0});
}

// Mouth cavity: a closed bag behind the lips, facing inwards.
void AddMouthCavity(Builder& b) {
  const int first_tri = static_cast<int>(b.F.size());
  const Vector3d radii(21.0, 14.0, 18.0), centre(0.0, -77.0, 57.0);
  auto place = [&](const Vector3d& s) { return Vector3d(centre + radii.cwiseProduct(Vector3d(s.x(), s.y(), s.z()))); };
  VertexInfo vi;
  vi.part = kMouthCavity;
  AddSphereBand(b, 0.0, 180.0, 10, 20, place, vi, {4.0, 0.0}, {1.0, 1.0});
  for (size_t f = first_tri; f < b.F.size(); ++f) std::swap(b.F[f][1], b.F[f][2]);
}

// One arch of teeth (jaw 0: upper, 1: lower), incisors to premolars, as a closed
// swept box between the lips and the cavity.
void AddTeethArch(int jaw, Builder& b) {
  constexpr int kSegments = 16;
  constexpr double kHalfAngle = 1.15;              // radians of the arch on each side
  const double ax = 21.0, az = 17.0, zc = 62.5;  // arch half-width, depth, centre (mm)
  // The upper incisors reach ~3 mm below the stomion, the lower ones sit behind them.
  const double y_top = jaw == 0 ? -67.0 : -77.5, y_bottom = jaw == 0 ? -78.5 : -87.0;
  const double zj = jaw == 0 ? zc : zc - 3.0;
  const double thick = 3.5;
  VertexInfo vi;
  vi.part = jaw == 0 ? kTeethUpper : kTeethLower;
  std::vector<std::array<int, 4>> sec;
  std::vector<Vector3d> out_n;
  for (int i = 0; i <= kSegments; ++i) {
    const double t = kHalfAngle * (2 * i - kSegments) / kSegments;  // exact ±t pairs
    const Vector3d c(ax * std::sin(t), 0.0, zj + az * std::cos(t));
    const Vector3d n = Vector3d(std::sin(t) / ax, 0.0, std::cos(t) / az).normalized();
    std::array<int, 4> ids;
    const Vector3d corners[4] = {c + 0.5 * thick * n + Vector3d(0, y_top, 0), c + 0.5 * thick * n + Vector3d(0, y_bottom, 0),
                                 c - 0.5 * thick * n + Vector3d(0, y_bottom, 0), c - 0.5 * thick * n + Vector3d(0, y_top, 0)};
    for (int k = 0; k < 4; ++k) {
      ids[k] = b.Add(corners[k], Vector2d(5.0 + 0.5 * jaw + 0.5 * i / kSegments, 0.25 * k), vi);
    }
    sec.push_back(ids);
    out_n.push_back(n);
  }
  auto quad = [&](int a, int bb, int c, int d, const Vector3d& outward) {
    for (const Eigen::Vector3i& t : {Eigen::Vector3i(a, bb, c), Eigen::Vector3i(a, c, d)}) {
      const Vector3d nrm = (b.V[t[1]] - b.V[t[0]]).cross(b.V[t[2]] - b.V[t[0]]);
      b.F.push_back(nrm.dot(outward) >= 0.0 ? t : Eigen::Vector3i(t[0], t[2], t[1]));
    }
  };
  for (int i = 0; i < kSegments; ++i) {
    const auto& A = sec[i];
    const auto& B = sec[i + 1];
    const Vector3d n = (out_n[i] + out_n[i + 1]).normalized();
    quad(A[0], A[1], B[1], B[0], n);                  // labial face
    quad(A[3], A[2], B[2], B[3], -n);                 // lingual face
    quad(A[0], A[3], B[3], B[0], Vector3d::UnitY());  // top
    quad(A[1], A[2], B[2], B[1], -Vector3d::UnitY()); // bottom
  }
  const Vector3d t0 = b.V[sec[1][0]] - b.V[sec[0][0]], t1 = b.V[sec[kSegments][0]] - b.V[sec[kSegments - 1][0]];
  quad(sec[0][0], sec[0][1], sec[0][2], sec[0][3], -t0);
  quad(sec[kSegments][0], sec[kSegments][1], sec[kSegments][2], sec[kSegments][3], t1);
}

// Teeth: two arches (upper and lower incisors to premolars) as closed swept boxes
// between the lips and the cavity; the lower one follows the jaw.
void AddTeeth(Builder& b) {
  for (int jaw = 0; jaw < 2; ++jaw) AddTeethArch(jaw, b);
}

// ---------------------------------------------------------------------------
// The face UV chart.

// The face part with its slits welded: each face vertex's index in P (-1 = not
// on the face; a lower rim shares its upper rim's) and the face triangles.
struct WeldedFace {
  std::vector<int> local;
  std::vector<Vector3d> P;
  std::vector<Eigen::Vector3i> tris;
};

WeldedFace WeldFace(const GridNodes& nodes, const Builder& b) {
  const int nv = static_cast<int>(b.V.size());
  WeldedFace w;
  std::vector<int>& local = w.local;
  std::vector<Vector3d>& P = w.P;
  local.assign(nv, -1);
  for (int v = 0; v < nv; ++v) {
    if (b.info[v].part != kFace || b.info[v].mouth_side < 0 || b.info[v].eye_side < 0) continue;
    local[v] = static_cast<int>(P.size());
    P.push_back(b.V[v]);
  }
  for (int v = 0; v < nv; ++v) {
    if (b.info[v].part == kFace && (b.info[v].mouth_side < 0 || b.info[v].eye_side < 0)) {
      local[v] = local[nodes.Face(b.info[v].r, b.info[v].c)];
    }
  }
  for (const auto& t : b.F) {
    if (b.info[t[0]].part == kFace && b.info[t[1]].part == kFace && b.info[t[2]].part == kFace) {
      w.tris.emplace_back(local[t[0]], local[t[1]], local[t[2]]);
    }
  }
  return w;
}

// Brings a conformal map `uw` of the triangles to the surface's scale (equal areas).
void ScaleToSurfaceArea(const std::vector<Vector3d>& P, const std::vector<Eigen::Vector3i>& tris,
                        std::vector<Vector2d>& uw) {
  double a3 = 0.0, a2 = 0.0;
  for (const auto& t : tris) {
    a3 += 0.5 * (P[t[1]] - P[t[0]]).cross(P[t[2]] - P[t[0]]).norm();
    const Vector2d e1 = uw[t[1]] - uw[t[0]], e2 = uw[t[2]] - uw[t[0]];
    a2 += 0.5 * std::abs(e1.x() * e2.y() - e1.y() * e2.x());
  }
  for (auto& q : uw) q *= std::sqrt(a3 / a2);
}

// Face UV chart (LSCM then ARAP on the face triangles). The slits are welded:
// upper and lower lid (lip) rims share their UVs, so the chart has no holes and
// the lids cannot overlap in UV.
void LayOutFaceChart(const Grid& g, const GridNodes& nodes, Builder& b) {
  const int nv = static_cast<int>(b.V.size());
  const WeldedFace face = WeldFace(nodes, b);
  const std::vector<int>& local = face.local;
  const std::vector<Vector3d>& P = face.P;
  const std::vector<Eigen::Vector3i>& tris = face.tris;
  const int pin_top = local[nodes.Face(g.fr0, g.c_centre)];
  int r_bottom = g.fr1;
  while (nodes.Face(r_bottom, g.c_centre) < 0) --r_bottom;
  const int pin_bottom = local[nodes.Face(r_bottom, g.c_centre)];
  std::vector<Vector2d> uw = Lscm(P, tris, pin_top, {0.0, 1.0}, pin_bottom, {0.0, 0.0});
  // Bring the conformal map to the surface's scale, then relax it towards isometry.
  ScaleToSurfaceArea(P, tris, uw);
  uw = Arap(P, tris, uw, pin_top, 20);
  double umin = 1e30, umax = -1e30, wmin = 1e30, wmax = -1e30;
  for (const auto& q : uw) {
    umin = std::min(umin, q.x());
    umax = std::max(umax, q.x());
    wmin = std::min(wmin, q.y());
    wmax = std::max(wmax, q.y());
  }
  // LSCM keeps orientation, so u grows towards the subject's left (+x); checked here.
  double sxu = 0.0;
  for (int v = 0; v < nv; ++v) {
    if (local[v] >= 0) sxu += b.V[v].x() * uw[local[v]].x();
  }
  Require(sxu > 0.0, "BuildProceduralRig: the face chart came out mirrored");
  const double scale = 0.96 / std::max(umax - umin, wmax - wmin);
  const double uc = 0.5 * (umin + umax), wc = 0.5 * (wmin + wmax);
  for (int v = 0; v < nv; ++v) {
    if (local[v] < 0) continue;
    const Vector2d q = uw[local[v]];
    b.UV[v] = Vector2d(0.5 + scale * (q.x() - uc), 0.5 - scale * (q.y() - wc));
  }
}

// Opens the welded slits a little in UV: each rim vertex moves a fraction of the
// way to its neighbour across the row, so that the lids (lips) do not share texels
// and texel grids built on the chart do not bridge the openings.
void OpenSlitsInUv(const GridNodes& nodes, Builder& b) {
  const int nv = static_cast<int>(b.V.size());
  for (int v = 0; v < nv; ++v) {
    const VertexInfo& vi = b.info[v];
    const int side = vi.eye_side != 0 ? vi.eye_side : vi.mouth_side;
    if (vi.part != kFace || side == 0) continue;
    const int across = nodes.Face(vi.r - side, vi.c);  // the next row above (upper) or below
    const double fraction = vi.eye_side != 0 ? 0.4 : 0.25;
    b.UV[v] += fraction * (b.UV[across] - b.UV[v]);
  }
}

// The rig's neutral mesh (positions, triangles, UVs) and vertex parts.
FaceRig RigFromBuilder(const Builder& b) {
  const int nv = static_cast<int>(b.V.size());
  FaceRig rig;
  rig.neutral.V.resize(nv, 3);
  for (int v = 0; v < nv; ++v) rig.neutral.V.row(v) = b.V[v].transpose();
  rig.neutral.F.resize(static_cast<Eigen::Index>(b.F.size()), 3);
  for (size_t f = 0; f < b.F.size(); ++f) rig.neutral.F.row(static_cast<Eigen::Index>(f)) = b.F[f].transpose();
  rig.neutral.UV.resize(nv, 2);
  for (int v = 0; v < nv; ++v) rig.neutral.UV.row(v) = b.UV[v].transpose();
  rig.part_names = PartNames();
  rig.vertex_part.resize(nv);
  for (int v = 0; v < nv; ++v) rig.vertex_part[v] = static_cast<uint8_t>(b.info[v].part);
  return rig;
}

// Mirror map (exact: the construction is symmetric bit for bit): each vertex's
// mirror image across x = 0.
std::vector<int> MirrorMap(const Builder& b) {
  const int nv = static_cast<int>(b.V.size());
  std::vector<int> mirror(nv, -1);
  auto group = [](int part) { return IsEyePart(part) ? (IsLeftEyePart(part) ? part : part - 1) : part; };
  // Positions rounded to 0.1 µm (the mirrored halves agree to rounding error).
  std::map<std::tuple<int64_t, int64_t, int64_t, int, int, int>, int> index;
  auto key = [&](int v, double sx) {
    const VertexInfo& vi = b.info[v];
    auto q = [](double x) { return static_cast<int64_t>(std::llround(x * 1e4)); };
    return std::make_tuple(q(sx * b.V[v].x()), q(b.V[v].y()), q(b.V[v].z()), group(vi.part), vi.eye_side,
                           vi.mouth_side);
  };
  for (int v = 0; v < nv; ++v) index[key(v, 1.0)] = v;
  for (int v = 0; v < nv; ++v) {
    auto it = index.find(key(v, -1.0));
    Require(it != index.end(), fmt::format("BuildProceduralRig: vertex {} has no mirror image", v));
    mirror[v] = it->second;
  }
  return mirror;
}

// Stomion height (for lip fields): y of the mouth slit at the midline.
double StomionHeight(const Grid& g, const GridNodes& nodes, const Builder& b) {
  return b.V[nodes.Face(g.r_mouth, g.c_centre)].y();
}

// ---------------------------------------------------------------------------
// Expressions.

// Jaw weight: the fraction of the jaw's motion (jawOpen's rotation about the
// hinge, jawLeft, jawForward) that a vertex follows.
double JawWeight(const Vector3d& p, const VertexInfo& vi) {
  if (vi.part == kMouthCavity) return 1.0 - Smoothstep(-86.0, -72.0, p.y());
  if (vi.part == kTeethLower) return 1.0;
  if (vi.part == kTeethUpper) return 0.0;
  if (!vi.grid) return 0.0;
  if (vi.mouth_side != 0) return vi.mouth_side < 0 ? 1.0 : 0.0;
  const double horiz = std::hypot(p.x(), p.z());
  const double psi = std::atan2(p.y(), horiz) / kDeg;
  const double aphi = std::abs(std::atan2(p.x(), p.z())) / kDeg;
  const double s = (kMouthPsi - psi) * kDeg * p.norm();  // mm below the stomion cone
  const double delta = 1.2 + 14.0 * Smoothstep(18.0, 45.0, aphi);
  return Smoothstep(-delta, delta, s) * (1.0 - Smoothstep(50.0, 88.0, aphi)) * Smoothstep(-178.0, -140.0, p.y());
}

// 1 on the upper lip and above the stomion, 0 on the lower lip and below.
double MouthUpper(const Vector3d& p, const VertexInfo& vi, double y_mouth) {
  if (vi.mouth_side != 0) return vi.mouth_side > 0 ? 1.0 : 0.0;
  return Smoothstep(y_mouth - 2.0, y_mouth + 2.0, p.y());
}

// Skin lateral of the outer canthus pulled towards it.
Vector3d CrowsFeet(const Vector3d& p) {
  const double gg = Gauss(p.x(), 56.0, 9.0) * Gauss(p.y(), -1.0, 9.0) * Smoothstep(-10.0, 40.0, p.z());
  return Vector3d(-3.0 * gg, 1.0 * gg, 0.0);
}

// The cheek under the eye pushed up (and a little out and forward), `amount` mm at its peak.
Vector3d CheekRaise(const Vector3d& p, double amount) {
  const double gg = Gauss(p.x(), 39.0, 13.0) * Gauss(p.y(), -24.0, 11.0) * Front(p);
  return Vector3d(0.15 * amount * gg, amount * gg, 0.3 * amount * gg);
}

// Left/right pairs of the upper face: brows, lids, cheek squint and nose sneer.
std::vector<ExpressionDef> UpperFaceExpressions() {
  return {
      {"browInnerUp_L", "browInnerUp_R",
       [](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 16.0, 10.0) * BrowProfile(p.y()) * Front(p);
         return Vector3d(-0.3 * gg, 6.5 * gg, 0.6 * gg);
       },
       {}},
      {"browOuterUp_L", "browOuterUp_R",
       [](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 41.0, 10.0) * BrowProfile(p.y()) * Smoothstep(0.0, 40.0, p.z());
         return Vector3d(0.5 * gg, 6.0 * gg, 0.0);
       },
       {}},
      {"browDown_L", "browDown_R",
       [](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 20.0, 11.0) * Gauss(p.y(), 16.0, 10.0) * Front(p);
         return Vector3d(-4.5 * gg, -3.5 * gg, 0.8 * gg);
       },
       {}},
      {"eyeBlink_L", "eyeBlink_R", {}, [](LidState& l) { l.close[0] = 1.0; }},
      {"eyeWide_L", "eyeWide_R",
       [](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 32.0, 14.0) * BrowProfile(p.y()) * Front(p);
         return Vector3d(0.0, 1.5 * gg, 0.0);
       },
       [](LidState& l) { l.upper[0] = kUpperLidOpen + 1.8; }},
      {"eyeSquint_L", "eyeSquint_R", [](const Vector3d& p, const VI&) { return CrowsFeet(p); },
       [](LidState& l) {
         l.upper[0] = kUpperLidOpen - 0.6;
         l.lower[0] = kLowerLidOpen - 1.4;
       }},
      {"cheekSquint_L", "cheekSquint_R",
       [](const Vector3d& p, const VI&) { return Vector3d(CheekRaise(p, 4.0) + 0.5 * CrowsFeet(p)); },
       [](LidState& l) { l.lower[0] = kLowerLidOpen - 0.7; }},
      {"noseSneer_L", "noseSneer_R",
       [](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 12.0, 7.0) * Gauss(p.y(), -38.0, 10.0) * Front(p);
         const double g2 = Gauss(p.x(), 16.0, 9.0) * Gauss(p.y(), 18.0, 8.0) * Front(p);
         return Vector3d(0.5 * gg - 0.5 * g2, 5.0 * gg - 2.0 * g2, 0.3 * gg);
       },
       {}},
  };
}

// Left/right pairs of the mouth (`y_mouth`: the stomion height).
std::vector<ExpressionDef> MouthExpressions(double y_mouth) {
  return {
      {"mouthSmile_L", "mouthSmile_R",
       [y_mouth](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 26.0, 11.0) * Gauss(p.y(), y_mouth, 11.0) * Front(p);
         return Vector3d(Vector3d(7.0 * gg, 7.5 * gg, -3.0 * gg) + CheekRaise(p, 3.5) + 0.5 * CrowsFeet(p));
       },
       [](LidState& l) { l.lower[0] = kLowerLidOpen - 0.5; }},
      {"mouthFrown_L", "mouthFrown_R",
       [y_mouth](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 25.0, 9.0) * Gauss(p.y(), y_mouth - 4.0, 10.0) * Front(p);
         return Vector3d(0.8 * gg, -4.5 * gg, -0.6 * gg);
       },
       {}},
      {"mouthStretch_L", "mouthStretch_R",
       [y_mouth](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 27.0, 12.0) * Gauss(p.y(), y_mouth - 4.0, 12.0) * Front(p);
         return Vector3d(4.0 * gg, -2.5 * gg, -1.5 * gg);
       },
       {}},
      {"mouthPress_L", "mouthPress_R",
       [y_mouth](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 10.0, 14.0) * Gauss(p.y(), y_mouth, 8.0) * Front(p);
         return Vector3d(0.0, -1.5 * std::tanh((p.y() - y_mouth) / 2.5) * gg, -1.2 * gg);
       },
       {}},
      {"mouthUpperUp_L", "mouthUpperUp_R",
       [y_mouth](const Vector3d& p, const VI& vi) {
         const double gg =
             Gauss(p.x(), 11.0, 9.0) * Gauss(p.y(), y_mouth + 6.0, 8.0) * Front(p) * MouthUpper(p, vi, y_mouth);
         return Vector3d(0.0, 3.5 * gg, 1.0 * gg);
       },
       {}},
      {"mouthLowerDown_L", "mouthLowerDown_R",
       [y_mouth](const Vector3d& p, const VI& vi) {
         const double gg = Gauss(p.x(), 11.0, 9.0) * Gauss(p.y(), y_mouth - 8.0, 9.0) * Front(p) *
                           (1.0 - MouthUpper(p, vi, y_mouth));
         return Vector3d(0.0, -4.0 * gg, 0.5 * gg);
       },
       {}},
      {"mouthDimple_L", "mouthDimple_R",
       [y_mouth](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 28.0, 8.0) * Gauss(p.y(), y_mouth, 9.0) * Front(p);
         return Vector3d(2.0 * gg, 0.0, -2.5 * gg);
       },
       {}},
      {"mouthLeft", "mouthRight",
       [y_mouth](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 0.0, 22.0) * Gauss(p.y(), y_mouth - 1.0, 11.0) * Front(p);
         return Vector3d(5.0 * gg, 0.0, 0.0);
       },
       {}},
  };
}

// Left/right pairs of the jaw and the gaze (the eyeballs rotate about their centre).
std::vector<ExpressionDef> JawSideAndGazeExpressions() {
  return {
      {"jawLeft", "jawRight",
       [](const Vector3d& p, const VI& vi) { return Vector3d(5.0 * JawWeight(p, vi), 0.0, 0.0); }, {}},
      {"eyeLookUp_L", "eyeLookUp_R",
       [](const Vector3d& p, const VI& vi) {
         if (!IsLeftEyePart(vi.part)) return Vector3d(Vector3d::Zero());
         return Vector3d(kEyeCentre + Eigen::AngleAxisd(-20.0 * kDeg, Vector3d::UnitX()) * (p - kEyeCentre) - p);
       },
       {}},
      {"eyeLookDown_L", "eyeLookDown_R",
       [](const Vector3d& p, const VI& vi) {
         if (!IsLeftEyePart(vi.part)) return Vector3d(Vector3d::Zero());
         return Vector3d(kEyeCentre + Eigen::AngleAxisd(25.0 * kDeg, Vector3d::UnitX()) * (p - kEyeCentre) - p);
       },
       {}},
      {"eyeLookIn_L", "eyeLookIn_R",
       [](const Vector3d& p, const VI& vi) {
         if (!IsLeftEyePart(vi.part)) return Vector3d(Vector3d::Zero());
         return Vector3d(kEyeCentre + Eigen::AngleAxisd(-25.0 * kDeg, Vector3d::UnitY()) * (p - kEyeCentre) - p);
       },
       {}},
      {"eyeLookOut_L", "eyeLookOut_R",
       [](const Vector3d& p, const VI& vi) {
         if (!IsLeftEyePart(vi.part)) return Vector3d(Vector3d::Zero());
         return Vector3d(kEyeCentre + Eigen::AngleAxisd(25.0 * kDeg, Vector3d::UnitY()) * (p - kEyeCentre) - p);
       },
       {}},
  };
}

// Unpaired (symmetric) shapes: jaw, cheeks and lips (`jaw_rad`: jawOpen's rotation).
std::vector<ExpressionDef> CentreExpressions(double y_mouth, double jaw_rad) {
  return {
      {"jawOpen", "",
       [jaw_rad](const Vector3d& p, const VI& vi) {
         return Vector3d(RotateX(p, kJawHinge, jaw_rad * JawWeight(p, vi)) - p);
       },
       {}},
      {"jawForward", "",
       [](const Vector3d& p, const VI& vi) { return Vector3d(0.0, 0.0, 5.0 * JawWeight(p, vi)); }, {}},
      {"cheekPuff", "",
       [](const Vector3d& p, const VI&) {
         const double gg = Gauss(std::abs(p.x()), 40.0, 14.0) * Gauss(p.y(), -55.0, 15.0) * Front(p);
         return Vector3d((p.x() < 0 ? -3.0 : 3.0) * gg, 0.0, 2.5 * gg);
       },
       {}},
      {"mouthPucker", "",
       [y_mouth](const Vector3d& p, const VI&) {
         const double gg = Gauss(p.x(), 0.0, 18.0) * Gauss(p.y(), y_mouth, 9.0) * Front(p);
         return Vector3d(-0.3 * p.x() * gg, 0.0, 6.0 * gg);
       },
       {}},
      {"mouthFunnel", "",
       [y_mouth](const Vector3d& p, const VI& vi) {
         const double gg = Gauss(p.x(), 0.0, 18.0) * Gauss(p.y(), y_mouth, 9.0) * Front(p);
         const double up = 2.0 * MouthUpper(p, vi, y_mouth) - 1.0;
         return Vector3d(-0.15 * p.x() * gg, 2.0 * up * gg, 4.0 * gg);
       },
       {}},
      {"mouthShrugLower", "",
       [y_mouth](const Vector3d& p, const VI& vi) {
         const double gg = Gauss(p.x(), 0.0, 20.0) * Gauss(p.y(), y_mouth - 18.0, 12.0) * Front(p) *
                           (1.0 - MouthUpper(p, vi, y_mouth));
         return Vector3d(0.0, 3.0 * gg, 1.5 * gg);
       },
       {}},
      {"mouthShrugUpper", "",
       [y_mouth](const Vector3d& p, const VI& vi) {
         const double gg =
             Gauss(p.x(), 0.0, 18.0) * Gauss(p.y(), y_mouth + 6.0, 8.0) * Front(p) * MouthUpper(p, vi, y_mouth);
         return Vector3d(0.0, 2.0 * gg, 0.8 * gg);
       },
       {}},
  };
}

// All expression definitions in the rig's order.
std::vector<ExpressionDef> ExpressionDefs(double y_mouth, double jaw_rad) {
  std::vector<ExpressionDef> defs = UpperFaceExpressions();
  for (const auto& group : {MouthExpressions(y_mouth), JawSideAndGazeExpressions(), CentreExpressions(y_mouth, jaw_rad)}) {
    defs.insert(defs.end(), group.begin(), group.end());
  }
  return defs;
}

// An expression's displacement of every vertex: its field (eyeballs, ears and
// teeth excepted) plus the lid rims its lid openings move.
MatX3d EvalExpression(const ExpressionDef& d, const HeadModel& head, const Builder& b) {
  const Grid& g = head.grid;
  const int nv = static_cast<int>(b.V.size());
  const LidState neutral_lids;
  MatX3d D = MatX3d::Zero(nv, 3);
  LidState lids;
  if (d.lids) d.lids(lids);
  for (int v = 0; v < nv; ++v) {
    const VertexInfo& vi = b.info[v];
    // Eyeballs, ears and teeth do not deform with the skin (teeth follow the jaw).
    if (d.field && vi.part != kEars) {
      const bool eye = IsEyePart(vi.part), teeth = vi.part == kTeethUpper || vi.part == kTeethLower;
      if ((!eye || d.name.rfind("eyeLook", 0) == 0) && (!teeth || d.name.rfind("jaw", 0) == 0)) {
        D.row(v) = d.field(b.V[v], vi).transpose();
      }
    }
    if (d.lids && vi.grid && vi.part == kFace) {
      const double psi = NodePsi(g, vi.r, vi.c), phi = g.phi[vi.c];
      if (EyeWarp(psi, phi, vi.eye_side, lids) != EyeWarp(psi, phi, vi.eye_side, neutral_lids)) {
        D.row(v) += (head.NodePosition(vi, lids) - b.V[v]).transpose();
      }
    }
  }
  return D;
}

// Expressions: each definition, then the mirror image of a pair's, as columns of
// the expression basis.
void AddExpressions(const std::vector<ExpressionDef>& defs, const HeadModel& head, const Builder& b,
                    const std::vector<int>& mirror, FaceRig& rig) {
  const int nv = static_cast<int>(b.V.size());
  std::vector<MatX3d> expr;
  for (const auto& d : defs) {
    const MatX3d D = EvalExpression(d, head, b);
    rig.expression_names.push_back(d.name);
    expr.push_back(D);
    if (!d.mirror.empty()) {
      MatX3d M(nv, 3);
      for (int v = 0; v < nv; ++v) {
        const int w = mirror[v];
        M.row(v) = Eigen::RowVector3d(-D(w, 0), D(w, 1), D(w, 2));
      }
      rig.expression_names.push_back(d.mirror);
      expr.push_back(M);
    }
  }
  rig.expression_basis.resize(3 * nv, static_cast<Eigen::Index>(expr.size()));
  for (size_t e = 0; e < expr.size(); ++e) {
    for (int v = 0; v < nv; ++v) {
      for (int k = 0; k < 3; ++k) rig.expression_basis(3 * v + k, static_cast<Eigen::Index>(e)) = static_cast<float>(expr[e](v, k));
    }
  }
}

// ---------------------------------------------------------------------------
// Identity modes: symmetric smooth fields, ±1 ≈ ±1 standard deviation.

struct IdentityDef {
  std::string name;
  std::function<Vector3d(const Vector3d&, const VertexInfo&)> field;
};

double Sign(double x) { return x < 0.0 ? -1.0 : 1.0; }

// The head's size and proportions, the forehead, brows and eyes.
std::vector<IdentityDef> HeadAndEyeIdentityModes() {
  return {
      {"head_width", [](const Vector3d& p, const VI&) { return Vector3d(3.5 * p.x() / 75.0, 0, 0); }},
      {"face_width",
       [](const Vector3d& p, const VI&) {
         return Vector3d(3.0 * p.x() / 65.0 * Gauss(p.y(), -15.0, 30.0) * Smoothstep(-30.0, 30.0, p.z()), 0, 0);
       }},
      {"face_length",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, -5.0 * Smoothstep(10.0, -118.0, p.y()) * Smoothstep(-60.0, 20.0, p.z()), 0);
       }},
      {"head_depth", [](const Vector3d& p, const VI&) { return Vector3d(0, 0, 4.0 * p.z() / 100.0); }},
      {"head_height", [](const Vector3d& p, const VI&) { return Vector3d(0, 5.0 * Smoothstep(10.0, 115.0, p.y()), 0); }},
      {"forehead_slope",
       [](const Vector3d& p, const VI&) { return Vector3d(0, 0, -4.0 * Smoothstep(25.0, 95.0, p.y()) * Front(p)); }},
      {"brow_ridge",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, 0, 2.5 * Gauss(std::abs(p.x()), 28.0, 18.0) * Gauss(p.y(), 22.0, 7.0) * Front(p));
       }},
      {"eye_spacing",
       [](const Vector3d& p, const VI&) {
         return Vector3d(2.0 * Sign(p.x()) * Gauss(std::abs(p.x()), 32.0, 14.0) * Gauss(p.y(), 0.0, 14.0) * Front(p), 0, 0);
       }},
      {"eye_size",
       [](const Vector3d& p, const VI&) {
         const Vector3d e(p.x() < 0 ? -kEyeCentre.x() : kEyeCentre.x(), kEyeCentre.y(), p.z());
         const double gg = Gauss(p.x() - e.x(), 0.0, 12.0) * Gauss(p.y(), 0.0, 10.0) * Front(p);
         return Vector3d(0.18 * (p - e).x() * gg, 0.18 * (p - e).y() * gg, 0.0);
       }},
      {"eye_depth",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, 0, -2.0 * Gauss(std::abs(p.x()), 32.0, 14.0) * Gauss(p.y(), 0.0, 12.0) * Front(p));
       }},
  };
}

// The nose and the cheeks.
std::vector<IdentityDef> NoseAndCheekIdentityModes() {
  return {
      {"nose_length",
       [](const Vector3d& p, const VI&) {
         const double prof = Smoothstep(2.0, -42.0, p.y()) * (1.0 - Smoothstep(-44.0, -62.0, p.y()));
         return Vector3d(0, -3.0 * Gauss(p.x(), 0.0, 13.0) * prof * Front(p), 0);
       }},
      {"nose_width",
       [](const Vector3d& p, const VI&) {
         return Vector3d(2.2 * Sign(p.x()) * Gauss(std::abs(p.x()), 14.0, 7.0) * Gauss(p.y(), -47.0, 8.0) * Front(p), 0, 0);
       }},
      {"nose_projection",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, 0, 3.0 * Gauss(p.x(), 0.0, 10.0) * Gauss(p.y(), -36.0, 13.0) * Front(p));
       }},
      {"nose_bridge",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, 0, 2.0 * Gauss(p.x(), 0.0, 8.0) * Gauss(p.y(), -10.0, 12.0) * Front(p));
       }},
      {"nose_tip_rotation",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, 2.0 * Gauss(p.x(), 0.0, 9.0) * Gauss(p.y(), -46.0, 7.0) * Front(p), 0);
       }},
      {"cheekbones",
       [](const Vector3d& p, const VI&) {
         const double gg = 2.5 * Gauss(std::abs(p.x()), 48.0, 14.0) * Gauss(p.y(), -12.0, 12.0) * Front(p);
         return Vector3d(0.7 * Sign(p.x()) * gg, 0, 0.7 * gg);
       }},
      {"cheek_fullness",
       [](const Vector3d& p, const VI&) {
         const double gg = 3.0 * Gauss(std::abs(p.x()), 40.0, 14.0) * Gauss(p.y(), -55.0, 16.0) * Front(p);
         return Vector3d(0.6 * Sign(p.x()) * gg, 0, 0.8 * gg);
       }},
  };
}

// The jaw, chin, lips (`y_mouth`: the stomion height), midface, ears and neck.
std::vector<IdentityDef> JawMouthEarAndNeckIdentityModes(double y_mouth) {
  return {
      {"jaw_width",
       [](const Vector3d& p, const VI&) {
         return Vector3d(4.0 * Sign(p.x()) * Gauss(std::abs(p.x()), 50.0, 18.0) * Gauss(p.y(), -85.0, 20.0) *
                             Smoothstep(-50.0, 0.0, p.z()),
                         0, 0);
       }},
      {"chin_projection",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, 0, 3.0 * Gauss(p.x(), 0.0, 16.0) * Gauss(p.y(), -108.0, 14.0) * Front(p));
       }},
      {"chin_height",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, -3.0 * Smoothstep(-86.0, -118.0, p.y()) * Gauss(p.x(), 0.0, 35.0) * Front(p), 0);
       }},
      {"lip_fullness",
       [y_mouth](const Vector3d& p, const VI& vi) {
         const double gg = Gauss(p.x(), 0.0, 18.0) * Gauss(p.y(), y_mouth, 7.0) * Front(p);
         const double up = vi.mouth_side != 0 ? 0.0 : std::tanh((p.y() - y_mouth) / 3.0);
         return Vector3d(0, 1.0 * up * gg, 1.8 * gg);
       }},
      {"mouth_width",
       [y_mouth](const Vector3d& p, const VI&) {
         return Vector3d(3.0 * Sign(p.x()) * Gauss(std::abs(p.x()), 25.0, 10.0) * Gauss(p.y(), y_mouth, 10.0) * Front(p), 0, 0);
       }},
      {"upper_lip_height",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, -2.5 * Smoothstep(-55.0, -72.0, p.y()) * Gauss(p.x(), 0.0, 40.0) * Smoothstep(-40.0, 30.0, p.z()), 0);
       }},
      {"midface_depth",
       [](const Vector3d& p, const VI&) {
         return Vector3d(0, 0, 3.0 * Gauss(p.y(), -30.0, 25.0) * Gauss(p.x(), 0.0, 40.0) * Front(p));
       }},
      {"ear_protrusion",
       [](const Vector3d& p, const VI& vi) {
         if (vi.part != kEars) return Vector3d(Vector3d::Zero());
         return Vector3d(4.0 * Sign(p.x()) * Smoothstep(-5.0, -30.0, p.z()), 0, 0);
       }},
      {"neck_width",
       [](const Vector3d& p, const VI&) { return Vector3d(4.0 * p.x() / 55.0 * Smoothstep(-120.0, -170.0, p.y()), 0, 0); }},
  };
}

// The identity modes as columns of the identity basis. Eyeballs move rigidly with
// the field at their centre.
void AddIdentityModes(double y_mouth, const Builder& b, FaceRig& rig) {
  std::vector<IdentityDef> ids = HeadAndEyeIdentityModes();
  for (const auto& group : {NoseAndCheekIdentityModes(), JawMouthEarAndNeckIdentityModes(y_mouth)}) {
    ids.insert(ids.end(), group.begin(), group.end());
  }
  const int nv = static_cast<int>(b.V.size());
  rig.identity_basis.resize(3 * nv, static_cast<Eigen::Index>(ids.size()));
  for (size_t k = 0; k < ids.size(); ++k) {
    rig.identity_names.push_back(ids[k].name);
    for (int v = 0; v < nv; ++v) {
      const VertexInfo& vi = b.info[v];
      Vector3d d;
      if (IsEyePart(vi.part)) {
        const Vector3d c(IsLeftEyePart(vi.part) ? kEyeCentre.x() : -kEyeCentre.x(), kEyeCentre.y(), kEyeCentre.z());
        VertexInfo face_vi;
        d = ids[k].field(c, face_vi);
      } else {
        d = ids[k].field(b.V[v], vi);
      }
      for (int j = 0; j < 3; ++j) rig.identity_basis(3 * v + j, static_cast<Eigen::Index>(k)) = static_cast<float>(d[j]);
    }
  }
}

// ---------------------------------------------------------------------------
// Landmarks (iBUG 68).

// Where landmarks are looked for: the face part's interior vertices, with the
// neutral's vertex normals `N`.
struct LandmarkSearch {
  const Grid& g;
  const Builder& b;
  MatX3d N;

  bool InteriorFace(int v) const {
    const VertexInfo& vi = b.info[v];
    return vi.part == kFace && g.InteriorFaceNode(vi.r, vi.c);
  }

  // Nearest front-facing face vertex to a frontal (x, y) target.
  int NearestXy(double x, double y) const {
    const int nv = static_cast<int>(b.V.size());
    int best = -1;
    double bd = 1e30;
    for (int v = 0; v < nv; ++v) {
      if (!InteriorFace(v) || b.V[v].z() < 0.0 || N(v, 2) < 0.25 || b.info[v].mouth_side < 0 || b.info[v].eye_side < 0) continue;
      const double d = std::hypot(b.V[v].x() - x, b.V[v].y() - y);
      if (d < bd) {
        bd = d;
        best = v;
      }
    }
    return best;
  }
};

// Jaw contour (ibug 1–17): the face outline seen from the front (the extreme
// front-facing vertex along many directions in the image plane, from the subject's
// right at ear level, under the chin, to the left), resampled to 17 points at
// equal arc length as annotators space them.
void PlaceJawContour(const LandmarkSearch& s, std::vector<int>& lm) {
  const Builder& b = s.b;
  const int nv = static_cast<int>(b.V.size());
  std::vector<int> outline;
  const Vector2d centre(0.0, -18.0);
  for (int k = 0; k <= 360; ++k) {
    const double a = (180.0 + 180.0 * k / 360.0) * kDeg;
    const Vector2d dir(std::cos(a), std::sin(a));
    int best = -1;
    double bd = -1e30;
    for (int v = 0; v < nv; ++v) {
      if (!s.InteriorFace(v) || b.V[v].y() > -8.0 || b.info[v].mouth_side < 0 || s.N(v, 2) < 0.1) continue;
      const double d = (Vector2d(b.V[v].x(), b.V[v].y()) - centre).dot(dir);
      if (d > bd) {
        bd = d;
        best = v;
      }
    }
    if (best >= 0 && (outline.empty() || outline.back() != best)) outline.push_back(best);
  }
  Require(outline.size() >= 17, "BuildProceduralRig: the face outline is too short for the jaw landmarks");
  std::vector<double> arc(outline.size(), 0.0);
  for (size_t i = 1; i < outline.size(); ++i) {
    arc[i] = arc[i - 1] + (b.V[outline[i]] - b.V[outline[i - 1]]).head<2>().norm();
  }
  for (int k = 0; k < 17; ++k) {
    const double target = arc.back() * k / 16.0;
    size_t i = 0;
    while (i + 1 < arc.size() && std::abs(arc[i + 1] - target) <= std::abs(arc[i] - target)) ++i;
    lm[1 + k] = outline[i];
  }
}

// Brows (18–22 the subject's right, outer to inner; 23–27 left, inner to outer),
// the nose bridge 28–31 (nasion to tip) and the lower nose 32–36.
void PlaceBrowAndNoseLandmarks(const LandmarkSearch& s, std::vector<int>& lm) {
  const double brow_x[5] = {50, 42, 33, 24, 15}, brow_y[5] = {17, 23, 25.5, 25, 22};
  for (int k = 0; k < 5; ++k) {
    lm[18 + k] = s.NearestXy(-brow_x[k], brow_y[k]);
    lm[27 - k] = s.NearestXy(brow_x[k], brow_y[k]);
  }
  const double bridge_y[4] = {0.0, -13.0, -27.0, -41.0};
  for (int k = 0; k < 4; ++k) lm[28 + k] = s.NearestXy(0.0, bridge_y[k]);
  const double nose_x[5] = {-13.0, -7.0, 0.0, 7.0, 13.0}, nose_y[5] = {-51.0, -54.0, -55.0, -54.0, -51.0};
  for (int k = 0; k < 5; ++k) lm[32 + k] = s.NearestXy(nose_x[k], nose_y[k]);
}

// Eyes (37–48): corners and rim vertices of the slits (upper and lower at the same
// columns, so that a blink brings them together).
void PlaceEyeLandmarks(const Grid& g, const GridNodes& nodes, std::vector<int>& lm) {
  auto col_at = [&](double frac) {  // left eye, fraction from inner to outer corner
    return g.eye_ci + static_cast<int>(std::lround(frac * (g.eye_co - g.eye_ci)));
  };
  auto upper = [&](int c) { return nodes.Face(g.r_eye, c); };
  auto lower_v = [&](int c) { return nodes.Lower(g.r_eye, c); };
  const int c1 = col_at(1.0 / 3.0), c2 = col_at(2.0 / 3.0);
  lm[43] = upper(g.eye_ci);
  lm[44] = upper(c1);
  lm[45] = upper(c2);
  lm[46] = upper(g.eye_co);
  lm[47] = lower_v(c2);
  lm[48] = lower_v(c1);
  lm[37] = upper(g.Mirror(g.eye_co));
  lm[38] = upper(g.Mirror(c2));
  lm[39] = upper(g.Mirror(c1));
  lm[40] = upper(g.Mirror(g.eye_ci));
  lm[41] = lower_v(g.Mirror(c1));
  lm[42] = lower_v(g.Mirror(c2));
}

// Lips (49–68): outer contour by position, corners and inner contour on the slit.
void PlaceLipLandmarks(const LandmarkSearch& s, const GridNodes& nodes, double y_mouth, std::vector<int>& lm) {
  const Grid& g = s.g;
  const Builder& b = s.b;
  const int mc = g.mouth_c, mr = g.Mirror(g.mouth_c);
  lm[49] = nodes.Face(g.r_mouth, mr);
  lm[55] = nodes.Face(g.r_mouth, mc);
  const double up_x[5] = {-15.0, -7.0, 0.0, 7.0, 15.0};
  const double up_y[5] = {y_mouth + 7.0, y_mouth + 9.5, y_mouth + 8.5, y_mouth + 9.5, y_mouth + 7.0};
  for (int k = 0; k < 5; ++k) lm[50 + k] = s.NearestXy(up_x[k], up_y[k]);
  const double lo_x[5] = {15.0, 8.0, 0.0, -8.0, -15.0};
  const double lo_y[5] = {y_mouth - 8.0, y_mouth - 10.5, y_mouth - 11.0, y_mouth - 10.5, y_mouth - 8.0};
  for (int k = 0; k < 5; ++k) lm[56 + k] = s.NearestXy(lo_x[k], lo_y[k]);
  auto slit_col = [&](double x) {  // slit column nearest to frontal x
    int best = g.c_centre;
    for (int c = mr + 1; c < mc; ++c) {
      if (std::abs(b.V[nodes.Face(g.r_mouth, c)].x() - x) < std::abs(b.V[nodes.Face(g.r_mouth, best)].x() - x)) best = c;
    }
    return best;
  };
  lm[61] = nodes.Face(g.r_mouth, mr + 1);
  lm[65] = nodes.Face(g.r_mouth, mc - 1);
  lm[62] = nodes.Face(g.r_mouth, slit_col(-10.0));
  lm[63] = nodes.Face(g.r_mouth, g.c_centre);
  lm[64] = nodes.Face(g.r_mouth, slit_col(10.0));
  lm[66] = nodes.Lower(g.r_mouth, slit_col(10.0));
  lm[67] = nodes.Lower(g.r_mouth, g.c_centre);
  lm[68] = nodes.Lower(g.r_mouth, slit_col(-10.0));
}

// Landmarks (iBUG 68) on the neutral of `rig`.
void PlaceLandmarks(const Grid& g, const GridNodes& nodes, const Builder& b, double y_mouth, FaceRig& rig) {
  const std::vector<std::string> names = IbugLandmarkNames();
  std::vector<int> lm(69, -1);
  const LandmarkSearch search{g, b, [&] {
                                TriMesh m = rig.neutral;
                                return VertexNormals(m);
                              }()};
  PlaceJawContour(search, lm);
  PlaceBrowAndNoseLandmarks(search, lm);
  PlaceEyeLandmarks(g, nodes, lm);
  PlaceLipLandmarks(search, nodes, y_mouth, lm);
  for (int i = 1; i <= 68; ++i) {
    Require(lm[i] >= 0, fmt::format("BuildProceduralRig: landmark ibug_{} was not placed", i));
    rig.landmarks.push_back({names[i - 1], lm[i]});
  }
}

// ---------------------------------------------------------------------------
// Region masks.

// Landmark ibug_`i`'s texel position in a `size`² mask, and its neutral position.
Vector2d LandmarkUv(const FaceRig& rig, int i, int size) {
  const int v = rig.landmarks[rig.LandmarkIndex(fmt::format("ibug_{}", i))].vertex;
  return Vector2d(rig.neutral.UV(v, 0) * size, rig.neutral.UV(v, 1) * size);
}
Vector3d LandmarkPosition(const FaceRig& rig, int i) {
  const int v = rig.landmarks[rig.LandmarkIndex(fmt::format("ibug_{}", i))].vertex;
  return Vector3d(rig.neutral.V.row(v).transpose());
}

// Brow hair along landmarks first…last: from just below to above the landmark
// line, thicker medially.
cv::Mat BrowMask(const FaceRig& rig, int size, double px_per_mm, int first, int last) {
  auto uv_of = [&](int i) { return LandmarkUv(rig, i, size); };
  std::vector<cv::Point> poly;
  const int inner = first == 18 ? 22 : 23;
  // Brow height ~9 mm at the head tapering to ~4 mm at the tail, the landmark
  // line a little below its middle.
  auto height = [&](int i) { return 4.0 + 5.0 * Gauss(std::abs(i - inner), 0.0, 1.6); };
  for (int i = first; i <= last; ++i) {
    const Vector2d q = uv_of(i) - Vector2d(0.0, 0.55 * height(i) * px_per_mm);
    poly.emplace_back(cvRound(q.x()), cvRound(q.y()));
  }
  for (int i = last; i >= first; --i) {
    const Vector2d q = uv_of(i) + Vector2d(0.0, 0.45 * height(i) * px_per_mm);
    poly.emplace_back(cvRound(q.x()), cvRound(q.y()));
  }
  cv::Mat m = cv::Mat::zeros(size, size, CV_8UC1);
  cv::fillPoly(m, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(255), cv::LINE_8);
  return m;
}

// The convex hull of landmarks `ids`, scaled by `grow` about their centroid.
cv::Mat HullMask(const FaceRig& rig, int size, std::initializer_list<int> ids, double grow) {
  std::vector<Vector2d> pts;
  Vector2d c = Vector2d::Zero();
  for (int i : ids) {
    pts.push_back(LandmarkUv(rig, i, size));
    c += pts.back();
  }
  c /= static_cast<double>(pts.size());
  std::vector<cv::Point> poly, h;
  for (const auto& q : pts) {
    const Vector2d g2 = c + grow * (q - c);
    poly.emplace_back(cvRound(g2.x()), cvRound(g2.y()));
  }
  cv::convexHull(poly, h);
  cv::Mat m = cv::Mat::zeros(size, size, CV_8UC1);
  cv::fillConvexPoly(m, h, cv::Scalar(255));
  return m;
}

// The lips: inside the outer lip contour (ibug 49–60).
cv::Mat LipsMask(const FaceRig& rig, int size) {
  std::vector<cv::Point> lips;
  for (int i = 49; i <= 60; ++i) {
    const Vector2d q = LandmarkUv(rig, i, size);
    lips.emplace_back(cvRound(q.x()), cvRound(q.y()));
  }
  cv::Mat m = cv::Mat::zeros(size, size, CV_8UC1);
  cv::fillPoly(m, std::vector<std::vector<cv::Point>>{lips}, cv::Scalar(255), cv::LINE_8);
  return m;
}

// Region masks: the standard ones from the landmarks, plus brows and lips.
void AddRegionMasks(const ProceduralRigOptions& options, FaceRig& rig) {
  rig.regions = RegionsFromLandmarks(rig, options.region_mask_size);
  const int size = options.region_mask_size;
  // Texels per mm near the eyes (the chart is conformal, so roughly isotropic there).
  const double px_per_mm = (LandmarkUv(rig, 46, size) - LandmarkUv(rig, 43, size)).norm() /
                           (LandmarkPosition(rig, 46) - LandmarkPosition(rig, 43)).norm();
  // Cheeks: RegionsFromLandmarks' hulls include the opposite ala (ibug 32 for the
  // left cheek) and so cross the nose; these stop at the own ala.
  for (auto& r : rig.regions) {
    if (r.name == "left_cheek") r.mask = HullMask(rig, size, {47, 48, 46, 16, 15, 14, 13, 55, 36}, 0.95);
    if (r.name == "right_cheek") r.mask = HullMask(rig, size, {41, 42, 37, 2, 3, 4, 5, 49, 32}, 0.95);
  }
  rig.regions.push_back({"brow_left", BrowMask(rig, size, px_per_mm, 23, 27)});
  rig.regions.push_back({"brow_right", BrowMask(rig, size, px_per_mm, 18, 22)});
  rig.regions.push_back({"lips", LipsMask(rig, size)});
}

}  // namespace

FaceRig BuildProceduralRig(const ProceduralRigOptions& options) {
  options.Check();
  HeadModel head;
  head.grid = MakeGrid(options);
  head.hair_mm = options.hair_thickness_mm;
  const Grid& g = head.grid;
  Builder b;
  const GridNodes nodes = AddHeadGrid(head, b);
  AddEyeballs(options, b);
  AddEars(b);
  AddMouthCavity(b);
  AddTeeth(b);
  LayOutFaceChart(g, nodes, b);
  OpenSlitsInUv(nodes, b);
  FaceRig rig = RigFromBuilder(b);
  const std::vector<int> mirror = MirrorMap(b);
  const double y_mouth = StomionHeight(g, nodes, b);
  AddExpressions(ExpressionDefs(y_mouth, options.jaw_open_deg * kDeg), head, b, mirror, rig);
  AddIdentityModes(y_mouth, b, rig);
  PlaceLandmarks(g, nodes, b, y_mouth, rig);
  AddRegionMasks(options, rig);
  rig.source = "crease procedural head (synth/procedural_rig.cc), options " + OptionsToJson(options, -1);
  rig.Validate("procedural rig");
  return rig;
}

ChartDistortion MeasureFaceChartDistortion(const FaceRig& rig) {
  const int face = rig.PartIndex("face");
  Require(face >= 0 || rig.part_names.empty(), "MeasureFaceChartDistortion: the rig has no part 'face'");
  const TriMesh& m = rig.neutral;
  std::vector<double> ratio, conformal;
  double area3 = 0.0, area_uv = 0.0;
  std::vector<std::pair<double, double>> per;  // (3D area, UV area)
  int pos = 0, neg = 0;
  for (int f = 0; f < m.num_faces(); ++f) {
    bool in = true;
    for (int k = 0; k < 3; ++k) in = in && (rig.part_names.empty() || rig.vertex_part[m.F(f, k)] == face);
    if (!in) continue;
    const Vector3d p0 = m.V.row(m.F(f, 0)), p1 = m.V.row(m.F(f, 1)), p2 = m.V.row(m.F(f, 2));
    const Vector2d u0 = m.UV.row(m.F(f, 0)), u1 = m.UV.row(m.F(f, 1)), u2 = m.UV.row(m.F(f, 2));
    Eigen::Matrix<double, 3, 2> E;
    E << p1 - p0, p2 - p0;
    Eigen::Matrix2d U;
    U << u1 - u0, u2 - u0;
    const double det = U.determinant();
    (det >= 0 ? pos : neg)++;
    if (std::abs(det) < 1e-18) continue;
    const Eigen::Matrix<double, 3, 2> J = E * U.inverse();
    const Eigen::JacobiSVD<Eigen::Matrix<double, 3, 2>> svd(J);
    const Eigen::Vector2d s = svd.singularValues();
    conformal.push_back(s[0] / std::max(s[1], 1e-12));
    const double a3 = 0.5 * (p1 - p0).cross(p2 - p0).norm(), auv = 0.5 * std::abs(det);
    per.emplace_back(a3, auv);
    area3 += a3;
    area_uv += auv;
  }
  ChartDistortion out;
  out.triangles = static_cast<int>(per.size());
  out.flipped = std::min(pos, neg);
  if (per.empty()) return out;
  const double mean = area3 / area_uv;
  for (const auto& [a3, auv] : per) ratio.push_back(a3 / auv / mean);
  auto pct = [](std::vector<double> x, double q) {
    std::sort(x.begin(), x.end());
    return x[static_cast<size_t>(std::lround(q * (x.size() - 1)))];
  };
  out.area_ratio_p05 = pct(ratio, 0.05);
  out.area_ratio_p50 = pct(ratio, 0.5);
  out.area_ratio_p95 = pct(ratio, 0.95);
  out.area_ratio_min = *std::min_element(ratio.begin(), ratio.end());
  out.area_ratio_max = *std::max_element(ratio.begin(), ratio.end());
  double sum = 0.0;
  for (double c : conformal) sum += c;
  out.conformal_mean = sum / static_cast<double>(conformal.size());
  out.conformal_p95 = pct(conformal, 0.95);
  return out;
}

MatX3d ProceduralRigPreviewColors(const FaceRig& rig) {
  const int n = rig.num_vertices();
  MatX3d colors(n, 3);
  const Eigen::RowVector3d skin(0.62, 0.40, 0.31), lip(0.50, 0.20, 0.19), brow(0.10, 0.06, 0.04);
  // Soft region weights: the masks blurred over ~1.5 % of the chart and sampled at
  // the vertex UVs, so that per-vertex colours do not show the grid's steps.
  auto soft = [&](const std::string& name) {
    const RegionMask* r = rig.FindRegion(name);
    if (!r) return cv::Mat();
    cv::Mat f;
    r->mask.convertTo(f, CV_32F, 1.0 / 255.0);
    const int k = std::max(3, (r->mask.rows / 64) | 1);
    cv::GaussianBlur(f, f, cv::Size(k, k), 0.0);
    return f;
  };
  const cv::Mat lips_w = soft("lips"), brow_l = soft("brow_left"), brow_r = soft("brow_right");
  auto sample = [](const cv::Mat& m, const Vector2d& uv) {
    if (m.empty() || uv.x() < 0.0 || uv.x() > 1.0 || uv.y() < 0.0 || uv.y() > 1.0) return 0.0;
    const int i = std::clamp(static_cast<int>(uv.x() * m.cols), 0, m.cols - 1);
    const int j = std::clamp(static_cast<int>(uv.y() * m.rows), 0, m.rows - 1);
    return static_cast<double>(m.at<float>(j, i));
  };
  for (int v = 0; v < n; ++v) {
    const std::string part = rig.part_names.empty() ? "face" : rig.part_names[rig.vertex_part[v]];
    Eigen::RowVector3d c = skin;
    if (part == "face") {
      const Vector2d uv = rig.neutral.UV.row(v).transpose();
      const double wl = std::min(1.0, 1.5 * sample(lips_w, uv));
      const double wb = std::min(1.0, 2.0 * std::max(sample(brow_l, uv), sample(brow_r, uv)));
      c = (1.0 - wl) * c + wl * lip;
      c = (1.0 - wb) * c + wb * brow;
    } else if (part == "hair") {
      c = Eigen::RowVector3d(0.07, 0.045, 0.03);
    } else if (part.rfind("eyeball", 0) == 0) {
      c = Eigen::RowVector3d(0.80, 0.78, 0.74);
    } else if (part.rfind("iris", 0) == 0) {
      c = Eigen::RowVector3d(0.20, 0.12, 0.06);
    } else if (part.rfind("pupil", 0) == 0) {
      c = Eigen::RowVector3d(0.01, 0.01, 0.01);
    } else if (part == "mouth_cavity") {
      c = Eigen::RowVector3d(0.05, 0.01, 0.01);
    } else if (part.rfind("teeth", 0) == 0) {
      c = Eigen::RowVector3d(0.75, 0.72, 0.62);
    }
    colors.row(v) = c;
  }
  return colors;
}

cv::Mat RigContactSheet(const FaceRig& rig, int tile) {
  struct View {
    double azimuth;
    std::vector<std::pair<std::string, double>> weights;
  };
  const std::vector<View> views = {
      {0.0, {}},
      {35.0, {}},
      {90.0, {}},
      {0.0, {{"mouthSmile_L", 1.0}, {"mouthSmile_R", 1.0}, {"cheekSquint_L", 0.6}, {"cheekSquint_R", 0.6}}},
      {30.0, {{"jawOpen", 0.8}, {"browInnerUp_L", 1.0}, {"browInnerUp_R", 1.0}, {"browOuterUp_L", 0.6},
              {"browOuterUp_R", 0.6}}},
      {-20.0, {{"eyeBlink_L", 1.0}, {"eyeSquint_R", 1.0}, {"browDown_L", 1.0}, {"browDown_R", 1.0},
               {"noseSneer_L", 0.8}, {"noseSneer_R", 0.8}, {"mouthFrown_L", 0.7}, {"mouthFrown_R", 0.7}}},
  };
  const MatX3d colors = ProceduralRigPreviewColors(rig);
  const int cols = 3, rows = static_cast<int>((views.size() + cols - 1) / cols);
  cv::Mat sheet(rows * tile, cols * tile, CV_32FC3, cv::Scalar(0, 0, 0));
  for (size_t i = 0; i < views.size(); ++i) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.num_expressions());
    for (const auto& [name, value] : views[i].weights) {
      const int e = rig.ExpressionIndex(name);
      if (e >= 0) w[e] = value;
    }
    PreviewRenderOptions o;
    o.width = o.height = tile;
    o.azimuth_deg = views[i].azimuth;
    o.elevation_deg = 5.0;
    o.margin = 0.72;
    o.key_light_dir = {-0.4, 0.5, 0.9};
    const PreviewRender r = RenderPreview(rig.Evaluate({}, w), o, colors);
    r.image.copyTo(sheet(cv::Rect(static_cast<int>(i % cols) * tile, static_cast<int>(i / cols) * tile, tile, tile)));
  }
  return sheet;
}


}  // namespace crease
