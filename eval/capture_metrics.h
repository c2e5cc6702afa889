// Core metrics of online capture against the studio's ground truth (issue 6,
// `crease eval --capture DIR --dataset DIR`):
//
//   tracking (Fig. 11)   2D error of the projected vertices of L^t and of L~^t
//                        (mean over the visible face-chart vertices, px), their
//                        3D vertex error in the camera frame (mm) raw and after a
//                        rigid alignment to the truth (Kabsch), and the jitter:
//                        the change of the 2D error vector from one frame to the
//                        next (px), which is 0 for a constant bias and grows with
//                        temporal instability;
//   displacement D^t     against the studio's medium-scale expression displacement
//                        (the quantity the paper regresses): RMSE, Pearson
//                        correlation and amplitude ratio (RMS of D^t / RMS of the
//                        truth), over the face and over the wrinkle regions, raw
//                        and in the wrinkle band (both maps minus their Gaussian
//                        blur of band_mm, as training validates: D^t also carries
//                        the broad shape the compatible rig gives up, Sec. 4.1),
//                        and its jitter (RMS of the frame-to-frame change of the
//                        band error);
//   surface H^t          every surface_every-th frame: H^t, rigidly aligned to the
//                        true coarse mesh through L~^t's face vertices (so pose and
//                        depth errors of the monocular tracker do not swamp the
//                        detail), against the true high-resolution surface rebuilt
//                        from the dataset's actor: distance along H^t's normal (mm)
//                        and the angle between H^t's normal and the true surface's
//                        normal (degrees), for three layers — L~^t alone, L~^t +
//                        D^HF, and the full H^t = L~^t + D^t + D^HF; and, when the
//                        truth D* is known, L~^t + D* + D^HF: what a perfect
//                        regressor would reach on this measure;
//   band normals         the same layers' normal error in the wrinkle band
//                        (BandNormalError), every frame with D^t and D*: the
//                        surface measure above also counts the static shape, the
//                        pores and the tracker's error, which no D^t can remove
//                        (issue 17, section 3);
//   speed                per-stage times and frames per second from the capture.
//
// Results: eval.json (summary and per-frame), eval_frames.csv, eval.md.
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/ray_caster.h"
#include "core/tri_mesh.h"
#include "core/ibug.h"
#include "eval/appearance_ceiling.h"
#include "pipeline/capture/capture_io.h"
#include "pipeline/training/detail_extraction.h"

namespace crease {

struct MesoscopicOptions;

// What Sec. 5.3's DoG makes of the skin's colour alone: MesoscopicMap (`options`)
// of the Rec. 709 luminance of a linear albedo map (CV_32FC3 RGB or CV_32FC1, any
// square size, resampled to `seen`'s), over the texels `seen` (CV_8U, square,
// non-zero = seen). Sec. 5.3 reads dark as deep: where the albedo varies at the
// DoG's scale, the capture's D^HF follows this map rather than the relief.
// Throws Error on a non-square albedo or a wrong type.
cv::Mat AlbedoMesoscopicMap(const cv::Mat& albedo, const cv::Mat& seen, const MesoscopicOptions& options);

class OptionVisitor;

// CaptureEvalOptions::detail_truth (see there).
enum class DetailTruthKind { kExtraction, kWrinkleLayer };
constexpr std::array<const char*, 2> OptionEnumNames(DetailTruthKind) { return {"extraction", "wrinkle-layer"}; }

struct CaptureEvalOptions {
  // Surface metrics of H^t on every this-many-th tracked frame (rebuilding the
  // true high-resolution surface costs ~0.35 s per frame, as much as all the other
  // metrics of ~3 frames). 0 = none.
  int surface_every = 10;
  // σ of the wrinkle band, mm on the face (as TrainingOptions::validation_band_mm).
  double band_mm = 2.0;
  // The band normal error's lower edge: relief finer than this Gaussian σ, mm on the
  // face, is left out (the pores of the studio's surface and of D^HF, Sec. 5.3,
  // whose own bandwidth is 0.3 mm), so the measure sees the wrinkles.
  double normal_band_low_mm = 0.5;
  // The truth D^t is scored against (eval/detail_truth.h): "extraction" = Sec. 4.1's
  // detail, the wrinkle layer beyond the neutral plus the coarse expression's medium
  // band that the compatible rig gives up (what training extracts and the cascade
  // regresses; needs the dataset's actor.json); "wrinkle-layer" = the dataset's
  // expression displacement maps (the studio's wrinkle lines alone, the definition
  // of crease ≤ 0.3). The wrinkle layer alone is reported beside either.
  DetailTruthKind detail_truth = DetailTruthKind::kExtraction;
  // When set, the truth D^t is scored against is written here per frame
  // (NNNNNN.exr, mm, CV_32F, the capture's map resolution), to look at beside D^t,
  // with the D^HF of the true albedo (mesoscopic_albedo.exr, AlbedoMesoscopicMap)
  // when the dataset has one, and the wrinkle regions' mask (wrinkle_mask.png, 255
  // where the wrinkle metrics score a texel).
  std::string truth_maps_dir;
  // The regions of the wrinkle metrics (rig region masks).
  std::vector<std::string> wrinkle_regions = {"forehead", "glabella", "left_eye", "right_eye", "left_cheek",
                                              "right_cheek"};
  // The wrinkle regions without a margin (mm) along the chart's open edges (the lid margins,
  // lip rims, nostrils; AwayFromRims): every metric over the wrinkle regions then scores
  // the skin between them only. 0 = the whole regions (the issue 17 figures).
  double rim_margin_mm = 0.0;
  // Rays from H^t farther than this from the true surface count as misses, mm.
  double surface_max_distance_mm = 5.0;
  // Resolution of the H^t grid rebuilt for the surface metrics (hifi_mesh_resolution).
  int surface_mesh_resolution = 256;
  // The base of that H^t: its triangles Phong-tessellated with this shape factor
  // (HifiMeshOptions::phong_alpha; 0 = flat, as the capture's default).
  double surface_phong_alpha = 0.0;
  int max_frames = -1;  // evaluate at most this many frames (−1 = all)
  // A frame counts as active for the pooled displacement metrics when the true
  // wrinkle-band RMS over the wrinkle regions reaches this, mm.
  double active_reference_rms_mm = 0.005;
  // Wrinkle offset (the slide of Fig. 14): the vertical shift of D^t's wrinkle band
  // against the truth's in this region that maximises their correlation, searched
  // within ±offset_search_mm.
  // Rung A of the detail ladder: the appearance ceiling (eval/appearance_ceiling.h),
  // measured when the truth D* is known.
  AppearanceCeilingOptions appearance;
  // The truth registered through the image (eval/registered_truth.h): D^t also
  // against the truth the capture's L~^t sees at each texel, when D* is known.
  bool registered_truth = true;
  std::string offset_region = "forehead";
  double offset_search_mm = 4.0;
  double offset_min_correlation = 0.2;  // below: the lines do not match at any shift; not measured
  // A frame counts as "face visible" for the loss metrics when at least this
  // fraction of the face-chart vertices is visible in the ground truth.
  double visible_face_fraction = 0.5;
  // The error-vector picture (Fig. 11): this frame (−1: the first tracked frame from
  // the middle of the sequence on); vectors drawn magnified by vectors_scale.
  int vectors_frame = -1;
  double vectors_scale = 2.0;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Normal error in the wrinkle band (issue 17): the mean angle, degrees, between the
// normals of two height fields over the chart, `estimate` and `truth` (CV_32F R×R,
// mm, already limited to the band), over the texels of `mask` (CV_8U) whose central
// differences are finite; texels mm_per_texel apart. A flat estimate scores the
// truth's own mean slope angle; the truth itself scores 0. Differences from a
// surface measure: the base surface is taken flat, which at a slope of a few degrees
// changes the angles by well under 1 %.
double BandNormalError(const cv::Mat& estimate, const cv::Mat& truth, const cv::Mat& mask, double mm_per_texel);

// BandNormalError of the layers a capture adds to L~^t, against D* (means over frames).
struct BandNormals {
  double coarse_deg = 0;    // L~^t: nothing added
  double meso_deg = 0;      // L~^t + D^HF
  double detail_deg = 0;    // L~^t + D^t
  double full_deg = 0;      // H^t = L~^t + D^t + D^HF
};

struct SurfaceError {
  int samples = 0;          // H^t vertices whose normal ray hit the true surface
  double distance_mm = 0;   // mean |distance|
  double distance_rms_mm = 0;
  double normal_deg = 0;    // mean angle between the normals
  // The same over the H^t vertices whose UV lies in the wrinkle regions (issue 17:
  // a whole-face mean hides a forehead line).
  int wrinkle_samples = 0;
  double wrinkle_distance_mm = 0;
  double wrinkle_normal_deg = 0;
};

// The refinement's steps (Sec. 5.1) at its flow points, 2D error against the true
// projections, px, over the flow points visible in the truth and to the refiner:
// u^t (the projection of L^t), ũ^t after the flow and outlier steps (all, and per
// status: trusted LK, MLS-recovered, reset to u^t), the 3D fit F, and L~^t. `coarse_*`
// beside a status is u^t's error at the same points, so that a step's gain or loss
// reads off one row. Means over points (per frame) or over frames (summary).
struct FlowStageErrors {
  int points = 0, trusted = 0, recovered = 0, reset = 0;
  double coarse_px = 0, flow_px = 0, fit_px = 0, refined_px = 0;
  double trusted_px = 0, trusted_coarse_px = 0;
  double recovered_px = 0, recovered_coarse_px = 0;
  double reset_px = 0;
};

// LK from the true positions (issue 16): each pair of consecutive tracked frames, the
// flow points' true projections in frame t−1 tracked into frame t with the capture's
// LK settings (window, levels, stopping), against their true projections in t. It
// isolates LK's own error from everything the refinement does with it: `ratio` =
// Σ d·m / Σ |m|² (d: LK's displacement, m: the true one; 1 = unbiased) over all
// point-steps, the means per point-step.
struct LkFromTruth {
  int point_steps = 0;
  double motion_px = 0, error_px = 0, ratio = 0;
};

struct FrameCaptureEval {
  int frame = 0;
  bool tracked = false;
  int visible_vertices = 0;
  double coarse_px = 0, refined_px = 0;          // 2D vertex error, L^t and L~^t
  double coarse_mm = 0, refined_mm = 0;          // 3D vertex error (camera frame)
  double coarse_aligned_mm = 0, refined_aligned_mm = 0;  // after rigid alignment
  double coarse_jitter_px = 0, refined_jitter_px = 0;    // vs the previous frame (0 on the first)
  // Prior error: the tracking rig's best fit to the true coarse mesh (RigPriorFit),
  // 2D over the visible face-chart vertices and 3D over all of them.
  double prior_px = 0, prior_mm = 0;
  bool has_flow = false;  // the capture stored the refinement's flow points
  FlowStageErrors flow;
  bool has_displacement = false;
  MapComparison d_face, d_wrinkle, d_face_band, d_wrinkle_band;
  double d_jitter_mm = 0;  // band, wrinkle regions
  // Still face: the true expression equals the previous frame's (a hold) and D^t
  // exists and is not zero in both; the correlation of D^t with the previous frame's D^t in the
  // wrinkle regions (1 = the regression is stable where nothing changes).
  bool still = false;
  bool still_active = false;  // a still pair whose truth holds wrinkles (an active frame, IsActiveFrame)
  double d_still_correlation = 0;
  // Wrinkle offset in offset_region, mm (+: D^t's wrinkles lie above the true ones,
  // towards the top of the face); measured on active frames only (has_offset).
  bool has_offset = false;
  double d_offset_mm = 0, d_offset_correlation = 0;
  double true_visible_fraction = 0;  // of the face-chart vertices, ground truth
  bool has_surface = false;
  SurfaceError surface_coarse, surface_meso, surface_full;
  // L~^t + D* + D^HF on the same measure (has_surface and D* known: has_surface_truth).
  bool has_surface_truth = false;
  SurfaceError surface_truth;
  bool has_band_normals = false;  // D^t and D* known
  BandNormals band_normals;
};

// The slides of CaptureEvalSummary::truth_shift: mm on the face, and the JSON key.
struct TruthShift {
  double mm;
  const char* key;
};
constexpr std::array<TruthShift, 4> kTruthShifts = {{{0.5, "0_5mm"}, {1.0, "1mm"}, {2.0, "2mm"}, {4.0, "4mm"}}};

// Adds `truth` against itself moved by `shift_texels` (≥ 1) along +u, −u, +v and −v
// to `moments`, over the texels of `mask` (CV_8U) whose moved texel is in `mask` too:
// how fast a map decorrelates as a texture slides on the face.
void AddSlidTruthMoments(const cv::Mat& truth, const cv::Mat& mask, int shift_texels, MapMoments* moments);

struct CaptureEvalSummary {
  std::string capture, dataset;
  int frames = 0, tracked = 0, displacement_frames = 0, surface_frames = 0;
  double coarse_px = 0, refined_px = 0, coarse_mm = 0, refined_mm = 0, coarse_aligned_mm = 0, refined_aligned_mm = 0;
  double coarse_jitter_px = 0, refined_jitter_px = 0;
  double prior_px = 0, prior_mm = 0;  // the tracking rig's best fit to the truth (mean over tracked frames)
  int flow_frames = 0;
  FlowStageErrors flow;  // means over the frames with flow points (flow_frames)
  LkFromTruth lk_truth;
  // Displacement, pooled over the texels of the active frames (those whose true
  // wrinkle-band RMS in the wrinkle regions reaches active_reference_rms_mm: a
  // correlation or amplitude ratio of a frame without wrinkles means nothing).
  int active_frames = 0;
  MapComparison d_face, d_wrinkle, d_wrinkle_band;
  // The same over each of the wrinkle regions alone (name, D*, its band), in the order
  // of CaptureEvalOptions::wrinkle_regions, regions without texels left out: where on
  // the face the regressed detail matches and where it does not.
  struct RegionComparison {
    std::string region;
    MapComparison detail, band;
  };
  std::vector<RegionComparison> d_by_region;
  // The wrinkle band split by the truth's expression (DominantExpression: the
  // largest true weight, at least 0.5, its side suffix dropped; in name order),
  // active frames: against D* and, with registered_truth, against D* registered
  // through the image. Which expressions the regression finds and which it misses.
  struct ExpressionComparison {
    std::string expression;
    int frames = 0, registered_frames = 0;
    MapComparison band, registered_band;
  };
  std::vector<ExpressionComparison> d_by_expression;
  // D^t's wrinkle band against the dataset's wrinkle layer alone (the studio's lines,
  // static ones included, without the coarse band: the truth of crease ≤ 0.3),
  // wrinkle regions, frames where that layer is active.
  MapComparison d_layer_band;
  int layer_active_frames = 0;
  std::string detail_truth;  // the truth used ("extraction" or "wrinkle-layer")
  double d_jitter_mm = 0;  // mean over consecutive frame pairs
  int still_pairs = 0;               // consecutive frames of a still face (FrameCaptureEval::still)
  double d_still_correlation = 0;    // mean over them
  // The same split by the held truth: pairs of active frames (the truth holds
  // wrinkles: an expressed hold) and of the others (a neutral face, where D^t should
  // be near 0 and a per-pair correlation rewards steady false detail as much as
  // steady true detail); and one correlation pooled over every pair's texels, which
  // weights each pair by D^t's energy.
  int still_active_pairs = 0, still_inactive_pairs = 0;
  double d_still_active_correlation = 0, d_still_inactive_correlation = 0;
  double d_still_pooled_correlation = 0;
  // Wrinkle offset: mean over the measured frames, and the slide — the mean of the
  // last quarter of the measured frames minus that of the first quarter (for the
  // moving-light preset: light from above minus light from the front, Fig. 14).
  int offset_frames = 0;
  double d_offset_mm = 0, d_offset_slide_mm = 0;
  // Loss and recovery: frames with the face visible (true_visible_fraction ≥
  // visible_face_fraction) but not tracked, in all and the longest run of them
  // (the recovery time after an occlusion, in frames).
  int lost_visible_frames = 0, longest_loss_frames = 0;
  // The smallest true_visible_fraction of the sequence (did an occluder cover the face?).
  double min_visible_fraction = 1.0;
  SurfaceError surface_coarse, surface_meso, surface_full;    // means over surface frames
  int surface_truth_frames = 0;
  SurfaceError surface_truth;  // L~^t + D* + D^HF, means over its frames
  // Means over the active frames (those of the pooled displacement metrics).
  int band_normal_frames = 0;
  BandNormals band_normals;
  // D^HF (the capture's maps/mesoscopic.exr, Sec. 5.3) against the actor's true
  // mesoscopic layer (the dataset's maps/mesoscopic_displacement.exr), wrinkle
  // regions, both in the band of the band normal error; texels 0 when either is absent.
  MapComparison mesoscopic;
  // D^HF against AlbedoMesoscopicMap of the dataset's maps/albedo.exr over the same
  // seen texels, wrinkle regions, unfiltered: how much of D^HF is the skin's colour.
  // Texels 0 when either map is absent. Only its correlation is meaningful, and only
  // while the capture's texture slides on the face by less than the DoG's scale
  // (~1 mm): both maps are compared texel by texel in the truth's UV layout (on the
  // quickstart's R3 capture, 3 mm of slide, it is −0.05; on an exact fit, 0.30).
  MapComparison mesoscopic_albedo;
  // Rung A: a linear filter of the capture's own textures against D* (correlation[0])
  // and the wrinkle layer beyond the most neutral frame's (correlation[1]).
  AppearanceCeiling appearance;
  // The landmark source's 68 points (the capture's frames/NNNNNN.json) against the
  // truth's projected landmark vertices, means over the frames that stored them: the
  // point-to-point error, px and / inter-ocular distance, and per face part
  // (core/ibug.h kIbugGroups) the mean error and mean error vector (+y down), px.
  // The jaw part is partly definitional: a detector follows the silhouette, the
  // truth's jaw points are fixed vertices.
  struct Landmarks {
    int frames = 0;
    double px = 0, iod = 0;
    // (error, dx, dy) per part. Eigen's fixed-size vectors are not zeroed by `{}`
    // (up to 0.4.3 eval.json's parts were whatever the memory held).
    std::array<Eigen::Vector3d, kIbugGroups.size()> groups = [] {
      std::array<Eigen::Vector3d, kIbugGroups.size()> zero;
      zero.fill(Eigen::Vector3d::Zero());
      return zero;
    }();
  } landmarks;
  // The truth registered through the image (eval/registered_truth.h), pooled over
  // the active frames in the wrinkle regions: D^t against the registered D* (raw and
  // wrinkle band) and the registered wrinkle layer's band; and how much of the truth
  // survives the registration (registered against unregistered band, D* and layer):
  // 1 when L~^t is the true mesh up to the image's resolution. The slide: how far
  // the true point a tracked texel sees lies from the texel itself on the chart
  // (per frame the median length and the median u and v components, +v towards the
  // chart's bottom; means over the registered frames), mm at the chart's mean scale,
  // over the same texels. The drift: how far the true point a texel sees has moved
  // on the chart since the first registered frame (per frame the median length over
  // the texels registered in both; mean and maximum over the later frames), mm: 0
  // for a texture that stays on the same skin however far it sits from the truth
  // (the "temporally consistent" textures of Sec. 5.1).
  struct Registered {
    int frames = 0;
    MapComparison detail, band, layer_band, truth_band, truth_layer_band;
    double slide_mm = 0, slide_u_mm = 0, slide_v_mm = 0;
    double drift_mm = 0, drift_max_mm = 0;
  } registered;
  // D*'s wrinkle band against itself slid by kTruthShifts[k] along ±u and ±v
  // (AddSlidTruthMoments), pooled over the active frames in the wrinkle regions: what
  // a slide of the tracked texture on the face costs any D^t in UV, so that
  // registered.slide_mm reads as a ceiling (empty without the detail truth).
  std::vector<MapComparison> truth_shift;
  std::string timing_json = "{}";  // copied from the capture's summary
  double fps = 0, tracking_share = 0, detail_share = 0;
  bool overlapped = false;        // the capture overlapped frames (CaptureSummary::overlapped)
  double stage_ms_per_frame = 0;  // its steady frames' stage times summed
  std::vector<FrameCaptureEval> per_frame;
  // Fig. 11: the frame with the 2D error vectors of L^t (left) and L~^t (right),
  // from the true projections of the visible face vertices (CV_8UC3, RGB); empty when
  // no frame was drawn.
  cv::Mat error_vectors;
  int error_vectors_frame = -1;

  std::string ToMarkdown() const;
  std::string ToJson() const;
  std::string ToCsv() const;  // one row per frame
};

// The vertical offset of D's features against G's, texels (+: D's lie higher, at
// smaller v): the s maximising the correlation of D(x, y − s) with G(x, y) over
// `mask` (CV_8U), |s| ≤ max_shift. D, G: CV_32F maps of one size. False when no shift correlates
// positively. The wrinkle offset of Fig. 14.
bool BestVerticalOffset(const cv::Mat& D, const cv::Mat& G, const cv::Mat& mask, int max_shift, int* shift,
                        double* correlation);

// FlowStageErrors of one frame: `arrays` with flow points and L~^t, `truth_px` the
// true projections of the rig's vertices (#V×2), `truth_visible` per vertex,
// `on_face` the vertices evaluated (the face chart's, with a truth correspondence).
FlowStageErrors MeasureFlowStages(const CaptureFrameArrays& arrays, const Camera& camera, const MatX2d& truth_px,
                                  const std::vector<char>& truth_visible, const std::vector<char>& on_face);

// H^t (`h`: V, N, UV) against the true surface `truth`: along each vertex normal
// (within max_distance_mm) the distance and the angle between the normals; the
// wrinkle_* figures over the vertices whose UV falls in `region` (R×R CV_8U in the
// texel convention of core/uv_raster.h; empty: none).
SurfaceError MeasureSurface(const TriMesh& h, const RayCaster& truth, double max_distance_mm, const cv::Mat& region);

// Evaluates the capture folder `capture` (written by `crease capture`) against the
// sequence dataset `dataset` (written by `crease synth sequence` with its maps).
// Throws Error naming the file when either folder lacks what is needed.
CaptureEvalSummary EvaluateCapture(const std::filesystem::path& capture, const std::filesystem::path& dataset,
                                   const CaptureEvalOptions& options);

// Writes a capture's evaluation into `dir` (created when missing): eval_frames.csv
// (ToCsv), eval.md (ToMarkdown), error_vectors.png (Fig. 11, when the summary has
// one) and eval.json (ToJson and a newline), all or nothing (WriteFilesAtomic).
void WriteCaptureEval(const std::filesystem::path& dir, const CaptureEvalSummary& summary);

}  // namespace crease
