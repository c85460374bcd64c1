// bench_detect_bias: the systematic error of omnirig's board detector on synthetic renders.
//
// Renders board views of the synthetic catadioptric cameras (engine/synth, 1024x768, the
// relative-pose bench's render settings: 0.5 px blur, grey), runs DetectBoard, labels each corner
// by the nearest exact projection and prints the error's mean (x, y), its mean along the radial
// direction from the principal point and along the concave side of the board's curved edges
// (the unit normal of the image of the board's row and column lines through the corner,
// pointing to their centres of curvature), and the RMS, in bins of distance from the principal
// point and of the edges' sag over the refinement window. A mean that does not average to zero
// over many corners is a bias; "z" is the mean over its standard error.
//
// For each render setting (noise-free with and without blur, image noise 2 and 19 grey levels)
// and two boards: the full detector, and DetectBoardFromPose started at the exact corners (the
// sub-pixel refinement alone), with the junction fit after cornerSubPix (corner_fit.h) on and off.
// After each DetectBoard table, the grid check (grid_check.h): corners it refined again or
// dropped, corners > 0.5 px from the truth and the largest error with and without it (the tables
// skip errors over 2 px), DetectBoard's CPU time per view both ways and the check's own cost.
// First, the renders of api/relpose_job_test (800x600, seed 5), whose cam1/pair_007 has the
// corner that OpenCV's classic detector puts 3.9 px off (the grid check's reproduction case).
// Then real sets (../shared/data/real: ocamcalib VMR and KaidanOmni, both cameras of the fisheye
// stereo pairs): views found and the per-camera calibration's RMS, fit off and on and without
// the grid check, with the mean and largest move of a corner between fit off and on.
//
// Usage: bench_detect_bias [--quick] [--only synthetic|real]
//   --quick: noise-free renders with 0.5 px blur only, 12 views per board, no real sets.

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/calib/grid_check.h"
#include "engine/geometry/unified_camera.h"
#include "engine/synth/presets.h"
#include "testing/synth/calib_board.h"

namespace omnirig {
namespace {

// Running sums of one group of corner errors.
struct Accumulator {
  int n = 0;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  double sum_sq = 0.0;  // |e|^2
  double radial = 0.0, radial_sq = 0.0;
  double concave = 0.0, concave_sq = 0.0;
  double sag = 0.0;

  void Add(const Eigen::Vector2d& e, double e_radial, double e_concave, double sag_px) {
    ++n;
    sum += e;
    sum_sq += e.squaredNorm();
    radial += e_radial;
    radial_sq += e_radial * e_radial;
    concave += e_concave;
    concave_sq += e_concave * e_concave;
    sag += sag_px;
  }
};

// z-score of a mean from its sums.
double ZScore(double sum, double sum_sq, int n) {
  if (n < 2) return NAN;
  const double mean = sum / n;
  const double var = std::max(0.0, sum_sq / n - mean * mean);
  return mean / std::sqrt(var / (n - 1) + 1e-30);
}

void PrintRow(const std::string& label, const Accumulator& a) {
  if (a.n == 0) {
    std::printf("| %-16s | %6d |\n", label.c_str(), 0);
    return;
  }
  std::printf(
      "| %-16s | %6d | %+8.4f | %+8.4f | %+8.4f | %6.1f | %+8.4f | %6.1f | %7.4f | %6.3f |\n",
      label.c_str(), a.n, a.sum.x() / a.n, a.sum.y() / a.n, a.radial / a.n,
      ZScore(a.radial, a.radial_sq, a.n), a.concave / a.n, ZScore(a.concave, a.concave_sq, a.n),
      std::sqrt(a.sum_sq / a.n), a.sag / a.n);
}

void PrintHeader(const std::string& title) {
  std::printf("\n%s\n", title.c_str());
  std::printf("| %-16s | %6s | %8s | %8s | %8s | %6s | %8s | %6s | %7s | %6s |\n", "group", "n",
              "mean x", "mean y", "radial", "z", "concave", "z", "rms", "sag px");
  std::printf(
      "|------------------|--------|----------|----------|----------|--------|----------|"
      "--------|---------|--------|\n");
}

// The image of the board line through `point` along board direction `axis`: its unit concave
// normal (towards the centre of curvature) and its sag over a chord of half-length half_px.
struct CurveGeometry {
  Eigen::Vector2d concave = Eigen::Vector2d::Zero();
  double curvature = 0.0;  // 1 / px
};

CurveGeometry LineCurvature(const UnifiedIntrinsics& k, const Rigid3d& cam_from_board,
                            const Eigen::Vector3d& point, const Eigen::Vector3d& axis, double h) {
  const auto p0 = Project(k, cam_from_board * point);
  const auto pm = Project(k, cam_from_board * (point - h * axis));
  const auto pp = Project(k, cam_from_board * (point + h * axis));
  CurveGeometry geometry;
  if (!p0 || !pm || !pp) return geometry;
  const Eigen::Vector2d tangent = (*pp - *pm) / 2.0;
  const Eigen::Vector2d t_hat = tangent.normalized();
  const Eigen::Vector2d second = *pp + *pm - 2.0 * *p0;
  const Eigen::Vector2d normal = second - second.dot(t_hat) * t_hat;
  if (normal.norm() < 1e-12) return geometry;
  geometry.concave = normal.normalized();
  geometry.curvature = normal.norm() / tangent.squaredNorm();
  return geometry;
}

struct BiasTables {
  Accumulator all;
  std::array<Accumulator, 6> by_radius;  // 0: < 150 px, then 50 px bins, 5: >= 350 px
  std::array<Accumulator, 5> by_sag;     // < 0.02, < 0.05, < 0.1, < 0.2, >= 0.2 px
  int views = 0, found = 0;
};

// What the grid check did over a set's detections, and the corners far from the truth (which
// the bias tables leave out: they label each corner by the nearest exact one and skip errors
// over 2 px).
struct GrossErrors {
  int views = 0, found = 0, rerefined = 0, dropped = 0;
  int over_half_px = 0;
  double largest_px = 0.0;
  double cpu_s = 0.0;

  void Add(const BoardDetection& detection, const std::vector<Eigen::Vector2d>& truth) {
    ++views;
    if (!detection.found) return;
    ++found;
    rerefined += detection.num_rerefined_corners;
    dropped += static_cast<int>(detection.dropped_corner_ids.size());
    for (const Eigen::Vector2d& corner : detection.corners_px) {
      double nearest = std::numeric_limits<double>::infinity();
      for (const Eigen::Vector2d& exact : truth)
        nearest = std::min(nearest, (exact - corner).norm());
      over_half_px += nearest > 0.5;
      largest_px = std::max(largest_px, nearest);
    }
  }
  void Print(const char* label) const {
    std::printf(
        "%-22s %d of %d views found, %d corners re-refined, %d dropped; corners > 0.5 px from the "
        "truth: %d, largest error %.3f px; DetectBoard %.1f ms CPU per view\n",
        label, found, views, rerefined, dropped, over_half_px, largest_px,
        1e3 * cpu_s / std::max(1, views));
  }
};

double CpuSeconds(std::clock_t start) {
  return static_cast<double>(std::clock() - start) / CLOCKS_PER_SEC;
}

// Adds one detection's errors against the exact corners of its view.
void AddDetection(const synth::SynthCamera& camera, const Rigid3d& cam_from_board,
                  const synth::CheckerboardSpec& spec, const std::vector<Eigen::Vector2d>& truth,
                  const BoardDetection& detection, BiasTables* tables) {
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  const std::vector<Eigen::Vector3d> object = synth::BoardCorners(spec);
  const Eigen::Vector2d pp(k.u0(), k.v0());
  for (const Eigen::Vector2d& corner : detection.corners_px) {
    int id = 0;
    for (size_t t = 1; t < truth.size(); ++t) {
      if ((truth[t] - corner).squaredNorm() < (truth[id] - corner).squaredNorm()) id = t;
    }
    const Eigen::Vector2d e = corner - truth[id];
    if (e.norm() > 2.0) continue;  // a mislabelled corner, not a bias
    const Eigen::Vector2d radial_dir = (truth[id] - pp).normalized();
    const double h = 0.25 * spec.square_size_m;
    const CurveGeometry along_x =
        LineCurvature(k, cam_from_board, object[id], Eigen::Vector3d::UnitX(), h);
    const CurveGeometry along_y =
        LineCurvature(k, cam_from_board, object[id], Eigen::Vector3d::UnitY(), h);
    const double e_concave = 0.5 * (e.dot(along_x.concave) + e.dot(along_y.concave));
    // The sag of the edges over the refinement window's half-width (0.4 of the local square).
    const int r = id / spec.cols, c = id % spec.cols;
    double square_px = 1e9;
    for (const auto& [dr, dc] : {std::pair{0, 1}, {0, -1}, {1, 0}, {-1, 0}}) {
      if (r + dr < 0 || r + dr >= spec.rows || c + dc < 0 || c + dc >= spec.cols) continue;
      square_px = std::min(square_px, (truth[(r + dr) * spec.cols + c + dc] - truth[id]).norm());
    }
    const double half = std::clamp(std::lround(0.4 * square_px), 2L, 15L);
    const double sag = 0.5 * 0.5 * (along_x.curvature + along_y.curvature) * half * half;
    const double radius = (truth[id] - pp).norm();
    tables->all.Add(e, e.dot(radial_dir), e_concave, sag);
    tables->by_radius[std::clamp(static_cast<int>((radius - 100.0) / 50.0), 0, 5)].Add(
        e, e.dot(radial_dir), e_concave, sag);
    const int sag_bin = sag < 0.02 ? 0 : sag < 0.05 ? 1 : sag < 0.1 ? 2 : sag < 0.2 ? 3 : 4;
    tables->by_sag[sag_bin].Add(e, e.dot(radial_dir), e_concave, sag);
  }
}

void PrintTables(const std::string& title, const BiasTables& tables) {
  char full[512];
  std::snprintf(full, sizeof(full), "%s: %d of %d views found", title.c_str(), tables.found,
                tables.views);
  PrintHeader(full);
  PrintRow("all", tables.all);
  const char* radius_names[] = {"r < 150 px",   "r 150-200 px", "r 200-250 px",
                                "r 250-300 px", "r 300-350 px", "r >= 350 px"};
  for (size_t b = 0; b < tables.by_radius.size(); ++b)
    PrintRow(radius_names[b], tables.by_radius[b]);
  const char* sag_names[] = {"sag < 0.02", "sag 0.02-0.05", "sag 0.05-0.1", "sag 0.1-0.2",
                             "sag >= 0.2"};
  for (size_t b = 0; b < tables.by_sag.size(); ++b) PrintRow(sag_names[b], tables.by_sag[b]);
}

struct RenderConfig {
  const char* name;
  double noise;
  double blur;
};

struct SetConfig {
  const char* name;
  synth::CheckerboardSpec board;
  double min_distance_m, max_distance_m;
};

// The grid check on a rendered set: DetectBoard's detections with it (`checked`, from the bias
// tables' pass) against a pass without it (gross errors against the truth, CPU time per view),
// and the check's own cost on the refined grids.
void PrintGridCheck(const synth::MonoCalibrationSet& set, const BoardSpec& board,
                    DetectOptions options, const std::vector<BoardDetection>& checked,
                    double checked_cpu_s) {
  GrossErrors with, without;
  with.cpu_s = checked_cpu_s;
  std::vector<std::vector<Eigen::Vector2d>> grids;
  options.check_grid = false;
  for (size_t v = 0; v < set.images.size(); ++v) {
    with.Add(checked[v], set.corners_px[v]);
    if (checked[v].found && checked[v].dropped_corner_ids.empty()) {
      grids.push_back(checked[v].corners_px);
    }
    const auto cpu_start = std::clock();
    const BoardDetection detection = DetectBoard(set.images[v], board, options);
    without.cpu_s += CpuSeconds(cpu_start);
    without.Add(detection, set.corners_px[v]);
  }
  with.Print("  with the grid check:");
  without.Print("  without:");
  constexpr int kRepeats = 200;
  const auto cpu_start = std::clock();
  size_t flagged = 0;
  for (int i = 0; i < kRepeats; ++i) {
    for (const auto& grid : grids) {
      flagged += FindInconsistentCorners(grid, board.cols, board.rows, options.grid_check).size();
    }
  }
  std::printf("  grid check alone on the %zu refined grids: %.1f us CPU per view (%zu flagged)\n",
              grids.size(),
              1e6 * CpuSeconds(cpu_start) / std::max<size_t>(1, kRepeats * grids.size()),
              flagged / kRepeats);
}

// The full detector on every view, and the refinement alone started at the exact corners.
void RunConfig(const SetConfig& set_config, const RenderConfig& render, int num_views,
               uint64_t seed) {
  const auto cpu_start = std::clock();
  const auto wall_start = std::chrono::steady_clock::now();
  synth::MonoCalibrationOptions options;
  options.num_views = num_views;
  options.board = set_config.board;
  options.poses.min_distance_m = set_config.min_distance_m;
  options.poses.max_distance_m = set_config.max_distance_m;
  options.render.noise_sigma = render.noise;
  options.render.blur_sigma_px = render.blur;
  options.render.grayscale = true;
  options.render.num_threads = 2;
  options.seed = seed;
  const synth::MonoCalibrationSet set = synth::MakeMonoCalibrationSet(options);
  const BoardSpec board = ToBoardSpec(set.board);
  for (const bool fit : {false, true}) {
    DetectOptions detect_options;
    detect_options.fit_corner_model = fit;
    BiasTables detected, from_truth;
    std::vector<BoardDetection> detections;
    double detect_cpu_s = 0.0;
    for (size_t v = 0; v < set.images.size(); ++v) {
      ++detected.views;
      ++from_truth.views;
      const auto cpu_start = std::clock();
      detections.push_back(DetectBoard(set.images[v], board, detect_options));
      detect_cpu_s += CpuSeconds(cpu_start);
      const BoardDetection& detection = detections.back();
      if (detection.found) {
        ++detected.found;
        AddDetection(set.camera, set.cam_from_board[v], set.board, set.corners_px[v], detection,
                     &detected);
      }
      const BoardDetection refined = DetectBoardFromPose(set.images[v], board, set.camera.model,
                                                         set.cam_from_board[v], detect_options);
      if (refined.found) {
        ++from_truth.found;
        AddDetection(set.camera, set.cam_from_board[v], set.board, set.corners_px[v], refined,
                     &from_truth);
      }
    }
    const std::string suffix = std::string(set_config.name) + ", " + render.name +
                               (fit ? ", corner model fit ON" : ", corner model fit OFF");
    PrintTables("DetectBoard, " + suffix, detected);
    PrintTables("refinement from the exact corners, " + suffix, from_truth);
    PrintGridCheck(set, board, detect_options, detections, detect_cpu_s);
  }
  std::printf("(%.1f s wall, %.1f s CPU)\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count(),
              static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC);
}

// api/relpose_job_test's renders, detected with and without the grid check.
void RunRelposeJobRenders() {
  synth::StereoBoardOptions options = synth::QuickStereoBoardOptions(8, 5);
  options.render.num_threads = 2;
  const synth::StereoBoardSet set = synth::MakeStereoBoardSet(options);
  const BoardSpec board = ToBoardSpec(set.board);
  std::printf("\napi/relpose_job_test's renders (2 x 8 views, 800x600, seed 5)\n");
  for (const bool check : {true, false}) {
    DetectOptions detect_options;
    detect_options.check_grid = check;
    GrossErrors errors;
    for (int camera = 0; camera < 2; ++camera) {
      for (size_t i = 0; i < set.names.size(); ++i) {
        const auto cpu_start = std::clock();
        const BoardDetection detection = DetectBoard(set.images[camera][i], board, detect_options);
        errors.cpu_s += CpuSeconds(cpu_start);
        errors.Add(detection, set.corners_px[camera][i]);
      }
    }
    errors.Print(check ? "  with the grid check:" : "  without:");
  }
}

// One real set: every image detected with the junction fit off and on, each camera calibrated
// from its own detections (default options).
void RunRealSet(const std::string& name, const std::filesystem::path& dir,
                const std::string& prefix, const BoardSpec& board) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(dir)) {
    std::printf("| %-34s | (not found: %s)\n", name.c_str(), dir.string().c_str());
    return;
  }
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string file = entry.path().filename().string();
    if (entry.path().extension() == ".jpg" && file.rfind(prefix, 0) == 0) files.push_back(file);
  }
  std::sort(files.begin(), files.end());
  std::vector<cv::Mat> images;
  for (const std::string& file : files) {
    images.push_back(cv::imread((dir / file).string(), cv::IMREAD_GRAYSCALE));
  }
  // Variants: junction fit off, on (both with the grid check), on without the grid check.
  struct Variant {
    const char* name;
    bool fit, check;
  };
  const std::array<Variant, 3> variants = {Variant{"off", false, true}, Variant{"on", true, true},
                                           Variant{"on, no grid check", true, false}};
  std::array<std::vector<CalibrationView>, 3> views;
  std::array<double, 3> detect_cpu_s = {0.0, 0.0, 0.0};
  double move_sum = 0.0, move_max = 0.0;
  int moves = 0;
  for (size_t i = 0; i < images.size(); ++i) {
    for (size_t k = 0; k < variants.size(); ++k) {
      DetectOptions options;
      options.fit_corner_model = variants[k].fit;
      options.check_grid = variants[k].check;
      const auto cpu_start = std::clock();
      views[k].push_back({files[i], DetectBoard(images[i], board, options)});
      detect_cpu_s[k] += CpuSeconds(cpu_start);
    }
    const BoardDetection& off = views[0].back().detection;
    const BoardDetection& on = views[1].back().detection;
    if (!off.found || !on.found || off.corner_ids != on.corner_ids) continue;
    for (size_t k = 0; k < on.corners_px.size(); ++k) {
      const double move = (on.corners_px[k] - off.corners_px[k]).norm();
      move_sum += move;
      move_max = std::max(move_max, move);
      ++moves;
    }
  }
  for (size_t k = 0; k < variants.size(); ++k) {
    int found = 0, rerefined = 0, dropped = 0;
    for (const auto& view : views[k]) {
      found += view.detection.found;
      rerefined += view.detection.num_rerefined_corners;
      dropped += static_cast<int>(view.detection.dropped_corner_ids.size());
    }
    std::printf("| %-34s | %-17s | %5d/%-3zu |", name.c_str(), variants[k].name, found,
                files.size());
    try {
      const CalibrationReport report = Calibrate(views[k], images[0].cols, images[0].rows, board,
                                                 CalibrationOptions(), ProgressSink());
      std::printf(" %5d | %9.4f | %9.4f |", report.num_views_used, report.rms_px,
                  report.rms_all_px);
    } catch (const std::exception& e) {
      std::printf(" calibration failed: %s |", e.what());
    }
    if (k == 1) {
      std::printf(" %.4f / %.4f px |", move_sum / std::max(1, moves), move_max);
    } else {
      std::printf(" %-20s |", "");
    }
    std::printf(" %3d / %3d | %5.2f s\n", rerefined, dropped, detect_cpu_s[k]);
  }
}

void RunReal() {
  const std::filesystem::path real =
      std::filesystem::path(OMNIRIG_SOURCE_DIR) / ".." / "shared" / "data" / "real";
  std::printf(
      "\nReal sets: views found, per-camera calibration RMS of the inliers and of every corner "
      "(px), junction fit off/on (with the grid check) and on without the grid check; corner "
      "move = mean / largest distance between the fit-off and fit-on detections; grid = corners "
      "the grid check refined again / dropped; detect = CPU s of DetectBoard over the set\n");
  std::printf("| %-34s | %-17s | %9s | %5s | %9s | %9s | %-20s | %-9s | %s\n", "set", "fit",
              "found", "used", "rms", "rms all", "corner move", "grid", "detect");
  BoardSpec board;
  board.square_size_m = 0.03;
  board.cols = 6;
  board.rows = 7;
  RunRealSet("ocamcalib-vmr", real / "ocamcalib-vmr", "", board);
  board.cols = 7;
  board.rows = 11;
  RunRealSet("ocamcalib-kaidanomni", real / "ocamcalib-kaidanomni", "", board);
  board.cols = 9;
  board.rows = 6;
  board.square_size_m = 0.02423;
  RunRealSet("fisheye-stereo-pairs, left (cam0)", real / "fisheye-stereo-pairs", "left", board);
  RunRealSet("fisheye-stereo-pairs, right (cam1)", real / "fisheye-stereo-pairs", "right", board);
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  bool quick = false;
  std::string only;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    if (std::strcmp(argv[i], "--only") == 0 && i + 1 < argc) only = argv[++i];
  }
  using omnirig::synth::CheckerboardSpec;
  CheckerboardSpec preset;
  preset.cols = 11;
  preset.rows = 8;
  const std::vector<omnirig::SetConfig> sets = {
      {"board 8x6 of 40 mm at 0.35-1.2 m", CheckerboardSpec(), 0.35, 1.2},
      {"board 11x8 of 40 mm at 0.35-1.2 m", preset, 0.35, 1.2}};
  const std::vector<omnirig::RenderConfig> renders = {
      {"noise-free, no blur", 0.0, 0.0},
      {"noise-free, blur 0.5 px", 0.0, 0.5},
      {"noise 2 grey levels, blur 0.5 px", 2.0, 0.5},
      {"noise 19 grey levels, blur 0.5 px", 19.0, 0.5}};
  try {
    if (only == "real") {
      omnirig::RunReal();
      return 0;
    }
    omnirig::RunRelposeJobRenders();
    for (const auto& set : sets) {
      for (const auto& render : renders) {
        // Quick: the relative-pose bench's render setting alone, fewer views.
        if (quick && render.blur == 0.0) continue;
        omnirig::RunConfig(set, render, quick ? 12 : 30, 21);
        if (quick) break;
      }
    }
    if (only.empty() && !quick) omnirig::RunReal();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_detect_bias: %s\n", e.what());
    return 1;
  }
  return 0;
}
