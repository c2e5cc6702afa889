// Deformation transfer between meshes of one topology (Sumner and Popović 2004),
// used twice by detail extraction (paper Sec. 4.1):
//   * the rig made compatible: G(L^0) → G(L^b) transferred to L^0 gives L_0^b;
//   * the scans: G(M^0) → G(M^j) transferred to M^0 gives M_0^j.
//
// Source and target share their triangles (the correspondence is the identity),
// so the transfer is the gradient-domain form of Sumner and Popović (shown to be
// equivalent by Botsch et al. 2006, "Deformation transfer for detail-preserving
// surface editing"):
//   1. per source triangle t, the deformation gradient Q_t = Ṽ_t V_t⁻¹, with
//      V_t = [v1 − v0, v2 − v0, n] of the rest triangle and Ṽ_t the same of the
//      deformed one, n = (v1 − v0) × (v2 − v0) / √|(v1 − v0) × (v2 − v0)| (the
//      paper's fourth vertex);
//   2. the target positions x minimise Σ_t A_t ‖J_t(x) − Q_t P_t‖²_F, where J_t(x)
//      is the Jacobian of the piecewise-linear map from the target's rest triangle
//      t (area A_t, tangent projector P_t) to x. The normal equations are
//        L x = Gᵀ A q        (L = Gᵀ A G, the cotangent Laplacian)
//      with G the per-triangle gradient operator.
//   3. L is singular (one translation per connected component), so a weak anchor
//      ε M (x − x̂) pulls the solution towards x̂ = T^0 + (S^1 − S^0), the target
//      moved by the source's displacement; ε is relative to the mean of L's
//      diagonal and small (1e-6 by default), so it fixes translations and hardly
//      anything else.
// When source and target are the same mesh, the transfer reproduces the source's
// deformation exactly (a test checks this).
//
// L depends only on the target's rest shape: it is factorised once in the
// constructor and every Transfer() is a solve with 3 right-hand sides.
#pragma once

#include <memory>
#include <string>

#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

struct DeformationTransferOptions {
  // ε: weight of the anchor towards T^0 + (S^1 − S^0), relative to the mean
  // diagonal of the cotangent Laplacian. Not in the paper (it fixes the
  // translation null space).
  double anchor_weight = 1e-6;
};

class DeformationTransfer {
 public:
  // source_rest (S^0) and target_rest (T^0) must have the same triangles (F) and
  // vertex count. Vertices duplicated along UV seams are welded first. Factorises
  // L. Throws Error (message starts with `what`) on mismatched topology, non-finite
  // positions or a failed factorisation.
  DeformationTransfer(const TriMesh& source_rest, const TriMesh& target_rest,
                      const DeformationTransferOptions& options = {},
                      const std::string& what = "deformation transfer");
  ~DeformationTransfer();
  DeformationTransfer(DeformationTransfer&&) noexcept;
  DeformationTransfer& operator=(DeformationTransfer&&) noexcept;

  // S^1: deformed source positions (#V×3). Returns the deformed target (#V×3).
  // Const; may be called from several threads.
  MatX3d Transfer(const MatX3d& source_deformed) const;

  int num_vertices() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crease
