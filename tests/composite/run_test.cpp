// Issue 7 item 1 with the true cameras: the whole live frame (key -> carve -> main-view depth
// -> composite) on the studio take against its true composite.
#include <gtest/gtest.h>

#include "tests/composite/take_fixture.h"

namespace previz::composite::test {
namespace {

TEST(RunTrueRig, CompositeMatchesTruthOverTheActorAndKeepsDepthOrder) {
  const fs::path& take = studioTake();
  const TakeMeasure m = measureTake(take, take / "truth" / "rig.json", false, "true rig and poses");
  ASSERT_EQ(m.frames.size(), 5u);
  // The take must exercise both orders: the actor behind the pillar at 2 s, in front at 8 s.
  EXPECT_GT(m.frames[1].truth_behind_px, 1000) << "actor not behind the CG at t = 2 s";
  EXPECT_LT(m.frames[4].truth_behind_px, m.frames[4].actor_px / 2) << "actor not in front at t = 8 s";
  EXPECT_GE(m.min_psnr_db, 30.0);
  EXPECT_LE(m.wrongFraction(), 0.005);
}

}  // namespace
}  // namespace previz::composite::test
