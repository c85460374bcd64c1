// Localising in a saved map (SlamOptions::saved_map): a first run round the synthetic room
// makes a map, written to a file and read back; a second run on another path through the same
// places, in other light, is placed in that map's world. Targets: at least 95 % of its frames
// localised in the map (in_map), its ATE in the saved map's world (no alignment of its own:
// the first run's alignment to the ground truth) at most 0.1 % of its path, no frame more than
// 0.5 m from its true position; the map it leaves is the saved one (unchanged keyframes) with
// what it added. Label integration (renders images).

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include <gtest/gtest.h>

#include "engine/slam/evaluation.h"
#include "engine/slam/saved_map.h"
#include "engine/slam/session.h"
#include "engine/slam/slam.h"
#include "testing/slam/revisit.h"

namespace omnirig::slam {
namespace {

SlamOptions Options() {
  SlamOptions options;
  options.num_threads = 2;
  return options;
}

StereoFrameLoader Loader(const synth::StereoSequence& sequence) {
  return [&sequence](int i) { return StereoImages{sequence.images[0][i], sequence.images[1][i]}; };
}

std::vector<Rigid3d> Estimates(const SlamResult& result) {
  std::vector<Rigid3d> poses;
  for (const FrameReport& frame : result.frames) poses.push_back(frame.world_from_rig.value());
  return poses;
}

class SavedMapLocalisation : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    first_ = new synth::StereoSequence(RenderCircleRun(FirstRun()));
    second_ = new synth::StereoSequence(RenderCircleRun(SecondRun()));
    first_result_ = new SlamResult(RunSlam(first_->rig, first_->names, Loader(*first_), Options()));
    // Through the file, as a later process reads it.
    const std::filesystem::path path =
        std::filesystem::path(::testing::TempDir()) / "saved_map_localise.bin";
    WriteSavedMap(path, first_result_->saved_map);
    SlamOptions options = Options();
    options.saved_map = std::make_shared<const SavedMap>(ReadSavedMap(path));
    std::filesystem::remove(path);
    second_result_ =
        new SlamResult(RunSlam(second_->rig, second_->names, Loader(*second_), options));
  }
  static void TearDownTestSuite() {
    delete second_result_;
    delete first_result_;
    delete second_;
    delete first_;
  }

  static synth::StereoSequence* first_;
  static synth::StereoSequence* second_;
  static SlamResult* first_result_;
  static SlamResult* second_result_;
};

synth::StereoSequence* SavedMapLocalisation::first_ = nullptr;
synth::StereoSequence* SavedMapLocalisation::second_ = nullptr;
SlamResult* SavedMapLocalisation::first_result_ = nullptr;
SlamResult* SavedMapLocalisation::second_result_ = nullptr;

TEST_F(SavedMapLocalisation, SecondRunIsLocalisedInTheFirstRunsWorld) {
  ASSERT_EQ(first_result_->num_tracked, static_cast<int>(first_->names.size()));
  ASSERT_EQ(second_result_->num_tracked, static_cast<int>(second_->names.size()));
  // The saved map's world in the ground truth's: the first run's own alignment.
  const Rigid3d gt_from_map =
      EvaluateTrajectory(Estimates(*first_result_), first_->world_from_rig).gt_from_estimate;
  const std::vector<Rigid3d> estimate = Estimates(*second_result_);
  double sum_sq = 0.0, max_m = 0.0, path_m = 0.0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    const double error =
        ((gt_from_map * estimate[i]).translation - second_->world_from_rig[i].translation).norm();
    sum_sq += error * error;
    max_m = std::max(max_m, error);
    if (i > 0) {
      path_m +=
          (second_->world_from_rig[i].translation - second_->world_from_rig[i - 1].translation)
              .norm();
    }
  }
  const double ate_m = std::sqrt(sum_sq / estimate.size());
  const double in_map =
      static_cast<double>(second_result_->num_frames_in_map) / second_->names.size();
  std::printf(
      "saved map: first run %zu frames, %zu keyframes saved, %zu landmarks; second run (other "
      "path, other light) %zu frames: in_map %.1f %%, ATE in the saved map's world %.2f mm = "
      "%.4f %% of its %.2f m path, max %.2f mm; first frame %s\n",
      first_->names.size(), first_result_->saved_map.keyframes.size(),
      first_result_->saved_map.landmarks.size(), second_->names.size(), 100.0 * in_map, 1e3 * ate_m,
      100.0 * ate_m / path_m, path_m, 1e3 * max_m, second_result_->frames.front().state.c_str());
  EXPECT_GE(in_map, 0.95);
  EXPECT_LE(ate_m, 0.001 * path_m);
  EXPECT_LE(max_m, 0.5);
  // Localised from the first frame on: relocalised against the saved keyframes, not a start
  // of its own.
  EXPECT_EQ(second_result_->frames.front().state, "relocalised");
  for (const FrameReport& frame : second_result_->frames) EXPECT_TRUE(frame.linked) << frame.name;
}

TEST_F(SavedMapLocalisation, ResultMapIsTheSavedOneWithWhatWasAdded) {
  const SavedMap& before = first_result_->saved_map;
  const SavedMap& after = second_result_->saved_map;
  ASSERT_GT(after.keyframes.size(), before.keyframes.size());  // the second run's keyframes
  for (size_t k = 0; k < before.keyframes.size(); ++k) {
    EXPECT_EQ(after.keyframes[k].name, before.keyframes[k].name);
    // The saved keyframes stay where the map had them: its world is the second run's.
    EXPECT_LT((after.keyframes[k].rig_from_world.translation -
               before.keyframes[k].rig_from_world.translation)
                  .norm(),
              1e-12);
  }
  EXPECT_GT(after.landmarks.size(), before.landmarks.size() / 2);
  // The map points exported hold the saved map's and the new ones.
  EXPECT_GT(second_result_->map.size(), first_result_->map.size());
}

TEST_F(SavedMapLocalisation, WithoutTheMapTheSecondRunHasAWorldOfItsOwn) {
  // The same frames without the saved map start their own world at their first frame, far
  // from the first run's: what the saved map changes is the world, not just the accuracy.
  const Rigid3d gt_from_map =
      EvaluateTrajectory(Estimates(*first_result_), first_->world_from_rig).gt_from_estimate;
  Session session(second_->rig, Options());
  const FrameReport first = session.Track(second_->names[0], Loader(*second_)(0));
  EXPECT_EQ(first.state, "initialised");
  EXPECT_FALSE(first.in_map);
  EXPECT_GT(((gt_from_map * first.world_from_rig.value()).translation -
             second_->world_from_rig[0].translation)
                .norm(),
            0.5);
}

}  // namespace
}  // namespace omnirig::slam
