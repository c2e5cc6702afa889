// The 68-point iBUG / 300-W landmark vocabulary: the 0-based indices crease uses
// by name, and the inter-ocular distance that normalises landmark errors.
// Index i is iBUG point i + 1. "Left" and "right" are the subject's: in a frontal
// image the subject's right eye is on the image's left (smaller x).
#pragma once

#include <array>
#include <string>

#include "core/error.h"
#include "core/types.h"

namespace crease {

inline constexpr int kIbugNumPoints = 68;
inline constexpr int kIbugRightEyeOuter = 36;  // iBUG 37: outer corner of the subject's right eye
inline constexpr int kIbugLeftEyeOuter = 45;   // iBUG 46: outer corner of the subject's left eye
inline constexpr int kIbugNoseTip = 30;        // iBUG 31

// The face parts of the 68 points, as 0-based index ranges [first, end).
struct IbugGroup {
  const char* name;
  int first, end;
};
inline constexpr std::array<IbugGroup, 5> kIbugGroups = {
    {{"jaw", 0, 17}, {"brows", 17, 27}, {"nose", 27, 36}, {"eyes", 36, 48}, {"mouth", 48, 68}}};

// Inter-ocular distance: the distance of the outer eye corners (iBUG 37 and 46, the
// 300-W convention), in the units of `points` (68×2, 0-based iBUG order). Not
// clamped: a caller that divides by it chooses its own floor. Throws Error when
// `points` has fewer than 68 rows.
inline double InterOcularDistance(const MatX2d& points) {
  if (points.rows() < kIbugNumPoints) {
    throw Error("InterOcularDistance: expected the 68 iBUG landmarks, got " + std::to_string(points.rows()) +
                " points");
  }
  return (points.row(kIbugRightEyeOuter) - points.row(kIbugLeftEyeOuter)).norm();
}

}  // namespace crease
