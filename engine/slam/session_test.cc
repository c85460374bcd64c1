// Session (session.h): the frames of a rendered sequence fed one at a time give RunSlam's
// result on the same frames, poses are given as frames are tracked, the snapshot follows the
// run, and a frame of the wrong size is refused without ending the session. Label integration
// (renders images).

#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "engine/slam/session.h"
#include "engine/util/check.h"
#include "testing/slam/sequence_accuracy.h"

namespace omnirig::slam {
namespace {

class SessionOnShortSequence : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    sequence_ = new synth::StereoSequence(synth::MakeStereoSequence(ShortSequenceOptions(8)));
  }
  static void TearDownTestSuite() { delete sequence_; }

  static StereoImages Frame(int i) {
    return StereoImages{sequence_->images[0][i], sequence_->images[1][i]};
  }

  static synth::StereoSequence* sequence_;
};

synth::StereoSequence* SessionOnShortSequence::sequence_ = nullptr;

TEST_F(SessionOnShortSequence, GivesRunSlamsResultFrameByFrame) {
  for (const int num_threads : {1, 2}) {
    SlamOptions options;
    options.num_threads = num_threads;
    const SlamResult batch = RunSlam(
        sequence_->rig, sequence_->names, [](int i) { return Frame(i); }, options);
    Session session(sequence_->rig, options);
    const int n = static_cast<int>(sequence_->names.size());
    for (int i = 0; i < n; ++i) {
      const FrameReport report = session.Track(sequence_->names[i], Frame(i), i + 1 == n);
      EXPECT_EQ(report.state, batch.frames[i].state) << sequence_->names[i];
      EXPECT_EQ(report.keyframe, batch.frames[i].keyframe) << sequence_->names[i];
      ASSERT_TRUE(report.world_from_rig.has_value()) << sequence_->names[i];
      EXPECT_EQ(session.Snapshot().world_from_rig.size(), static_cast<size_t>(i + 1));
    }
    const SlamResult live = session.Finish();
    ASSERT_EQ(live.frames.size(), batch.frames.size());
    EXPECT_EQ(live.num_tracked, batch.num_tracked);
    EXPECT_EQ(live.num_keyframes, batch.num_keyframes);
    EXPECT_EQ(live.map.size(), batch.map.size());
    EXPECT_EQ(live.loops.size(), batch.loops.size());
    for (size_t i = 0; i < batch.frames.size(); ++i) {
      ASSERT_TRUE(live.frames[i].world_from_rig && batch.frames[i].world_from_rig);
      const Rigid3d& a = *live.frames[i].world_from_rig;
      const Rigid3d& b = *batch.frames[i].world_from_rig;
      // The same run: RunSlam twice on these frames differs by ~1e-16 m (the global
      // adjustment's sums in another order), far below 1e-9.
      EXPECT_LT((a.translation - b.translation).norm(), 1e-9)
          << "threads " << num_threads << " frame " << i;
      EXPECT_LT(a.rotation.angularDistance(b.rotation), 1e-9)
          << "threads " << num_threads << " frame " << i;
    }
    EXPECT_THROW(session.Finish(), InvalidArgument);
  }
}

TEST_F(SessionOnShortSequence, SnapshotFollowsTheRunAndPosesMoveWithTheCamera) {
  Session session(sequence_->rig, SlamOptions());
  std::vector<int> keyframes;  // as the frames' reports said
  for (int i = 0; i < 4; ++i) {
    if (session.Track(sequence_->names[i], Frame(i)).keyframe) keyframes.push_back(i);
  }
  const SlamSnapshot snapshot = session.Snapshot();
  ASSERT_FALSE(keyframes.empty());
  EXPECT_EQ(snapshot.keyframes, keyframes);
  EXPECT_EQ(snapshot.keyframes.front(), 0);  // the first frame initialises the map
  ASSERT_EQ(snapshot.names.size(), 4u);
  EXPECT_EQ(snapshot.names[3], sequence_->names[3]);
  EXPECT_EQ(snapshot.states[0], "initialised");
  EXPECT_GE(snapshot.num_keyframes, 1);
  EXPECT_FALSE(snapshot.map.empty());
  ASSERT_TRUE(snapshot.world_from_rig[0] && snapshot.world_from_rig[3]);
  // The poses so far hold the metric motion: the distance travelled, as rendered, to 2 cm.
  const double moved_m =
      (snapshot.world_from_rig[3]->translation - snapshot.world_from_rig[0]->translation).norm();
  const double true_m =
      (sequence_->world_from_rig[3].translation - sequence_->world_from_rig[0].translation).norm();
  EXPECT_NEAR(moved_m, true_m, 0.02);
}

TEST_F(SessionOnShortSequence, RefusesAFrameOfTheWrongSizeAndGoesOn) {
  Session session(sequence_->rig, SlamOptions());
  session.Track(sequence_->names[0], Frame(0));
  const cv::Mat small(100, 120, CV_8UC3, cv::Scalar(128, 128, 128));
  try {
    session.Track("small", StereoImages{small, small});
    FAIL() << "a 120x100 frame was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("120x100"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("640x480"), std::string::npos) << e.what();
  }
  EXPECT_EQ(session.num_frames(), 1);
  const FrameReport next = session.Track(sequence_->names[1], Frame(1));
  EXPECT_EQ(next.state, "tracked") << next.reason;
  const SlamResult result = session.Finish();
  EXPECT_EQ(result.num_tracked, 2);
}

}  // namespace
}  // namespace omnirig::slam
