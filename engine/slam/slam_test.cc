// RunSlam (slam.cc) on its own: a short rendered sequence tracked frame after frame, a black
// frame reported as lost while the run goes on, a wrong image size and invalid options refused,
// and cancellation through the progress sink. Label integration (renders images).

#include <cmath>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/slam/slam.h"
#include "engine/util/check.h"
#include "testing/slam/sequence_accuracy.h"

namespace omnirig::slam {
namespace {

class SlamOnShortSequence : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    sequence_ = new synth::StereoSequence(synth::MakeStereoSequence(ShortSequenceOptions(10)));
  }
  static void TearDownTestSuite() { delete sequence_; }

  static SlamOptions Options() {
    SlamOptions options;
    options.num_threads = 2;
    return options;
  }

  // Frame i's images, with frame `black` replaced by black images in both cameras.
  static StereoFrameLoader Loader(int black = -1) {
    return [black](int i) {
      if (i == black) {
        return StereoImages{cv::Mat::zeros(sequence_->images[0][i].size(),
                                           sequence_->images[0][i].type()),
                            cv::Mat::zeros(sequence_->images[1][i].size(),
                                           sequence_->images[1][i].type())};
      }
      return StereoImages{sequence_->images[0][i], sequence_->images[1][i]};
    };
  }

  static synth::StereoSequence* sequence_;
};

synth::StereoSequence* SlamOnShortSequence::sequence_ = nullptr;

TEST_F(SlamOnShortSequence, TracksEveryFrameInTheFirstFramesWorld) {
  const SlamResult result = RunSlam(sequence_->rig, sequence_->names, Loader(), Options());
  ASSERT_EQ(result.frames.size(), sequence_->names.size());
  EXPECT_EQ(result.num_tracked, static_cast<int>(sequence_->names.size()));
  EXPECT_EQ(result.num_lost, 0);
  EXPECT_EQ(result.frames[0].state, "initialised");
  for (size_t i = 0; i < result.frames.size(); ++i) {
    const FrameReport& frame = result.frames[i];
    EXPECT_EQ(frame.name, sequence_->names[i]);
    if (i > 0) {
      EXPECT_EQ(frame.state, "tracked") << frame.name << ": " << frame.reason;
    }
    EXPECT_TRUE(frame.linked) << frame.name;
    EXPECT_TRUE(frame.world_from_rig.has_value()) << frame.name;
  }
  // The world frame is the first frame's rig frame.
  const Rigid3d& first = *result.frames[0].world_from_rig;
  EXPECT_LT(first.translation.norm(), 1e-3);
  ASSERT_TRUE(result.global_bundle_adjustment.has_value());
  EXPECT_FALSE(result.map.empty());

  const SequenceAccuracy accuracy = EvaluateOnSequence(*sequence_, result, sequence_->rig);
  // README: drift 0.127 % over 40 frames of 1024x768; 10 frames of 640x480 stay within 1 %.
  EXPECT_LT(accuracy.trajectory.final_drift_percent, 1.0);
  EXPECT_LT(accuracy.map_median_percent_of_range, 1.0);
}

TEST_F(SlamOnShortSequence, ABlackFrameIsLostWithItsReasonAndTheRunGoesOn) {
  const int black = 4;
  const SlamResult result = RunSlam(sequence_->rig, sequence_->names, Loader(black), Options());
  ASSERT_EQ(result.frames.size(), sequence_->names.size());
  const FrameReport& lost = result.frames[black];
  EXPECT_EQ(lost.state, "lost");
  EXPECT_NE(lost.reason.find("black"), std::string::npos) << lost.reason;
  EXPECT_FALSE(lost.world_from_rig.has_value());
  EXPECT_EQ(result.num_lost, 1);
  EXPECT_EQ(result.num_tracked, static_cast<int>(sequence_->names.size()) - 1);
  // The next frame is tracked against the last good one (30 cm away), still in the first
  // frame's world.
  const FrameReport& next = result.frames[black + 1];
  EXPECT_EQ(next.state, "tracked") << next.reason;
  EXPECT_TRUE(next.linked);
}

TEST_F(SlamOnShortSequence, AnImageOfAnotherSizeIsRefused) {
  StereoFrameLoader small = [](int i) {
    cv::Mat half;
    cv::resize(sequence_->images[0][i], half, cv::Size(320, 240));
    return StereoImages{half, sequence_->images[1][i]};
  };
  try {
    RunSlam(sequence_->rig, sequence_->names, small, Options());
    FAIL() << "a 320x240 image with a 640x480 calibration must be refused";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("320x240"), std::string::npos) << e.what();
  }
}

TEST_F(SlamOnShortSequence, CancelStopsTheRun) {
  int reports = 0;
  ProgressSink progress;
  progress.report = [&](double, const std::string&, const std::string&) { ++reports; };
  progress.is_cancelled = [&] { return reports >= 3; };
  EXPECT_THROW(RunSlam(sequence_->rig, sequence_->names, Loader(), Options(), progress),
               Cancelled);
}

TEST(SlamOptions, InvalidOptionsAreRefused) {
  SlamOptions options;
  EXPECT_NO_THROW(options.Check());
  options.min_features = 2;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = SlamOptions();
  options.num_threads = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = SlamOptions();
  options.global_bundle_adjustment = false;
  options.calibration_refinement.refine = CalibrationRefinement::kAll;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = SlamOptions();
  options.loop_max_drift_fraction = -0.01;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::slam
