// Poisson (Laplace) fill of the texels of a map that no patch covers (paper
// Sec. 5.2: "pixels which are not covered by any patch are smoothly filled in by
// solving a Poisson system on the texture domain. Since the patch coverage is
// fixed once the wrinkle map has been computed, we can pre-factorize the Poisson
// matrix to achieve real-time performance").
//
// Problem. On the R×R texel grid (DESIGN.md texel convention), with
//   domain Ω  — the texels where the map is defined (the face chart),
//   known K   — texels whose values are given (patch-covered), K ⊂ Ω,
//   unknown U = Ω \ K,
// find u on U with the 5-point Laplacian Δu = 0 (u = mean of its 4 neighbours)
// where the neighbours in K are Dirichlet values, and the neighbours outside Ω
// (or beyond the map) are either 0 (PoissonFillOptions::fill_boundary = "zero",
// a Dirichlet condition at the chart border) or left out of the mean ("neumann",
// zero normal derivative at the chart border).
//
// Why "zero" is the default for D^t: a displacement map of wrinkles is mostly 0
// away from the patches (D^t holds only what the coarse mesh lacks, Sec. 4.1), and
// the chart border is where the refined surface must meet the coarse one without
// an offset. With Neumann the uncovered face (cheeks, chin, nose — most of the
// chart) would take the average of the patches' edge values as a constant offset,
// i.e. shift the whole surface; with zero Dirichlet the fill decays from the
// patch borders to 0 at the chart border and the eye and mouth holes.
//
// Solver (fixed domain, so everything but the right-hand side is built once in the
// constructor), with s = R / fill_resolution (default 1024 / 128 = 8):
//   1. Coarse grid: node (I, J) stands for the s×s block of texels [sI, sI+s) ×
//      [sJ, sJ+s), located at its centre. A block at least half in K is a coarse
//      Dirichlet node; its value is the least-squares affine fit of its known texels
//      evaluated at the block centre (the block mean when it is fully known), a fixed
//      linear combination precomputed per block. Otherwise a block with ("zero") at
//      least half / ("neumann") any of its texels in Ω is a coarse unknown; the rest
//      is outside. (Half-block thresholds keep the coarse boundaries within ±s/2 of
//      the fine ones instead of biased by up to s.) The coarse 5-point Laplace system
//      is factorised once (Eigen SimplicialLDLT, AMD ordering); per frame one
//      back-substitution.
//   2. Every fine unknown texel takes the bilinear interpolation of the coarse field
//      at its position (outside nodes: 0 for "zero"; the mean of their in-domain
//      neighbour nodes for "neumann").
//   3. Fine-grid smoothing: fill_smoothing_sweeps red-black Gauss–Seidel sweeps of
//      the fine 5-point equations on the unknown texels within fill_band_texels
//      (Chebyshev distance) of a known texel or ("zero") of the domain's edge, the
//      other unknowns held at step 2's values. This removes the seam between the
//      coarse field and the fine known values (detail inside an s×s block that the
//      coarse nodes cannot carry) and the ±s/2 offset of the coarse chart border.
// With s = 1 (fill_resolution ≥ R) step 1 is the exact direct solve of the fine
// system and steps 2–3 change nothing.
//
// Properties (tests/poisson_fill_test.cc): known texels are never written (bit
// identical); texels outside Ω are set to 0; no NaN (components of coarse unknowns
// with no Dirichlet neighbour, possible with "neumann", are set to 0); bytes do not
// depend on the TBB thread count (every output texel is computed by one task from
// values of the previous colour / step). A linear field is reproduced exactly (to
// float rounding: 2.4e-7 on a field of range 8.7, s = 1, 4, 8) when U is enclosed by
// a band of K at least 2s texels thick: the affine fits are exact, the 5-point
// Laplacian and bilinear interpolation reproduce linear functions, and smoothing
// leaves a discrete harmonic field unchanged. (Known bands thinner than 2s are seen
// by step 3 only, so the coarse field may leak through them; the patch unions of
// the detail regressor are ≥ w = 32 texels wide.) Against the exact fine solve of a
// wavy field (range 2.6, wavelengths 42–125 texels) on a 256² disc: RMS error 0.030 /
// max 0.18 at s = 4, RMS 0.071 / max 0.30 at s = 8 (without step 3: max 0.33 / 0.51).
//
// Speed (bench/detail_regression_bench.cc, 2-vCPU Sapphire Rapids, Release, R = 1024):
// see the table in detail_regression.h.
//
// Differences from the paper:
//   1. The paper pre-factorises the full-resolution Poisson matrix. A direct solve
//      of ~600k unknowns costs ~20–30 ms per frame on this machine (PLATFORM.md),
//      so the solve runs on a coarse grid (128² by default: ~10k unknowns for a
//      face chart) and is refined by a few fine-grid Gauss–Seidel sweeps near the
//      known texels and the chart border: an approximation of the fine solution
//      (exact for linear data; the difference to the exact fine solve is above).
//   2. The paper does not say which boundary condition holds at the edge of the
//      texture domain; "zero" is the default (see above), "neumann" is available.
//   3. The equation is Laplace's (Δu = 0: "smoothly filled in"); there is no source
//      term.
#pragma once

#include <array>
#include <memory>
#include <string>

#include <opencv2/core/mat.hpp>

namespace crease {

class OptionVisitor;

// PoissonFillOptions::fill_boundary (see there).
enum class FillBoundary { kZero, kNeumann };
constexpr std::array<const char*, 2> OptionEnumNames(FillBoundary) { return {"zero", "neumann"}; }

struct PoissonFillOptions {
  // Side of the coarse grid the Laplace system is factorised on, texels (not in the
  // paper, Difference 1): blocks of s = R / fill_resolution texels, R % s must be 0.
  // ≥ R = solve on the full grid (exact, ~20 ms at 1024²). 128 at R = 1024 (s = 8)
  // costs ~1.5 ms less per frame than 256 (s = 4; ~39k instead of ~10k coarse
  // unknowns on a face chart), at about twice the (small) difference to the exact
  // fine solve.
  int fill_resolution = 128;
  // Condition at the edge of the domain (texels outside it and beyond the map):
  // "zero" (Dirichlet 0, the default for wrinkle displacement, see the header) or
  // "neumann" (zero normal derivative). Not specified in the paper (Difference 2).
  FillBoundary fill_boundary = FillBoundary::kZero;
  // Red-black Gauss–Seidel sweeps of the fine equations near the known texels
  // (Difference 1); 0 = the coarse field alone. Unused when the grid is not coarsened.
  int fill_smoothing_sweeps = 6;
  // Width of the band of unknown texels smoothed around the known ones, texels
  // (Chebyshev distance; Difference 1).
  int fill_band_texels = 6;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

class PoissonFill {
 public:
  // domain: CV_8U R×R, non-zero where the map is defined (the face chart); known:
  // CV_8U R×R, non-zero where values are given (patch-covered; only known ∧ domain
  // counts). Unknown = domain ∧ ¬known. Builds and factorises the coarse system and
  // the smoothing band. Throws Error on invalid options, an empty, non-square or
  // wrongly typed mask, masks of different sizes, or R not divisible into blocks.
  PoissonFill(const cv::Mat& domain, const cv::Mat& known, const PoissonFillOptions& options);
  ~PoissonFill();
  PoissonFill(PoissonFill&&) noexcept;
  PoissonFill& operator=(PoissonFill&&) noexcept;

  // map: CV_32F R×R (continuous or not), in place: known texels unchanged, unknown
  // ones filled, outside the domain 0. Non-finite known texels are the caller's
  // business (they propagate). Throws Error on a wrong type or size.
  void Apply(cv::Mat* map) const;

  int map_size() const;
  int block_size() const;        // s
  int num_unknown() const;       // |U| (fine texels)
  int num_coarse_unknown() const;  // unknowns of the factorised coarse system
  int num_band() const;          // fine texels smoothed per sweep

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crease
