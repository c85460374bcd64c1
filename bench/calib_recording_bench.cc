// bench_calib_recording: calibration from a long recording. A board waved for two minutes at
// 20 Hz in front of the synthetic 1280x1024 catadioptric camera (DefaultCamera): 2,400 frames of
// smooth motion between board poses drawn around the mirror, every fifth stretch of 1.5 s taking
// the board out of view (frames without it, and half hidden by the mirror's hole on the way;
// synth::WavedBoardTrajectory). The frames are rendered ahead of time (not timed; a frame where
// no inner corner projects is the background render with fresh noise) and held as raw 8-bit grey
// pixels, read through an ImageReader that copies them out as a recording's raw mono8 frames are
// decoded. Then:
//   1. CalibrateImages as the recording job runs it (2 threads, overlays written): screening,
//      near duplicates, full detection of the candidates, view selection, calibration;
//   2. the calibration on every detected view: every frame the screen passes, detected fully (the
//      same detector options) and calibrated, no near duplicates skipped and no cap;
//   3. the path before screening (every frame detected, re-detection pass) on every 40th frame,
//      its time scaled by 40 as an estimate for the whole recording.
// Prints wall and process CPU seconds, the load average, frames per reason, views used, and the
// RMS ratio of 1 to 2 (target within 5 %); ray errors against the true camera.
//   bench_calib_recording [num_frames]   (default 2400)

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <time.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/imgcodecs.hpp>

#include "engine/calib/pipeline.h"
#include "engine/synth/presets.h"
#include "engine/synth/render.h"
#include "engine/util/parallel.h"
#include "engine/util/timer.h"
#include "testing/synth/calib_board.h"

namespace omnirig {
namespace {

namespace fs = std::filesystem;

constexpr double kRateHz = 20.0;
constexpr int kSegmentFrames = 30;  // 1.5 s between poses

double ProcessCpuSeconds() {
  timespec now{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &now);
  return now.tv_sec + 1e-9 * now.tv_nsec;
}

struct RunFigures {
  CalibrationReport report;
  double wall_s = 0.0;
  double cpu_s = 0.0;
  double load = 0.0;
};

RunFigures Run(const ImageReader& read, const std::vector<std::string>& names,
               const BoardSpec& board, int max_views, const fs::path& overlay_dir) {
  ImageCalibrationOptions options;
  options.calibrate.num_threads = 2;
  options.selection.max_views = max_views;
  RunFigures figures;
  const double cpu0 = ProcessCpuSeconds();
  Timer timer;
  figures.report = CalibrateImages(read, names, board, options, overlay_dir, ProgressSink());
  figures.wall_s = timer.ElapsedSeconds();
  figures.cpu_s = ProcessCpuSeconds() - cpu0;
  double load[1] = {0.0};
  if (getloadavg(load, 1) == 1) figures.load = load[0];
  return figures;
}

// The calibration on every detected view: every frame the screen passes (ScreenFrame), detected
// with the long path's detector options, all of them calibrated.
RunFigures EveryDetectedView(const ImageReader& read, const std::vector<std::string>& names,
                             const BoardSpec& board, std::vector<CalibrationView>* detected) {
  ImageCalibrationOptions options;
  options.calibrate.num_threads = 2;
  DetectOptions detect = options.detect;
  detect.try_costly_variants = false;
  RunFigures figures;
  const double cpu0 = ProcessCpuSeconds();
  Timer timer;
  std::vector<CalibrationView> views(names.size());
  int width = 0, height = 0;
  RunTasks(static_cast<int>(names.size()), 2, ProgressSink(),
           [&](int i, const ProgressSink&) {
             views[i].name = names[i];
             const cv::Mat grey = read(names[i], cv::IMREAD_GRAYSCALE);
             if (i == 0) {
               width = grey.cols;
               height = grey.rows;
             }
             if (ScreenFrame(grey, board).empty()) {
               views[i].detection.reason = "no whole board at screening";
               return;
             }
             views[i].detection = DetectBoard(grey, board, detect);
           },
           [](int) {});
  figures.report.timings.detect_s = timer.ElapsedSeconds();
  const double detect_s = figures.report.timings.detect_s;
  figures.report = Calibrate(views, width, height, board, options.calibrate, ProgressSink());
  figures.report.timings.detect_s = detect_s;
  *detected = views;
  figures.wall_s = timer.ElapsedSeconds();
  figures.cpu_s = ProcessCpuSeconds() - cpu0;
  double load[1] = {0.0};
  if (getloadavg(load, 1) == 1) figures.load = load[0];
  return figures;
}

double MeanRayErrorDeg(const synth::SynthCamera& truth, const CameraModel& estimate) {
  double sum = 0.0;
  int n = 0;
  for (int v = 0; v < truth.model.height; v += 8) {
    for (int u = 0; u < truth.model.width; u += 8) {
      const Eigen::Vector2d pixel(u, v);
      if (!synth::InAnnulus(truth, pixel)) continue;
      const auto a = Lift(truth.model.intrinsics, pixel);
      const auto b = Lift(estimate.intrinsics, pixel);
      if (!a || !b) continue;
      sum += std::acos(std::min(1.0, a->dot(*b)));
      ++n;
    }
  }
  return n ? sum / n * 180.0 / M_PI : -1.0;
}

void PrintRun(const char* label, const RunFigures& run, const synth::SynthCamera& camera) {
  std::map<std::string, int> reasons;
  for (const FrameReport& frame : run.report.frames) ++reasons[frame.reason];
  int detected = 0;
  for (const CalibrationImageReport& image : run.report.images) detected += !image.detector.empty();
  std::printf("%s\n", label);
  std::printf("   wall %.1f s, CPU %.1f s (both threads), load average %.1f at the end\n",
              run.wall_s, run.cpu_s, run.load);
  std::printf("   detect %.1f s (screen + detect + select), redetect %.1f s, calibrate %.1f s\n",
              run.report.timings.detect_s, run.report.timings.redetect_s,
              run.report.timings.total_s);
  std::printf("   views detected fully and calibrated on: %d, used %d, RMS %.4f px, ray error "
              "%.4f deg\n",
              detected, run.report.num_views_used, run.report.rms_px,
              MeanRayErrorDeg(camera, run.report.camera));
  std::printf("   frames:");
  for (const auto& [reason, count] : reasons) std::printf(" %s %d,", reason.c_str(), count);
  std::printf("\n");
}

int Main(int argc, char** argv) {
  const int num_frames = argc > 1 ? std::atoi(argv[1]) : 2400;
  if (num_frames < 60) {
    std::fprintf(stderr, "usage: bench_calib_recording [num_frames >= 60]\n");
    return 2;
  }
  const synth::SynthCamera camera = synth::DefaultCamera(1280, 1024);
  const synth::CheckerboardSpec board_spec;
  const uint64_t seed = 11;
  const std::vector<Rigid3d> trajectory = synth::WavedBoardTrajectory(camera, board_spec, num_frames, kSegmentFrames, seed);
  synth::Scene scene = synth::MakeCalibrationBackground(seed);
  const int board_index = scene.AddCheckerboard(board_spec, Rigid3d());
  const synth::Renderer renderer(camera, 2);
  synth::RenderOptions render;
  render.supersampling = 1;
  render.noise_sigma = 2.0;
  render.blur_sigma_px = 0.5;
  render.grayscale = true;
  render.num_threads = 2;
  std::printf("bench_calib_recording (%s): %d frames of %dx%d at %.0f Hz, board %dx%d\n",
              "renders held as raw grey frames", num_frames, camera.model.width,
              camera.model.height, kRateHz, board_spec.cols, board_spec.rows);
  Timer render_timer;
  auto frames = std::make_shared<std::vector<cv::Mat>>();
  std::vector<std::string> names;
  synth::RenderOptions clean = render;
  clean.noise_sigma = 0.0;
  scene.SetBoardPose(board_index, Rigid3d(Eigen::Quaterniond::Identity(),
                                          Eigen::Vector3d(0.0, 0.0, 100.0)));
  const cv::Mat background = renderer.Render(scene, Rigid3d(), clean);
  cv::RNG rng(seed);
  int num_hidden = 0;
  for (int f = 0; f < num_frames; ++f) {
    int visible = 0;
    for (const auto& corner : synth::ProjectBoardCorners(camera, trajectory[f], board_spec)) {
      visible += std::isfinite(corner.x());
    }
    if (visible == 0) {
      cv::Mat noise(background.size(), CV_16SC1);
      rng.fill(noise, cv::RNG::NORMAL, 0.0, render.noise_sigma);
      cv::Mat noisy;
      background.convertTo(noisy, CV_16SC1);
      noisy += noise;
      noisy.convertTo(noisy, CV_8UC1);
      frames->push_back(noisy);
      ++num_hidden;
    } else {
      scene.SetBoardPose(board_index, trajectory[f]);
      render.seed = seed * 100000 + f;
      frames->push_back(renderer.Render(scene, Rigid3d(), render));
    }
    char name[32];
    std::snprintf(name, sizeof(name), "t%08.3f.msg", f / kRateHz);
    names.push_back(name);
    if ((f + 1) % 200 == 0) {
      std::fprintf(stderr, "rendered %d / %d (%.0f s)\n", f + 1, num_frames,
                   render_timer.ElapsedSeconds());
    }
  }
  std::printf("   rendering (not timed below): %.0f s; %d frames show no inner corner\n",
              render_timer.ElapsedSeconds(), num_hidden);

  std::map<std::string, size_t> index;
  for (size_t f = 0; f < names.size(); ++f) index[names[f]] = f;
  const ImageReader read = [frames, index](const std::string& name, int flags) {
    const auto it = index.find(name);
    if (it == index.end()) return cv::Mat();
    cv::Mat image = (*frames)[it->second].clone();  // a raw frame's pixels, copied out
    if (flags == cv::IMREAD_COLOR) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
    return image;
  };
  const BoardSpec board = ToBoardSpec(board_spec);
  const fs::path overlays = fs::temp_directory_path() / "omnirig_bench_calib_recording";
  fs::remove_all(overlays);
  const RunFigures selected = Run(read, names, board, ImageCalibrationOptions().selection.max_views,
                                  overlays);
  fs::remove_all(overlays);
  PrintRun("1. default (screen, skip near duplicates, select views; overlays written)", selected,
           camera);
  std::vector<CalibrationView> detected;
  const RunFigures every = EveryDetectedView(read, names, board, &detected);
  PrintRun("2. every frame the screen passes, detected fully and calibrated (no cap, no overlays)",
           every, camera);
  int missing_selected = 0, missing_every = 0;
  const double rms_selected = RmsOverViews(selected.report.camera, board, detected, &missing_selected);
  const double rms_every = RmsOverViews(every.report.camera, board, detected, &missing_every);
  std::printf("RMS over every detected view (poses fitted with each model): selected model %.4f "
              "px, every view's %.4f px, ratio %.4f (target within 5 %%; views not fitted %d, %d)\n",
              rms_selected, rms_every, rms_selected / rms_every, missing_selected, missing_every);
  std::printf("RMS over each calibration's own views: ratio %.4f\n",
              selected.report.rms_px / every.report.rms_px);
  std::vector<std::string> subset;
  for (size_t f = 0; f < names.size(); f += 40) subset.push_back(names[f]);
  const RunFigures before = Run(read, subset, board, 0, "");
  PrintRun("3. the path before screening on every 40th frame (every frame detected, redetect pass)",
           before, camera);
  const double scale = static_cast<double>(names.size()) / subset.size();
  std::printf("estimated for all %zu frames: %.0f s wall, %.0f s CPU (x%.0f); ratio to 1: %.1fx "
              "wall, %.1fx CPU\n",
              names.size(), before.wall_s * scale, before.cpu_s * scale, scale,
              before.wall_s * scale / selected.wall_s, before.cpu_s * scale / selected.cpu_s);
  std::printf("target: %d frames of 1280x1024 in <= 60 s wall on 2 cores: %.1f s wall, %.1f s "
              "CPU\n",
              num_frames, selected.wall_s, selected.cpu_s);
  return 0;
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) { return omnirig::Main(argc, argv); }
