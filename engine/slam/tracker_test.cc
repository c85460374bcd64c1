// The keyframe decision (DecideKeyframe, tracker.h): a first visit makes keyframes as the
// tracked landmarks thin out or the rig moves on; a revisit tracked on an earlier passage's
// keyframes makes none while one of them is near and enough of its landmarks are tracked.

#include <vector>

#include <gtest/gtest.h>

#include "engine/slam/tracker.h"

namespace omnirig::slam::internal {
namespace {

// A keyframe `metres` ahead of the frame along x, turned `degrees` about the vertical.
CovisibleKeyframe Keyframe(int index, int shared, int held, int keyframes_since, double metres,
                           double degrees = 0.0) {
  CovisibleKeyframe k;
  k.keyframe = index;
  k.shared = shared;
  k.held = held;
  k.keyframes_since = keyframes_since;
  k.keyframe_from_frame = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(degrees * M_PI / 180.0, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(metres, 0, 0));
  return k;
}

TEST(DecideKeyframe, AFirstVisitComparesWithTheLastKeyframe) {
  const SlamOptions options;
  // The last keyframe holds 400 landmarks: 300 still tracked is enough, 250 (< 70 %) is not.
  const std::vector<CovisibleKeyframe> last = {Keyframe(41, 300, 400, 0, 0.3)};
  KeyframeDecision decision = DecideKeyframe(last, 300, options);
  EXPECT_EQ(decision.reference_keyframe, 41);
  EXPECT_FALSE(decision.on_mapped_place);
  EXPECT_FALSE(decision.needs_keyframe);
  EXPECT_TRUE(DecideKeyframe(last, 250, options).needs_keyframe);
  // Moved or turned too far from it.
  EXPECT_TRUE(DecideKeyframe({Keyframe(41, 300, 400, 0, 1.2)}, 300, options).needs_keyframe);
  EXPECT_TRUE(DecideKeyframe({Keyframe(41, 300, 400, 0, 0.3, 25.0)}, 300, options).needs_keyframe);
  // No keyframe shares a landmark (a new segment).
  decision = DecideKeyframe({}, 0, options);
  EXPECT_EQ(decision.reference_keyframe, -1);
  EXPECT_TRUE(decision.needs_keyframe);
}

TEST(DecideKeyframe, ARevisitTrackedOnTheMapNeedsNoKeyframe) {
  const SlamOptions options;
  // After a loop the frame tracks the new keyframe's landmarks most, and 120 of a keyframe of
  // the first lap, 0.4 m away: the map covers the view, although the frame tracks fewer than
  // 70 % of what either keyframe holds.
  const std::vector<CovisibleKeyframe> revisit = {Keyframe(420, 200, 450, 0, 0.3),
                                                  Keyframe(17, 120, 500, 300, 0.4, 5.0)};
  const KeyframeDecision decision = DecideKeyframe(revisit, 250, options);
  EXPECT_EQ(decision.reference_keyframe, 17);
  EXPECT_TRUE(decision.on_mapped_place);
  EXPECT_FALSE(decision.needs_keyframe);
}

TEST(DecideKeyframe, AMappedKeyframeMustBeOldNearAndWellTracked) {
  const SlamOptions options;
  const CovisibleKeyframe recent = Keyframe(420, 200, 450, 0, 0.3);
  for (const CovisibleKeyframe& mapped :
       {// Among the recent keyframes: the same passage, not a revisit.
        Keyframe(400, 120, 500, options.loop_min_keyframe_gap, 0.4),
        // Too far, or turned too much, to cover the view.
        Keyframe(17, 120, 500, 300, 1.3), Keyframe(17, 120, 500, 300, 0.4, 30.0),
        // Too few of its landmarks tracked.
        Keyframe(17, options.keyframe_min_mapped_landmarks - 1, 500, 300, 0.4)}) {
    const KeyframeDecision decision = DecideKeyframe({recent, mapped}, 250, options);
    EXPECT_EQ(decision.reference_keyframe, 420);
    EXPECT_FALSE(decision.on_mapped_place);
    EXPECT_TRUE(decision.needs_keyframe);  // 250 < 70 % of 450
  }
}

}  // namespace
}  // namespace omnirig::slam::internal
