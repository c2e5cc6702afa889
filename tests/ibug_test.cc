#include "core/ibug.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"

namespace crease {
namespace {

TEST(Ibug, InterOcularDistanceIsTheOuterEyeCornerDistance) {
  MatX2d p = MatX2d::Zero(kIbugNumPoints, 2);
  p.row(kIbugRightEyeOuter) << 10.0, 20.0;  // the subject's right eye: image left
  p.row(kIbugLeftEyeOuter) << 13.0, 24.0;
  EXPECT_DOUBLE_EQ(InterOcularDistance(p), 5.0);
  // The other points do not matter.
  p.row(kIbugNoseTip) << 100.0, 100.0;
  EXPECT_DOUBLE_EQ(InterOcularDistance(p), 5.0);
}

TEST(Ibug, InterOcularDistanceRejectsFewerThan68Points) {
  EXPECT_ERROR_HAS(InterOcularDistance(MatX2d::Zero(51, 2)), "51 points");
  EXPECT_ERROR_HAS(InterOcularDistance(MatX2d()), "68 iBUG landmarks");
}

}  // namespace
}  // namespace crease
