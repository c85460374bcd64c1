#include "engine/calib/frame_selection.h"

#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/calib/pipeline.h"
#include "engine/synth/render.h"
#include "testing/synth/calib_board.h"

namespace omnirig {
namespace {

std::vector<Eigen::Vector2d> Grid(const Eigen::Vector2d& origin, int n) {
  std::vector<Eigen::Vector2d> corners;
  for (int i = 0; i < n; ++i) corners.push_back(origin + Eigen::Vector2d(10.0 * i, 0.0));
  return corners;
}

TEST(FrameSelection, BoardShiftTakesTheBetterNumbering) {
  const std::vector<Eigen::Vector2d> a = Grid({0.0, 0.0}, 4);
  std::vector<Eigen::Vector2d> turned(a.rbegin(), a.rend());
  EXPECT_DOUBLE_EQ(BoardShift(a, turned), 0.0);
  EXPECT_DOUBLE_EQ(BoardShift(a, Grid({3.0, 4.0}, 4)), 5.0);
}

TEST(FrameSelection, NearDuplicatesPointAtTheKeptFrame) {
  // Frames 0, 1 close; 2 empty; 3 far; 4 back near 0 (a revisit); 5 close to 3.
  const std::vector<std::vector<Eigen::Vector2d>> corners = {
      Grid({0, 0}, 4), Grid({2, 0}, 4), {}, Grid({100, 0}, 4), Grid({0, 3}, 4), Grid({101, 1}, 4)};
  const std::vector<int> duplicate_of = MarkNearDuplicates(corners, 5.0);
  EXPECT_EQ(duplicate_of, (std::vector<int>{-1, 0, -1, -1, 0, 3}));
}

// A board waved in front of the 1024x768 camera, 12 frames a stretch: frames without the board,
// near duplicates, and more distinct views than the cap. Rendered once for the tests.
struct WavedSequence {
  synth::SynthCamera camera;
  BoardSpec board;
  std::vector<std::string> names;
  std::shared_ptr<std::vector<cv::Mat>> frames = std::make_shared<std::vector<cv::Mat>>();
  ImageReader read;
};

const WavedSequence& Sequence() {
  static const WavedSequence sequence = [] {
    WavedSequence out;
    out.camera = synth::DefaultCamera(1024, 768);
    const synth::CheckerboardSpec spec;
    out.board = ToBoardSpec(spec);
    const int num_frames = 84;
    const std::vector<Rigid3d> trajectory =
        synth::WavedBoardTrajectory(out.camera, spec, num_frames, 12, 5);
    synth::Scene scene = synth::MakeCalibrationBackground(5);
    const int board_index = scene.AddCheckerboard(spec, Rigid3d());
    const synth::Renderer renderer(out.camera, 2);
    synth::RenderOptions render;
    render.supersampling = 1;
    render.noise_sigma = 2.0;
    render.grayscale = true;
    render.num_threads = 2;
    std::map<std::string, size_t> index;
    for (int f = 0; f < num_frames; ++f) {
      scene.SetBoardPose(board_index, trajectory[f]);
      render.seed = 1000 + f;
      out.frames->push_back(renderer.Render(scene, Rigid3d(), render));
      out.names.push_back("frame_" + std::to_string(1000 + f));
      index[out.names.back()] = f;
    }
    out.read = [frames = out.frames, index](const std::string& name, int flags) {
      const auto it = index.find(name);
      if (it == index.end()) return cv::Mat();
      cv::Mat image = (*frames)[it->second].clone();
      if (flags == cv::IMREAD_COLOR) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
      return image;
    };
    return out;
  }();
  return sequence;
}

CalibrationReport CalibrateSequence(int max_views) {
  const WavedSequence& sequence = Sequence();
  ImageCalibrationOptions options;
  options.calibrate.num_threads = 2;
  options.selection.max_views = max_views;
  options.selection.long_input_frames = 50;  // the 84 frames are a long input here
  return CalibrateImages(sequence.read, sequence.names, sequence.board, options, "",
                         ProgressSink());
}

// The calibration on every detected view: every frame the screen passes, detected fully with the
// long path's detector options, all calibrated (no near duplicates skipped, no cap).
CalibrationReport CalibrateEveryDetectedView(std::vector<CalibrationView>* views_out) {
  const WavedSequence& sequence = Sequence();
  DetectOptions detect;
  detect.try_costly_variants = false;
  std::vector<CalibrationView> views;
  for (const std::string& name : sequence.names) {
    const cv::Mat grey = sequence.read(name, cv::IMREAD_GRAYSCALE);
    views.push_back({name, BoardDetection()});
    if (!ScreenFrame(grey, sequence.board).empty()) {
      views.back().detection = DetectBoard(grey, sequence.board, detect);
    }
  }
  CalibrationOptions options;
  options.num_threads = 2;
  *views_out = views;
  return Calibrate(views, sequence.camera.model.width, sequence.camera.model.height,
                   sequence.board, options, ProgressSink());
}

TEST(FrameSelection, LongSequenceCalibratesOnSelectedViews) {
  const WavedSequence& sequence = Sequence();
  const CalibrationReport selected = CalibrateSequence(10);
  std::vector<CalibrationView> detected;
  const CalibrationReport every = CalibrateEveryDetectedView(&detected);
  EXPECT_EQ(selected.max_views, 10);
  ASSERT_EQ(selected.frames.size(), sequence.names.size());

  std::map<std::string, int> reasons;
  std::map<std::string, size_t> position;
  for (size_t i = 0; i < selected.frames.size(); ++i) {
    const FrameReport& frame = selected.frames[i];
    EXPECT_EQ(frame.name, sequence.names[i]);
    EXPECT_EQ(frame.used, frame.reason == "used") << frame.name;
    ++reasons[frame.reason];
    position[frame.name] = i;
    if (frame.reason == "near_duplicate_of") {
      // Points at an earlier frame that was kept (detected fully, whatever became of it).
      ASSERT_TRUE(position.count(frame.duplicate_of)) << frame.name;
      const FrameReport& kept = selected.frames[position[frame.duplicate_of]];
      EXPECT_NE(kept.reason, "near_duplicate_of");
      EXPECT_NE(kept.reason, "no_board");
    } else {
      EXPECT_TRUE(frame.duplicate_of.empty()) << frame.name;
    }
  }
  const std::set<std::string> known = {"used", "no_board", "near_duplicate_of",
                                       "detection_failed", "not_selected", "outlier"};
  for (const auto& [reason, count] : reasons) EXPECT_TRUE(known.count(reason)) << reason;
  EXPECT_GT(reasons["no_board"], 0);
  EXPECT_GT(reasons["near_duplicate_of"], 0);
  EXPECT_GT(reasons["not_selected"], 0);
  EXPECT_EQ(reasons["used"], selected.num_views_used);
  EXPECT_GE(selected.num_views_used, 8);
  EXPECT_LE(static_cast<int>(selected.images.size()), 10);

  EXPECT_GT(every.num_views_used, selected.num_views_used);
  // The selected views calibrate as well as every detected view: over the same corners (every
  // detected view, each pose fitted with the model), RMS within 5 %.
  int missing_selected = 0, missing_every = 0;
  const double rms_selected =
      RmsOverViews(selected.camera, sequence.board, detected, &missing_selected);
  const double rms_every = RmsOverViews(every.camera, sequence.board, detected, &missing_every);
  EXPECT_EQ(missing_selected, 0);
  EXPECT_EQ(missing_every, 0);
  EXPECT_NEAR(rms_selected / rms_every, 1.0, 0.05)
      << "over every detected view: selected model " << rms_selected << " px, every view's "
      << rms_every << " px (own views: " << selected.rms_px << " px, " << every.rms_px << " px)";
}

}  // namespace
}  // namespace omnirig
