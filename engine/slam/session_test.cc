// Session (session.h): the frames of a rendered sequence fed one at a time give RunSlam's
// result on the same frames (tracked whole, or with the next frame's front end on another
// thread beside this one's back end), poses are given as frames are tracked, the snapshot
// follows the run, and a frame of the wrong size is refused without ending the session. Label
// integration (renders images).

#include <future>
#include <optional>
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
  // RunSlam over the whole sequence with `num_threads`: what a session over the same frames
  // must give.
  static SlamResult BatchRun(int num_threads, SlamOptions* options) {
    options->num_threads = num_threads;
    return RunSlam(sequence_->rig, sequence_->names, [](int i) { return Frame(i); }, *options);
  }

  static synth::StereoSequence* sequence_;
};

synth::StereoSequence* SessionOnShortSequence::sequence_ = nullptr;

// The same run: RunSlam twice on these frames differs by ~1e-16 m (the global adjustment's sums
// in another order), far below 1e-9.
void ExpectSameRun(const SlamResult& live, const SlamResult& batch, const std::string& what) {
  ASSERT_EQ(live.frames.size(), batch.frames.size()) << what;
  EXPECT_EQ(live.num_tracked, batch.num_tracked) << what;
  EXPECT_EQ(live.num_keyframes, batch.num_keyframes) << what;
  EXPECT_EQ(live.map.size(), batch.map.size()) << what;
  EXPECT_EQ(live.loops.size(), batch.loops.size()) << what;
  for (size_t i = 0; i < batch.frames.size(); ++i) {
    EXPECT_EQ(live.frames[i].name, batch.frames[i].name) << what;
    ASSERT_TRUE(live.frames[i].world_from_rig && batch.frames[i].world_from_rig) << what;
    const Rigid3d& a = *live.frames[i].world_from_rig;
    const Rigid3d& b = *batch.frames[i].world_from_rig;
    EXPECT_LT((a.translation - b.translation).norm(), 1e-9) << what << " frame " << i;
    EXPECT_LT(a.rotation.angularDistance(b.rotation), 1e-9) << what << " frame " << i;
  }
}

TEST_F(SessionOnShortSequence, GivesRunSlamsResultFrameByFrame) {
  for (const int num_threads : {1, 2}) {
    SlamOptions options;
    const SlamResult batch = BatchRun(num_threads, &options);
    Session session(sequence_->rig, options);
    const int n = static_cast<int>(sequence_->names.size());
    for (int i = 0; i < n; ++i) {
      const FrameReport report = session.Track(sequence_->names[i], Frame(i), i + 1 == n);
      EXPECT_EQ(report.state, batch.frames[i].state) << sequence_->names[i];
      EXPECT_EQ(report.keyframe, batch.frames[i].keyframe) << sequence_->names[i];
      ASSERT_TRUE(report.world_from_rig.has_value()) << sequence_->names[i];
      EXPECT_EQ(session.Snapshot().world_from_rig.size(), static_cast<size_t>(i + 1));
    }
    ExpectSameRun(session.Finish(), batch, "threads " + std::to_string(num_threads));
    EXPECT_THROW(session.Finish(), InvalidArgument);
  }
}

// The live job's pipeline: the front end of frame i + 1 on another thread while frame i's back
// end runs on this one, and the snapshot taken between frames while a front end runs.
TEST_F(SessionOnShortSequence, GivesRunSlamsResultWithTheFrontEndAFrameAhead) {
  SlamOptions options;
  const SlamResult batch = BatchRun(2, &options);
  Session session(sequence_->rig, options);
  const int n = static_cast<int>(sequence_->names.size());
  const auto front_end = [&session](int i) {
    return session.FrontEnd(sequence_->names[i], Frame(i));
  };
  std::future<PreparedFrame> next = std::async(std::launch::async, front_end, 0);
  for (int i = 0; i < n; ++i) {
    PreparedFrame prepared = next.get();
    EXPECT_EQ(prepared.name(), sequence_->names[i]);
    if (i + 1 < n) next = std::async(std::launch::async, front_end, i + 1);
    const FrameReport report = session.Track(std::move(prepared), i + 1 == n);
    EXPECT_EQ(report.state, batch.frames[i].state) << sequence_->names[i];
    EXPECT_EQ(report.keyframe, batch.frames[i].keyframe) << sequence_->names[i];
    ASSERT_TRUE(report.world_from_rig.has_value()) << sequence_->names[i];
    EXPECT_EQ(session.num_frames(), i + 1);
    EXPECT_EQ(session.Snapshot().names.size(), static_cast<size_t>(i + 1));
  }
  ExpectSameRun(session.Finish(), batch, "pipelined");
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

// A live caller answers from on_pose: once per frame, before Track() returns, with the frame's
// pose as tracked (a keyframe's mapping refines it afterwards); the run is the same.
TEST_F(SessionOnShortSequence, HearsEachPoseBeforeTheKeyframesMappingAndTheRunIsTheSame) {
  SlamOptions options;
  const SlamResult batch = BatchRun(2, &options);
  Session session(sequence_->rig, options);
  const int n = static_cast<int>(sequence_->names.size());
  for (int i = 0; i < n; ++i) {
    std::optional<FrameReport> heard;
    int calls = 0;
    const FrameReport report = session.Track(
        session.FrontEnd(sequence_->names[i], Frame(i)), i + 1 == n,
        [&](const FrameReport& tracked) {
          ++calls;
          heard = tracked;
          EXPECT_EQ(session.num_frames(), i);  // before Track() returns
        });
    ASSERT_EQ(calls, 1) << sequence_->names[i];
    EXPECT_EQ(heard->state, report.state) << sequence_->names[i];
    EXPECT_EQ(heard->keyframe, report.keyframe) << sequence_->names[i];
    ASSERT_TRUE(heard->world_from_rig && report.world_from_rig) << sequence_->names[i];
    const double moved_m =
        (heard->world_from_rig->translation - report.world_from_rig->translation).norm();
    if (!report.keyframe) {
      EXPECT_EQ(moved_m, 0.0) << sequence_->names[i];
    }
    EXPECT_LT(moved_m, 0.01) << sequence_->names[i];
  }
  ExpectSameRun(session.Finish(), batch, "with on_pose");
}

// A frame prepared and then not tracked (the live server could not store it) gives its index
// back to the next frame; only the last frame prepared can be given back.
TEST_F(SessionOnShortSequence, GivesBackTheIndexOfAFrameThatWillNotBeTracked) {
  Session session(sequence_->rig, SlamOptions());
  session.Track(sequence_->names[0], Frame(0));
  session.Discard(session.FrontEnd(sequence_->names[1], Frame(1)));
  EXPECT_EQ(session.Track(sequence_->names[2], Frame(2)).state, "tracked");
  PreparedFrame third = session.FrontEnd(sequence_->names[3], Frame(3));
  PreparedFrame fourth = session.FrontEnd(sequence_->names[4], Frame(4));
  EXPECT_THROW(session.Discard(std::move(third)), std::logic_error);
  const SlamResult result = session.Finish();
  ASSERT_EQ(result.frames.size(), 2u);
  EXPECT_EQ(result.frames[1].name, sequence_->names[2]);
  EXPECT_EQ(result.num_tracked, 2);
}

// Refused by the front end while a frame waits prepared: the refused frame takes no index, the
// prepared one and the next are tracked with consecutive indices.
TEST_F(SessionOnShortSequence, RefusesAFrameOfTheWrongSizeWhileAFrameWaitsPrepared) {
  Session session(sequence_->rig, SlamOptions());
  session.Track(sequence_->names[0], Frame(0));
  PreparedFrame first = session.FrontEnd(sequence_->names[1], Frame(1));
  const cv::Mat small(100, 120, CV_8UC3, cv::Scalar(128, 128, 128));
  EXPECT_THROW(session.FrontEnd("small", StereoImages{small, small}), InvalidArgument);
  EXPECT_EQ(session.num_frames(), 1);
  EXPECT_EQ(session.Track(std::move(first)).state, "tracked");
  EXPECT_EQ(session.Track(sequence_->names[2], Frame(2)).state, "tracked");
  const SlamResult result = session.Finish();
  ASSERT_EQ(result.frames.size(), 3u);
  EXPECT_EQ(result.frames[2].name, sequence_->names[2]);
  EXPECT_EQ(result.num_tracked, 3);
}

}  // namespace
}  // namespace omnirig::slam
