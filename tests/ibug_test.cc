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

TEST(Ibug, GroupsPartitionThe68PointsInOrder) {
  int next = 0;
  for (const IbugGroup& g : kIbugGroups) {
    EXPECT_EQ(g.first, next) << g.name;
    EXPECT_LT(g.first, g.end) << g.name;
    next = g.end;
  }
  EXPECT_EQ(next, kIbugNumPoints);
  // The named points fall in their parts.
  EXPECT_STREQ(kIbugGroups[3].name, "eyes");
  EXPECT_TRUE(kIbugRightEyeOuter >= kIbugGroups[3].first && kIbugLeftEyeOuter < kIbugGroups[3].end);
  EXPECT_TRUE(kIbugNoseTip >= kIbugGroups[2].first && kIbugNoseTip < kIbugGroups[2].end);
}

}  // namespace
}  // namespace crease
