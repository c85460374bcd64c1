// bench_detect_hole: checkerboard detection on frames whose board is partly hidden by the
// mirror's central hole. Renders the frames of bench_calib_recording's waved board
// (synth::WavedBoardTrajectory, 1280x1024 DefaultCamera, same seed) where some but not all inner
// corners project into the annulus and at least one hidden corner lies towards the hole, and
// times on each: OpenCV's classic detector with adaptive thresholds (the flags DetectBoard uses)
// on the plain image, the contrast-equalised image, and the equalised image with the mirror's
// hole and outside (MirrorMask) set to a flat grey; and DetectBoard with every variant.
//   bench_detect_hole [max_frames [min_visible_corners]]   (default 12 1)

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/calib/detect.h"
#include "engine/features/mirror_mask.h"
#include "engine/synth/presets.h"
#include "engine/synth/render.h"
#include "engine/util/timer.h"
#include "testing/synth/calib_board.h"

namespace omnirig {
namespace {

int Main(int argc, char** argv) {
  const int max_frames = argc > 1 ? std::atoi(argv[1]) : 12;
  const int min_visible = argc > 2 ? std::atoi(argv[2]) : 1;
  const int num_frames = 2400;
  const synth::SynthCamera camera = synth::DefaultCamera(1280, 1024);
  const synth::CheckerboardSpec board_spec;
  const uint64_t seed = 11;
  const std::vector<Rigid3d> trajectory =
      synth::WavedBoardTrajectory(camera, board_spec, num_frames, 30, seed);
  synth::Scene scene = synth::MakeCalibrationBackground(seed);
  const int board_index = scene.AddCheckerboard(board_spec, Rigid3d());
  const synth::Renderer renderer(camera, 2);
  synth::RenderOptions render;
  render.supersampling = 1;
  render.noise_sigma = 2.0;
  render.blur_sigma_px = 0.5;
  render.grayscale = true;
  render.num_threads = 2;
  const BoardSpec board = ToBoardSpec(board_spec);
  const cv::Size pattern(board.cols, board.rows);
  const int flags =
      cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK;
  std::printf(
      "frame visible/total  classic_s equalised_classic_s masked_equalised_classic_s  "
      "detect_board_s found method\n");
  double total_classic = 0.0, total_equalised = 0.0, total_masked = 0.0, total_detect = 0.0;
  int done = 0;
  for (int f = 0; f < num_frames && done < max_frames; ++f) {
    const auto corners = synth::ProjectBoardCorners(camera, trajectory[f], board_spec);
    int visible = 0;
    for (const auto& c : corners) visible += std::isfinite(c.x());
    if (visible < min_visible || visible == static_cast<int>(corners.size())) continue;
    // Partly over the hole: the board's centre (camera frame) near the camera's axis.
    const Eigen::Vector3d centre = trajectory[f].translation;
    if (std::hypot(centre.x(), centre.y()) > 0.5 * centre.z()) continue;
    if (f % 3 != 0) continue;  // neighbouring frames look alike
    scene.SetBoardPose(board_index, trajectory[f]);
    render.seed = seed * 100000 + f;
    const cv::Mat grey = renderer.Render(scene, Rigid3d(), render);
    // The equalised image with the mirror's hole and the outside set to a flat grey: how much
    // of the cost the hole and the border carry.
    MirrorMaskOptions mask_options;
    mask_options.margin_px = 0.0;
    const cv::Mat mask =
        MirrorMask(grey, Eigen::Vector2d(grey.cols / 2.0, grey.rows / 2.0), mask_options);
    cv::Mat equalised;
    cv::createCLAHE(3.0, cv::Size(8, 8))->apply(grey, equalised);
    cv::Mat masked = equalised.clone();
    masked.setTo(128, mask == 0);
    std::vector<cv::Point2f> found;
    Timer t4;
    cv::findChessboardCorners(masked, pattern, found, flags);
    const double masked_s = t4.ElapsedSeconds();
    Timer t1;
    cv::findChessboardCorners(grey, pattern, found, flags);
    const double classic_s = t1.ElapsedSeconds();
    Timer t2;
    cv::findChessboardCorners(equalised, pattern, found, flags);
    const double equalised_s = t2.ElapsedSeconds();
    Timer t3;
    const BoardDetection detection = DetectBoard(grey, board, DetectOptions());
    const double detect_s = t3.ElapsedSeconds();
    std::printf("%5d %3d/%3zu  %8.2f %8.2f %8.2f  %8.2f %d %s\n", f, visible, corners.size(),
                classic_s, equalised_s, masked_s, detect_s, detection.found,
                detection.method.c_str());
    std::fflush(stdout);
    total_classic += classic_s;
    total_equalised += equalised_s;
    total_masked += masked_s;
    total_detect += detect_s;
    ++done;
  }
  std::printf(
      "%d frames: classic %.2f s, equalised classic %.2f s, masked equalised classic %.2f s, "
      "DetectBoard %.2f s\n",
      done, total_classic, total_equalised, total_masked, total_detect);
  return 0;
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) { return omnirig::Main(argc, argv); }
