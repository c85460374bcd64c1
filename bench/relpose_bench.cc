// bench_relpose: accuracy of the stereo rig's relative pose (against its targets), next to the
// paper's method and cv::omnidir::stereoCalibrate on the same corners, in the same run.
//
//   1. Synthetic vertical rig (100 mm), 20 pairs rendered at 1024x768 per seed, 3 seeds, corners
//      from omnirig's own detector, in three readings of "renders with 0.2 px noise": image
//      noise of 2 grey levels with the corners as detected; the same + 0.2 px Gaussian noise on
//      every corner; image noise of 19 grey levels (the detector's own error then 0.16 px
//      RMS). Mean, spread and worst of the baseline error (target < 0.01 %) and rotation error
//      (< 0.01 deg) over the seeds, and how many seeds meet both, for: known cameras (the rig
//      alone), eq. (9) alone, the paper's average of per-pair poses, cameras calibrated per
//      camera from the same images with and without the joint intrinsics refinement (the job's
//      default), cv::omnidir::stereoCalibrate (its own initialisation, COUNT 300 / EPS 1e-8).
//   2. The estimator's floor without rendering: exact corners + 0.2 px noise, cameras known,
//      20 / 80 / 320 pairs, 20 seeds each: how many pairs the 0.01 % target needs at that noise;
//      then the same with both cameras' intrinsics refined with the rig (self-calibration, the
//      "free" model, started at the true cameras) at 0.2 px and at reading A's 0.025 px: the
//      spread any unbiased estimate of a self-calibrated rig has on such data.
//   3. Triangulation of the board corners of 10 new pairs about 1 m away with each estimated
//      rig (target: mean error < 0.5 % of the range).
//   4. Real fisheye pairs (../shared/data/real/fisheye-stereo-pairs, left = cam0, right =
//      cam1, 9 x 6 corners, 24.23 mm): baseline against the reference 109.96 mm (target within
//      0.2 %) and RMS (< 0.5 px); the reference's own method (cv::fisheye::stereoCalibrate, the
//      Kannala-Brandt model, its 12 iterations and converged) and cv::omnidir on our corners;
//      what fixing / freeing k5, skew and the tangential terms, the robust loss, pair rejection
//      and dropping outer corners do; the baseline without each pair and from each half; the
//      job's default: the intrinsics model chosen by leave-one-pair-out cross-validation
//      (engine/rig/relpose_model_select.h), with each candidate's held-out error, with and
//      without the test for unsynchronised pairs (engine/rig/relpose_sync.h), whose
//      per-pair statistics it prints.
//   5. (--only preset; not in a full run: tens of CPU minutes) The synthetic readings B and C
//      with a recording preset: 60 pairs of a board of 11 x 8 corners of 40 mm, 3 seeds, all
//      methods incl. cv::omnidir::stereoCalibrate on the same renders.
// RMS everywhere is sqrt(mean |e|^2) of the Euclidean corner error, as OpenCV reports it.
//
//   6. The camera chain (--only chain): rigs with given calibrations, kept or refined
//      with the calibrations' own views, against cv::omnidir::stereoCalibrate, 5 seeds.
//   7. (--only sync; not in a full run) The synchronisation test's false-alarm rate on the
//      renderer's synchronised pairs, with its 95 % interval, and its power on pairs whose
//      board moved between the exposures (RunSyncFalseAlarms).
// Usage: bench_relpose [--quick] [--data DIR] [--only synthetic|floor|preset|real|chain|sync]
//   [--seeds N] [--first-seed K] [--cache DIR] [--csv FILE]
//   (DIR: the folder holding the real data sets; --only runs one part, "synthetic" includes
//   the floor; the rest are for "sync": N rendered rigs from seed 3000 + K, kept in the cache
//   folder for reruns, first-round per-pair statistics to FILE)

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <iterator>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <Eigen/Core>
#include <opencv2/calib3d.hpp>
#include <opencv2/ccalib/omnidir.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>

#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/estimators/board_pose.h"
#include "engine/estimators/triangulation.h"
#include "engine/rig/relative_pose.h"
#include "engine/rig/relpose_corner_order.h"
#include "engine/rig/relpose_model_select.h"
#include "engine/synth/presets.h"
#include "testing/synth/calib_board.h"

namespace omnirig {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

struct Row {
  std::string method;
  bool ok = false;
  Rigid3d cam0_from_cam1;
  double rms_px = NAN;
  double time_s = NAN;
  std::string note;
};

void PrintRows(const std::string& title, const std::vector<Row>& rows, const Rigid3d* truth,
               double reference_baseline_m) {
  std::printf("\n%s\n", title.c_str());
  std::printf("| %-44s | %12s | %10s | %10s | %8s | %7s | %s\n", "method", "baseline mm", "error %",
              "rot err deg", "RMS px", "time s", "note");
  std::printf("|%s|%s|%s|%s|%s|%s|---\n", std::string(46, '-').c_str(),
              std::string(14, '-').c_str(), std::string(12, '-').c_str(),
              std::string(12, '-').c_str(), std::string(10, '-').c_str(),
              std::string(9, '-').c_str());
  for (const Row& row : rows) {
    if (!row.ok) {
      std::printf("| %-44s | %12s | %10s | %10s | %8s | %7s | %s\n", row.method.c_str(), "-", "-",
                  "-", "-", "-", row.note.c_str());
      continue;
    }
    const double baseline = row.cam0_from_cam1.translation.norm();
    const double error_pct = 100.0 * (baseline - reference_baseline_m) / reference_baseline_m;
    char rotation[32] = "-";
    if (truth != nullptr) {
      std::snprintf(rotation, sizeof(rotation), "%.5f",
                    RotationDistanceRad(row.cam0_from_cam1.rotation, truth->rotation) * kDegPerRad);
    }
    char rms[32] = "-";
    if (std::isfinite(row.rms_px)) std::snprintf(rms, sizeof(rms), "%.4f", row.rms_px);
    char time[32] = "-";
    if (std::isfinite(row.time_s)) std::snprintf(time, sizeof(time), "%.3f", row.time_s);
    std::printf("| %-44s | %12.4f | %+10.4f | %10s | %8s | %7s | %s\n", row.method.c_str(),
                baseline * 1e3, error_pct, rotation, rms, time, row.note.c_str());
  }
}

void AddCornerNoise(double sigma_px, std::mt19937* rng, BoardDetection* detection) {
  std::normal_distribution<double> noise(0.0, sigma_px);
  for (auto& corner : detection->corners_px) corner += Eigen::Vector2d(noise(*rng), noise(*rng));
}

// Renames a detection's ids after the ground truth's nearest corner, for measurements that
// must not depend on which end of a symmetric board the detector started from.
void LabelByGroundTruth(const std::vector<Eigen::Vector2d>& truth, BoardDetection* detection) {
  for (size_t c = 0; c < detection->corners_px.size(); ++c) {
    int best = 0;
    for (size_t id = 1; id < truth.size(); ++id) {
      if ((truth[id] - detection->corners_px[c]).squaredNorm() <
          (truth[best] - detection->corners_px[c]).squaredNorm()) {
        best = static_cast<int>(id);
      }
    }
    detection->corner_ids[c] = best;
  }
}

std::vector<StereoBoardPair> DetectPairs(const synth::StereoBoardSet& set, const BoardSpec& board,
                                         double corner_noise_px, bool label_by_truth,
                                         double* max_detection_error_px, uint64_t seed = 42,
                                         double* rms_detection_error_px = nullptr) {
  std::mt19937 rng(static_cast<uint32_t>(seed));
  std::vector<StereoBoardPair> pairs;
  *max_detection_error_px = 0.0;
  double sum_squares = 0.0;
  int count = 0;
  for (size_t i = 0; i < set.names.size(); ++i) {
    StereoBoardPair pair;
    pair.name = set.names[i];
    BoardDetection* detections[2] = {&pair.cam0, &pair.cam1};
    for (int c = 0; c < 2; ++c) {
      *detections[c] = DetectBoard(set.images[c][i], board, DetectOptions());
      if (!detections[c]->found) continue;
      BoardDetection labelled = *detections[c];
      LabelByGroundTruth(set.corners_px[c][i], &labelled);
      for (size_t k = 0; k < labelled.corners_px.size(); ++k) {
        const double error =
            (labelled.corners_px[k] - set.corners_px[c][i][labelled.corner_ids[k]]).norm();
        *max_detection_error_px = std::max(*max_detection_error_px, error);
        sum_squares += error * error;
        ++count;
      }
      if (label_by_truth) *detections[c] = labelled;
      AddCornerNoise(corner_noise_px, &rng, detections[c]);
    }
    pairs.push_back(pair);
  }
  if (rms_detection_error_px != nullptr) {
    *rms_detection_error_px = count > 0 ? std::sqrt(sum_squares / count) : NAN;
  }
  return pairs;
}

// The corners of the full detections of the pairs that our estimate used, as OpenCV's stereo
// calibrations take them: cam1's corners in the order our estimate settled on, so that every
// method sees identical correspondences.
struct CvCorrespondences {
  std::vector<cv::Mat> object_points, image_points0, image_points1;
};

CvCorrespondences BuildCvCorrespondences(const BoardSpec& board,
                                         const std::vector<StereoBoardPair>& pairs,
                                         const RelativePoseReport& ours) {
  const std::vector<BoardSymmetry> symmetries = BoardGridSymmetries(board);
  const std::vector<Eigen::Vector3d> object = board.ObjectPoints();
  std::vector<cv::Mat> object_points, image_points0, image_points1;
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (!ours.pairs[i].used) continue;
    const int n = board.NumCorners();
    if (static_cast<int>(pairs[i].cam0.corners_px.size()) != n ||
        static_cast<int>(pairs[i].cam1.corners_px.size()) != n) {
      continue;
    }
    cv::Mat obj(1, n, CV_64FC3), img0(1, n, CV_64FC2), img1(1, n, CV_64FC2);
    const auto& permutation = symmetries[ours.pairs[i].cam1_order].permutation;
    for (int c = 0; c < n; ++c) {
      const int id = pairs[i].cam0.corner_ids[c];
      obj.at<cv::Vec3d>(0, c) = cv::Vec3d(object[id].x(), object[id].y(), object[id].z());
      img0.at<cv::Vec2d>(0, c) =
          cv::Vec2d(pairs[i].cam0.corners_px[c].x(), pairs[i].cam0.corners_px[c].y());
    }
    for (int c = 0; c < n; ++c) {
      const int id = permutation[pairs[i].cam1.corner_ids[c]];
      // Position of corner `id` in cam0's list (ids of a full detection are a permutation).
      const int slot = static_cast<int>(
          std::find(pairs[i].cam0.corner_ids.begin(), pairs[i].cam0.corner_ids.end(), id) -
          pairs[i].cam0.corner_ids.begin());
      img1.at<cv::Vec2d>(0, slot) =
          cv::Vec2d(pairs[i].cam1.corners_px[c].x(), pairs[i].cam1.corners_px[c].y());
    }
    object_points.push_back(obj);
    image_points0.push_back(img0);
    image_points1.push_back(img1);
  }
  return {object_points, image_points0, image_points1};
}

// cv::omnidir::stereoCalibrate (Mei model, k1 k2 p1 p2, skew fixed) from its own
// initialisation, run to convergence.
Row RunOmnidirStereo(const BoardSpec& board, const std::vector<StereoBoardPair>& pairs,
                     const RelativePoseReport& ours, cv::Size size0, cv::Size size1) {
  Row row;
  row.method = "cv::omnidir::stereoCalibrate";
  auto [object_points, image_points0, image_points1] = BuildCvCorrespondences(board, pairs, ours);
  cv::Mat k0, k1, xi0, xi1, d0, d1, rvec, tvec, idx;
  std::vector<cv::Mat> rvecs, tvecs;
  const auto start = std::chrono::steady_clock::now();
  try {
    row.rms_px = cv::omnidir::stereoCalibrate(
        object_points, image_points0, image_points1, size0, size1, k0, xi0, d0, k1, xi1, d1, rvec,
        tvec, rvecs, tvecs, cv::omnidir::CALIB_FIX_SKEW,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 300, 1e-8), idx);
  } catch (const cv::Exception& e) {
    row.note = std::string("threw: ") + e.what();
    return row;
  }
  row.time_s = Seconds(start);
  // OpenCV's (rvec, tvec) maps its first camera (our cam0) into its second: cam1_from_cam0.
  cv::Mat rotation_cv;
  cv::Rodrigues(rvec, rotation_cv);
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  cv::cv2eigen(rotation_cv, rotation);
  cv::cv2eigen(tvec.reshape(1, 3), translation);
  row.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond(rotation), translation).Inverse();
  row.ok = std::isfinite(row.rms_px) && row.cam0_from_cam1.translation.allFinite();
  if (row.ok && (row.rms_px > 100.0 || row.cam0_from_cam1.translation.norm() > 10.0)) {
    row.ok = false;
    char note[160];
    std::snprintf(note, sizeof(note), "diverged: RMS %.3g px, baseline %.3g m, xi %.3g / %.3g",
                  row.rms_px, row.cam0_from_cam1.translation.norm(), xi0.at<double>(0),
                  xi1.at<double>(0));
    row.note = note;
    return row;
  }
  row.note = std::to_string(idx.total()) + " pairs used, xi " + std::to_string(xi0.at<double>(0)) +
             " / " + std::to_string(xi1.at<double>(0));
  return row;
}

Row OurRow(const std::string& method, const CameraModel& cam0, const CameraModel& cam1,
           const BoardSpec& board, const std::vector<StereoBoardPair>& pairs,
           const RelativePoseOptions& options, RelativePoseReport* out = nullptr) {
  const auto start = std::chrono::steady_clock::now();
  const auto cpu_start = std::clock();
  const RelativePoseReport report = EstimateRelativePose(cam0, cam1, board, pairs, options);
  Row row;
  row.method = method;
  row.time_s = Seconds(start);
  row.ok = report.success;
  row.cam0_from_cam1 = report.rig.cam0_from_cam1;
  row.rms_px = report.rms_px;
  char note[200];
  std::snprintf(note, sizeof(note),
                "%d/%zu pairs, baseline std %.4f mm (cluster-robust %.4f), rot std %.5f deg, "
                "%.2f s CPU",
                report.num_pairs_used, pairs.size(), report.baseline_std_m * 1e3,
                report.baseline_std_robust_m * 1e3, report.rotation_std_deg,
                static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC);
  row.note = report.success ? note : report.message;
  if (out != nullptr) *out = report;
  return row;
}

CameraModel CalibrateCamera(const std::vector<StereoBoardPair>& pairs, int camera, int width,
                            int height, const BoardSpec& board, double* rms_px,
                            const CalibrationOptions& options = CalibrationOptions()) {
  std::vector<CalibrationView> views;
  for (const StereoBoardPair& pair : pairs) {
    views.push_back({pair.name, camera == 0 ? pair.cam0 : pair.cam1});
  }
  const CalibrationReport report = Calibrate(views, width, height, board, options, ProgressSink());
  *rms_px = report.rms_px;
  return report.camera;
}

struct TriangulationStats {
  int num_points = 0;
  double mean_error_pct = 0.0;
  double max_error_pct = 0.0;
  double mean_range_m = 0.0;
};

TriangulationStats TriangulateBoards(const synth::StereoBoardSet& set, const BoardSpec& board,
                                     const StereoRig& rig,
                                     const std::vector<StereoBoardPair>& pairs) {
  TriangulationStats stats;
  const std::vector<Eigen::Vector3d> object = board.ObjectPoints();
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (!pairs[i].cam0.found || !pairs[i].cam1.found) continue;
    std::vector<int> slot1(board.NumCorners(), -1);
    for (size_t c = 0; c < pairs[i].cam1.corner_ids.size(); ++c) {
      slot1[pairs[i].cam1.corner_ids[c]] = static_cast<int>(c);
    }
    for (size_t c = 0; c < pairs[i].cam0.corner_ids.size(); ++c) {
      const int id = pairs[i].cam0.corner_ids[c];
      if (slot1[id] < 0) continue;
      const auto bearing0 = Lift(rig.cam0.intrinsics, pairs[i].cam0.corners_px[c]);
      const auto bearing1 = Lift(rig.cam1.intrinsics, pairs[i].cam1.corners_px[slot1[id]]);
      if (!bearing0 || !bearing1) continue;
      const TriangulatedPoint point =
          TriangulateOptimalAngular(cam1_from_cam0, *bearing0, *bearing1);
      if (!point.valid) continue;
      const Eigen::Vector3d truth = set.cam0_from_board[i] * object[id];
      const double error_pct = 100.0 * (point.point_in_cam1 - truth).norm() / truth.norm();
      stats.mean_error_pct += error_pct;
      stats.max_error_pct = std::max(stats.max_error_pct, error_pct);
      stats.mean_range_m += truth.norm();
      ++stats.num_points;
    }
  }
  if (stats.num_points > 0) {
    stats.mean_error_pct /= stats.num_points;
    stats.mean_range_m /= stats.num_points;
  }
  return stats;
}

synth::StereoBoardSet RenderSet(int num_pairs, double min_distance_m, double max_distance_m,
                                uint64_t seed, double image_noise = 2.0,
                                const synth::CheckerboardSpec& board = {}) {
  synth::StereoBoardOptions options;
  options.board = board;
  options.num_pairs = num_pairs;
  options.poses.min_distance_m = min_distance_m;
  options.poses.max_distance_m = max_distance_m;
  options.render.noise_sigma = image_noise;
  options.render.blur_sigma_px = 0.5;
  options.render.grayscale = true;
  options.seed = seed;
  return synth::MakeStereoBoardSet(options);
}

// Errors of one method over several seeds.
struct ErrorStats {
  std::vector<double> error_pct, rotation_deg, reported_std_pct, rms_px;
  int failures = 0;

  void Add(const Row& row, const Rigid3d& truth, double reported_std_m) {
    if (!row.ok) {
      ++failures;
      return;
    }
    const double baseline = truth.translation.norm();
    error_pct.push_back(100.0 * (row.cam0_from_cam1.translation.norm() - baseline) / baseline);
    rotation_deg.push_back(RotationDistanceRad(row.cam0_from_cam1.rotation, truth.rotation) *
                           kDegPerRad);
    reported_std_pct.push_back(100.0 * reported_std_m / baseline);
    rms_px.push_back(row.rms_px);
  }
};

double Mean(const std::vector<double>& v) {
  double sum = 0.0;
  for (double x : v) sum += x;
  return v.empty() ? NAN : sum / v.size();
}

double StdDev(const std::vector<double>& v) {
  if (v.size() < 2) return NAN;
  const double mean = Mean(v);
  double sum = 0.0;
  for (double x : v) sum += (x - mean) * (x - mean);
  return std::sqrt(sum / (v.size() - 1.0));
}

double MaxAbs(const std::vector<double>& v) {
  double m = 0.0;
  for (double x : v) m = std::max(m, std::abs(x));
  return v.empty() ? NAN : m;
}

// "n of m runs" meeting both targets (|baseline error| < 0.01 %, rotation < 0.01 deg).
int NumMeetingTargets(const ErrorStats& stats) {
  int n = 0;
  for (size_t k = 0; k < stats.error_pct.size(); ++k) {
    n += std::abs(stats.error_pct[k]) < 0.01 && stats.rotation_deg[k] < 0.01;
  }
  return n;
}

void PrintStatsHeader(const std::string& title) {
  std::printf("\n%s\n", title.c_str());
  std::printf("| %-50s | %5s | %11s | %10s | %11s | %12s | %11s | %11s | %8s |\n", "method", "runs",
              "mean err %", "std err %", "max |err| %", "mean rot deg", "max rot deg", "its std %",
              "meet");
  std::printf("|%s|%s|%s|%s|%s|%s|%s|%s|%s|\n", std::string(52, '-').c_str(),
              std::string(7, '-').c_str(), std::string(13, '-').c_str(),
              std::string(12, '-').c_str(), std::string(13, '-').c_str(),
              std::string(14, '-').c_str(), std::string(13, '-').c_str(),
              std::string(13, '-').c_str(), std::string(10, '-').c_str());
}

// "its std %": the baseline's standard deviation the estimator reports (covariance), to set
// against the spread actually seen over the seeds. "meet": runs meeting both targets.
void PrintStats(const std::string& method, const ErrorStats& stats) {
  const size_t runs = stats.error_pct.size();
  char meet[32];
  std::snprintf(meet, sizeof(meet), "%d/%zu", NumMeetingTargets(stats), runs + stats.failures);
  std::printf("| %-50s | %5zu | %+11.4f | %10.4f | %11.4f | %12.5f | %11.5f | %11.4f | %8s |\n",
              method.c_str(), runs, Mean(stats.error_pct), StdDev(stats.error_pct),
              MaxAbs(stats.error_pct), Mean(stats.rotation_deg), MaxAbs(stats.rotation_deg),
              Mean(stats.reported_std_pct), meet);
}

// The renders' configurations: what "renders with 0.2 px noise" can mean.
struct NoiseConfig {
  std::string label;  // short, for the triangulation table
  std::string name;
  double image_noise;      // grey levels, in the render
  double corner_noise_px;  // Gaussian, per coordinate, added to the detector's corners
};

// The methods compared on every seed, in print order.
const std::vector<std::string>& SyntheticMethods() {
  static const std::vector<std::string> methods = {
      "known cameras: omnirig joint (eq. 20)",
      "known cameras: omnirig eq. (9) + SVD",
      "known cameras: paper, average of per-pair poses",
      "calibrated per camera: omnirig joint, cameras fixed",
      "calibrated: omnirig joint + intrinsics (\"free\")",
      "cv::omnidir::stereoCalibrate"};
  return methods;
}

// Runs every method on one seed's pairs, adding to `stats` (indexed like SyntheticMethods());
// `rigs` receives the known-camera and calibrated rigs for the triangulation test.
void RunSyntheticSeed(const synth::StereoBoardSet& set, const BoardSpec& board,
                      const std::vector<StereoBoardPair>& pairs, std::vector<ErrorStats>* stats,
                      std::vector<std::pair<std::string, StereoRig>>* rigs,
                      const std::string& label) {
  const Rigid3d truth = set.rig.cam0_from_cam1;
  const RelativePoseOptions fixed_cameras;
  RelativePoseOptions joint;
  joint.refine_intrinsics = true;
  RelativePoseReport known;
  const Row known_row = OurRow(SyntheticMethods()[0], set.rig.cam0, set.rig.cam1, board, pairs,
                               fixed_cameras, &known);
  (*stats)[0].Add(known_row, truth, known.baseline_std_m);
  (*stats)[1].Add({"", known.success, known.linear_cam0_from_cam1, NAN, NAN, ""}, truth, NAN);
  (*stats)[2].Add({"", known.success, known.averaged_cam0_from_cam1, NAN, NAN, ""}, truth, NAN);
  double rms0 = 0.0, rms1 = 0.0;
  const CameraModel cam0 =
      CalibrateCamera(pairs, 0, set.rig.cam0.width, set.rig.cam0.height, board, &rms0);
  const CameraModel cam1 =
      CalibrateCamera(pairs, 1, set.rig.cam1.width, set.rig.cam1.height, board, &rms1);
  RelativePoseReport calibrated_fixed, calibrated;
  const Row fixed_row = OurRow("", cam0, cam1, board, pairs, fixed_cameras, &calibrated_fixed);
  (*stats)[3].Add(fixed_row, truth, calibrated_fixed.baseline_std_m);
  const Row joint_row = OurRow("", cam0, cam1, board, pairs, joint, &calibrated);
  (*stats)[4].Add(joint_row, truth, calibrated.baseline_std_m);
  (*stats)[5].Add(
      RunOmnidirStereo(board, pairs, known, cv::Size(set.rig.cam0.width, set.rig.cam0.height),
                       cv::Size(set.rig.cam1.width, set.rig.cam1.height)),
      truth, NAN);
  if (rigs == nullptr) return;
  if (known.success) rigs->push_back({label + ", known cameras", known.rig});
  if (calibrated.success) rigs->push_back({label + ", calibrated + joint", calibrated.rig});
}

void PrintTriangulationHeader() {
  std::printf(
      "\nTriangulation of board corners about 1 m away (target: mean error < 0.5%% of "
      "the range; optimal angular triangulation, corners labelled by the ground truth)\n");
  std::printf("| %-48s | %8s | %10s | %14s | %12s |\n", "rig", "points", "range m", "mean error %",
              "max error %");
  std::printf("|%s|%s|%s|%s|%s|\n", std::string(50, '-').c_str(), std::string(10, '-').c_str(),
              std::string(12, '-').c_str(), std::string(16, '-').c_str(),
              std::string(14, '-').c_str());
}

void PrintTriangulation(const std::string& name, const synth::StereoBoardSet& far,
                        const BoardSpec& board, const StereoRig& rig,
                        const std::vector<StereoBoardPair>& far_pairs) {
  const TriangulationStats stats = TriangulateBoards(far, board, rig, far_pairs);
  std::printf("| %-48s | %8d | %10.3f | %14.4f | %12.4f |\n", name.c_str(), stats.num_points,
              stats.mean_range_m, stats.mean_error_pct, stats.max_error_pct);
}

// One reading of "0.2 px noise" over the seeds: every method's errors, one table.
void RunSyntheticConfig(const NoiseConfig& config, int num_pairs,
                        const std::vector<uint64_t>& seeds, const synth::CheckerboardSpec& spec,
                        std::vector<std::pair<std::string, StereoRig>>* triangulation_rigs) {
  const BoardSpec board = ToBoardSpec(spec);
  std::vector<ErrorStats> stats(SyntheticMethods().size());
  double detection_rms = 0.0;
  const auto start = std::chrono::steady_clock::now();
  const auto cpu_start = std::clock();
  for (size_t k = 0; k < seeds.size(); ++k) {
    const synth::StereoBoardSet set =
        RenderSet(num_pairs, 0.35, 1.2, seeds[k], config.image_noise, spec);
    double max_detection_error_px = 0.0, rms_detection_error_px = 0.0;
    const std::vector<StereoBoardPair> pairs =
        DetectPairs(set, board, config.corner_noise_px, false, &max_detection_error_px, seeds[k],
                    &rms_detection_error_px);
    detection_rms += rms_detection_error_px / seeds.size();
    RunSyntheticSeed(set, board, pairs, &stats,
                     k == 0 ? triangulation_rigs : nullptr, "reading " + config.label);
  }
  char title[640];
  std::snprintf(title, sizeof(title),
                "Synthetic vertical rig (100 mm), reading %s, %s: %d pairs of 1024x768 per seed, "
                "board %d x %d corners of %.0f mm, %zu seeds, detector error %.3f px RMS before "
                "any added noise (%.0f s wall, %.0f s CPU); targets: |error| < 0.01%%, rotation "
                "< 0.01 deg",
                config.label.c_str(), config.name.c_str(), num_pairs, spec.cols, spec.rows,
                spec.square_size_m * 1e3, seeds.size(), detection_rms, Seconds(start),
                static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC);
  PrintStatsHeader(title);
  for (size_t m = 0; m < stats.size(); ++m) PrintStats(SyntheticMethods()[m], stats[m]);
}

// The preset a user would record for a rig calibration (README): 60 pairs of a board of
// 11 x 8 inner corners of 40 mm, in readings B and C, against cv::omnidir on the same renders.
void RunSyntheticPreset(bool quick) {
  synth::CheckerboardSpec spec;
  spec.cols = 11;
  spec.rows = 8;
  const std::vector<uint64_t> seeds =
      quick ? std::vector<uint64_t>{7} : std::vector<uint64_t>{7, 8, 9};
  const std::vector<NoiseConfig> configs = {
      {"B", "renders, image noise 2 grey levels, detector corners + 0.2 px Gaussian noise", 2.0,
       0.2},
      {"C", "renders, image noise 19 grey levels, detector corners as found", 19.0, 0.0}};
  for (const NoiseConfig& config : configs) {
    RunSyntheticConfig(config, quick ? 20 : 60, seeds, spec, nullptr);
  }
}

// The camera chain: 10 board pairs and 12 views of each camera alone per seed (vertical
// rig, 100 mm), each camera calibrated from its 22 images, then the rig with those
// calibrations given: kept as they are (once the default, now "intrinsics_model": "fixed"), and
// the job's default (the calibrations' 12 own views join the pairs, the model chosen by
// cross-validation between "fixed" and "free"); against cv::omnidir::stereoCalibrate on the
// same pairs' corners (it takes pairs only).
void RunCameraChain(bool quick) {
  const std::vector<uint64_t> seeds =
      quick ? std::vector<uint64_t>{21} : std::vector<uint64_t>{21, 22, 23, 24, 25};
  const std::vector<std::string> methods = {
      "given calibrations kept (\"fixed\")",
      "given calibrations + their views, CV (job default)",
      "cv::omnidir::stereoCalibrate (the pairs)"};
  std::vector<ErrorStats> stats(methods.size());
  std::vector<std::string> chosen;
  const auto start = std::chrono::steady_clock::now();
  for (const uint64_t seed : seeds) {
    const synth::StereoBoardSet set = RenderSet(10, 0.35, 1.2, seed);
    const synth::StereoBoardSet mono = RenderSet(12, 0.35, 1.2, seed + 1000);
    const BoardSpec board = ToBoardSpec(set.board);
    const Rigid3d truth = set.rig.cam0_from_cam1;
    double max_error = 0.0;
    const std::vector<StereoBoardPair> pairs = DetectPairs(set, board, 0.0, false, &max_error);
    const std::vector<StereoBoardPair> mono_pairs =
        DetectPairs(mono, board, 0.0, false, &max_error);
    std::vector<StereoBoardPair> with_views = pairs;
    std::array<CameraModel, 2> cameras;
    for (int c = 0; c < 2; ++c) {
      std::vector<CalibrationView> views;
      for (const auto& pair : pairs) views.push_back({pair.name, c == 0 ? pair.cam0 : pair.cam1});
      for (const auto& pair : mono_pairs) {
        const BoardDetection& detection = c == 0 ? pair.cam0 : pair.cam1;
        views.push_back({"mono " + pair.name, detection});
        if (!detection.found) continue;
        StereoBoardPair single;
        single.name = "cam" + std::to_string(c) + " view " + pair.name;
        (c == 0 ? single.cam0 : single.cam1) = detection;
        single.single_camera_view = true;
        with_views.push_back(single);
      }
      cameras[c] = Calibrate(views, set.rig.cam0.width, set.rig.cam0.height, board,
                             CalibrationOptions(), ProgressSink())
                       .camera;
    }
    RelativePoseReport fixed;
    stats[0].Add(OurRow("", cameras[0], cameras[1], board, pairs, RelativePoseOptions(), &fixed),
                 truth, fixed.baseline_std_m);
    std::vector<RigModelCandidate> candidates;
    for (const RigIntrinsicsModel& model : StandardRigIntrinsicsModels(DefaultFixedIntrinsics())) {
      if (model.name == "fixed" || model.name == "free") {
        candidates.push_back({model, cameras[0], cameras[1]});
      }
    }
    const RigModelSelection selection =
        SelectRigIntrinsicsModel(board, with_views, candidates, RelativePoseOptions());
    if (selection.chosen >= 0) {
      const RelativePoseReport& fit = selection.candidates[selection.chosen].fit;
      stats[1].Add({"", fit.success, fit.rig.cam0_from_cam1, fit.rms_px, NAN, ""}, truth,
                   fit.baseline_std_m);
      chosen.push_back(selection.candidates[selection.chosen].name + " (" +
                       std::to_string(fit.num_single_camera_views_used) + " views)");
    } else {
      ++stats[1].failures;
    }
    stats[2].Add(RunOmnidirStereo(board, pairs, fixed,
                                  cv::Size(set.rig.cam0.width, set.rig.cam0.height),
                                  cv::Size(set.rig.cam1.width, set.rig.cam1.height)),
                 truth, NAN);
  }
  char title[400];
  std::snprintf(title, sizeof(title),
                "Camera chain: 10 pairs + 12 views per camera of 1024x768, 100 mm "
                "vertical rig, image noise 2 grey levels, %zu seeds (%.0f s wall); target: "
                "baseline and rotation errors no higher than cv::omnidir::stereoCalibrate",
                seeds.size(), Seconds(start));
  PrintStatsHeader(title);
  for (size_t m = 0; m < methods.size(); ++m) PrintStats(methods[m], stats[m]);
  std::printf("models chosen:");
  for (const std::string& name : chosen) std::printf(" %s;", name.c_str());
  std::printf("\n");
}

// The synthetic target on renders, over several seeds (the estimator's spread at this
// noise is larger than the target, so one seed alone could pass or fail by luck).
void RunSynthetic(bool quick) {
  const int num_pairs = quick ? 8 : 20;
  // Three seeds per reading keep the run to minutes; the floor below gives the statistics of
  // 20 seeds at the 0.2 px level without rendering.
  const std::vector<uint64_t> seeds =
      quick ? std::vector<uint64_t>{7} : std::vector<uint64_t>{7, 8, 9};
  // Image noise of 19 grey levels makes the detector's own corner error 0.16 px RMS, near the
  // literal "renders with 0.2 px noise" (the title prints the measured value). 28 grey levels
  // give 0.23 px, but the detector then needs its slow fallbacks (20 s a pair).
  const std::vector<NoiseConfig> configs = {
      {"A", "renders, image noise 2 grey levels, detector corners as found", 2.0, 0.0},
      {"B", "renders, image noise 2 grey levels, detector corners + 0.2 px Gaussian noise", 2.0,
       0.2},
      {"C", "renders, image noise 19 grey levels, detector corners as found", 19.0, 0.0}};
  std::vector<std::pair<std::string, StereoRig>> triangulation_rigs;
  const synth::StereoBoardSet far = RenderSet(quick ? 4 : 10, 0.9, 1.1, 11);
  triangulation_rigs.push_back({"ground truth rig", far.rig});
  const BoardSpec board = ToBoardSpec(far.board);
  for (const NoiseConfig& config : configs) {
    RunSyntheticConfig(config, num_pairs, seeds, synth::CheckerboardSpec(), &triangulation_rigs);
  }
  double max_detection_error_px = 0.0;
  for (double corner_noise_px : {0.0, 0.2}) {
    const std::vector<StereoBoardPair> far_pairs =
        DetectPairs(far, board, corner_noise_px, true, &max_detection_error_px);
    PrintTriangulationHeader();
    std::printf("(triangulated corners: detector + %.1f px noise; rigs from the first seed)\n",
                corner_noise_px);
    for (const auto& [name, rig] : triangulation_rigs) {
      PrintTriangulation("rig: " + name, far, board, rig, far_pairs);
    }
  }
}

// The estimator's statistical floor without rendering: exact projections of sampled board
// poses plus 0.2 px Gaussian noise, cameras known, for several numbers of pairs. The spread
// over seeds against the number of pairs shows what the 0.01 % target needs.
// The floor for one board and pair count: exact corners + 0.2 px noise, cameras known.
// With `refine_intrinsics` both cameras' intrinsics are refined with the rig (the "free"
// model), started at the truth.
ErrorStats CornerLevelFloor(const synth::CheckerboardSpec& spec, int num_pairs, int num_seeds,
                            double sigma_px = 0.2, bool refine_intrinsics = false) {
  const std::vector<synth::SynthCamera> cameras = {synth::DefaultCamera(),
                                                   synth::DefaultSecondCamera()};
  const Rigid3d truth = synth::DefaultCam0FromCam1();
  const std::vector<Rigid3d> cam_from_cam0 = {Rigid3d(), truth.Inverse()};
  const BoardSpec board = ToBoardSpec(spec);
  ErrorStats stats;
  for (int seed = 0; seed < num_seeds; ++seed) {
    std::mt19937 rng(1000 + seed);
    std::normal_distribution<double> noise(0.0, sigma_px);
    std::vector<StereoBoardPair> pairs(num_pairs);
    for (int i = 0; i < num_pairs; ++i) {
      const Rigid3d cam0_from_board = synth::SampleBoardPose(
          cameras, cam_from_cam0, spec, synth::BoardPoseOptions(), i, num_pairs, 500 + seed);
      BoardDetection* detections[2] = {&pairs[i].cam0, &pairs[i].cam1};
      for (int c = 0; c < 2; ++c) {
        const auto corners =
            synth::ProjectBoardCorners(cameras[c], cam_from_cam0[c] * cam0_from_board, spec);
        for (size_t id = 0; id < corners.size(); ++id) {
          if (!corners[id].allFinite()) continue;
          detections[c]->corners_px.push_back(corners[id] +
                                              Eigen::Vector2d(noise(rng), noise(rng)));
          detections[c]->corner_ids.push_back(static_cast<int>(id));
        }
        detections[c]->found = true;
      }
      pairs[i].name = "pair" + std::to_string(i);
    }
    RelativePoseOptions options;
    options.refine_intrinsics = refine_intrinsics;
    RelativePoseReport report;
    const Row row =
        OurRow("", cameras[0].model, cameras[1].model, board, pairs, options, &report);
    stats.Add(row, truth, report.baseline_std_m);
  }
  return stats;
}

void RunCornerLevelFloor(bool quick) {
  const int num_seeds = quick ? 4 : 20;
  PrintStatsHeader(
      "Estimator floor: exact corners + 0.2 px Gaussian noise, cameras known, "
      "omnirig joint (eq. 20), " +
      std::to_string(num_seeds) + " seeds per row");
  const synth::CheckerboardSpec spec;
  for (int num_pairs : {20, 80, 320}) {
    PrintStats(std::to_string(num_pairs) + " pairs, 8 x 6 corners of 40 mm",
               CornerLevelFloor(spec, num_pairs, num_seeds));
  }
  for (const auto& [cols, rows, square_m] :
       {std::tuple{11, 8, 0.04}, std::tuple{11, 8, 0.03}, std::tuple{14, 10, 0.03}}) {
    synth::CheckerboardSpec larger;
    larger.cols = cols;
    larger.rows = rows;
    larger.square_size_m = square_m;
    for (int num_pairs : {20, 60}) {
      char name[96];
      std::snprintf(name, sizeof(name), "%d pairs, %d x %d corners of %.0f mm", num_pairs, cols,
                    rows, square_m * 1e3);
      try {
        PrintStats(name, CornerLevelFloor(larger, num_pairs, num_seeds));
      } catch (const std::exception& e) {
        std::printf("| %-50s | %s\n", name, e.what());
      }
    }
  }
  // Self-calibration: the intrinsics refined with the rig. The estimator is started at the true
  // cameras, so the spread is the problem's (any unbiased estimate's), not the initialisation's.
  PrintStatsHeader(
      "Estimator floor with self-calibrated cameras: exact corners + Gaussian noise, both "
      "cameras' intrinsics refined with the rig (\"free\"), " +
      std::to_string(num_seeds) + " seeds per row");
  synth::CheckerboardSpec preset;
  preset.cols = 11;
  preset.rows = 8;
  for (const double sigma_px : {0.2, 0.025}) {
    for (const auto& [board, num_pairs] : {std::pair{spec, 20}, std::pair{preset, 60}}) {
      char name[96];
      std::snprintf(name, sizeof(name), "%.3f px, %d pairs, %d x %d corners of 40 mm", sigma_px,
                    num_pairs, board.cols, board.rows);
      PrintStats(name, CornerLevelFloor(board, num_pairs, num_seeds, sigma_px, true));
    }
  }
}

// cv::fisheye::stereoCalibrate (Kannala-Brandt model, the reference's): each camera
// calibrated first, then both jointly with the rig, for `max_iterations` LM iterations.
Row RunFisheyeStereo(const std::string& method, const BoardSpec& board,
                     const std::vector<StereoBoardPair>& pairs, const RelativePoseReport& ours,
                     cv::Size size, const cv::TermCriteria& criteria) {
  Row row;
  row.method = method;
  const CvCorrespondences cv_pairs = BuildCvCorrespondences(board, pairs, ours);
  cv::Matx33d k0, k1, rotation_cv;
  cv::Vec4d d0, d1;
  cv::Vec3d translation_cv;
  const auto start = std::chrono::steady_clock::now();
  try {
    row.rms_px = cv::fisheye::stereoCalibrate(
        cv_pairs.object_points, cv_pairs.image_points0, cv_pairs.image_points1, k0, d0, k1, d1,
        size, rotation_cv, translation_cv,
        cv::fisheye::CALIB_RECOMPUTE_EXTRINSIC | cv::fisheye::CALIB_FIX_SKEW, criteria);
  } catch (const cv::Exception& e) {
    row.note = std::string("threw: ") + e.what();
    return row;
  }
  row.time_s = Seconds(start);
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  cv::cv2eigen(cv::Mat(rotation_cv), rotation);
  cv::cv2eigen(cv::Mat(translation_cv), translation);
  // (R, T) maps its first camera (cam0) into its second: cam1_from_cam0.
  row.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond(rotation), translation).Inverse();
  row.ok = std::isfinite(row.rms_px);
  row.note = std::to_string(cv_pairs.object_points.size()) + " pairs";
  return row;
}

// The numbers of the list after `key` (the first "[ ... ]" following it) in a small YAML file.
std::vector<double> YamlNumbers(const std::string& text, const std::string& key) {
  const size_t at = text.find("\n" + key + ":");
  if (at == std::string::npos) return {};
  const size_t open = text.find('[', at);
  const size_t close = text.find(']', open);
  if (open == std::string::npos || close == std::string::npos) return {};
  std::string list = text.substr(open + 1, close - open - 1);
  std::replace(list.begin(), list.end(), ',', ' ');
  std::istringstream in(list);
  std::vector<double> numbers;
  for (double x; in >> x;) numbers.push_back(x);
  return numbers;
}

// The reference's result: (R, T) of cv::fisheye::stereoCalibrate, cam1_from_cam0, metres.
// Read by hand: the file was written by OpenCV 2/3, whose YAML OpenCV 4's parser refuses.
std::optional<Rigid3d> ReadReference(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in.good()) return std::nullopt;
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::vector<double> r = YamlNumbers(text, "R");
  const std::vector<double> t = YamlNumbers(text, "T");
  if (r.size() != 9 || t.size() != 3) return std::nullopt;
  const Eigen::Matrix3d rotation =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(r.data());
  const Eigen::Vector3d translation(t[0], t[1], t[2]);
  return Rigid3d(Eigen::Quaterniond(rotation), translation).Inverse();
}

// Keeps only the corners seen at most `max_angle_deg` off the camera's axis (a detection left
// with fewer than 12 corners counts as not found).
BoardDetection WithinFieldAngle(const BoardDetection& detection, const CameraModel& camera,
                                double max_angle_deg) {
  BoardDetection kept = detection;
  kept.corners_px.clear();
  kept.corner_ids.clear();
  for (size_t c = 0; c < detection.corners_px.size(); ++c) {
    const auto bearing = Lift(camera.intrinsics, detection.corners_px[c]);
    if (!bearing || std::acos(bearing->normalized().z()) * kDegPerRad > max_angle_deg) continue;
    kept.corners_px.push_back(detection.corners_px[c]);
    kept.corner_ids.push_back(detection.corner_ids[c]);
  }
  if (kept.corners_px.size() < 12) {
    kept.found = false;
    kept.reason = "fewer than 12 corners within the field angle";
  }
  return kept;
}

double MaxFieldAngleDeg(const std::vector<StereoBoardPair>& pairs, const CameraModel& cam0,
                        const CameraModel& cam1) {
  double max_angle = 0.0;
  for (const auto& pair : pairs) {
    for (const auto& [detection, camera] :
         {std::pair{&pair.cam0, &cam0}, std::pair{&pair.cam1, &cam1}}) {
      for (const auto& corner : detection->corners_px) {
        const auto bearing = Lift(camera->intrinsics, corner);
        if (bearing) max_angle = std::max(max_angle, std::acos(bearing->normalized().z()));
      }
    }
  }
  return max_angle * kDegPerRad;
}

std::vector<StereoBoardPair> LoadRealPairs(const std::filesystem::path& dir, const BoardSpec& board,
                                           cv::Size* size) {
  std::vector<StereoBoardPair> pairs;
  for (int i = 1; i <= 29; ++i) {
    const cv::Mat left =
        cv::imread((dir / ("left" + std::to_string(i) + ".jpg")).string(), cv::IMREAD_GRAYSCALE);
    const cv::Mat right =
        cv::imread((dir / ("right" + std::to_string(i) + ".jpg")).string(), cv::IMREAD_GRAYSCALE);
    if (left.empty() || right.empty()) continue;
    *size = left.size();
    pairs.push_back({"pair" + std::to_string(i), DetectBoard(left, board, DetectOptions()),
                     DetectBoard(right, board, DetectOptions())});
  }
  return pairs;
}

// Leave-one-out and two halves of the used pairs: how far the baseline moves with the choice
// of pairs (the data's own uncertainty, whatever the model).
void PrintPairSubsets(const CameraModel& cam0, const CameraModel& cam1, const BoardSpec& board,
                      const std::vector<StereoBoardPair>& pairs, const RelativePoseReport& all,
                      const RelativePoseOptions& options) {
  std::vector<double> baselines;
  const std::vector<Eigen::Vector3d> object = board.ObjectPoints();
  std::printf(
      "per pair: baseline without it (mm) | RMS in the joint fit | RMS of each camera's "
      "own board pose (px), refined cameras | the two own board poses compared through the "
      "rig: board centre offset (mm), rotation (deg)\n");
  const std::vector<BoardSymmetry> symmetries = BoardGridSymmetries(board);
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : object) centre += p / static_cast<double>(object.size());
  for (size_t leave = 0; leave < pairs.size(); ++leave) {
    if (!all.pairs[leave].used) continue;
    std::vector<StereoBoardPair> subset = pairs;
    subset.erase(subset.begin() + static_cast<long>(leave));
    const RelativePoseReport report = EstimateRelativePose(cam0, cam1, board, subset, options);
    if (report.success) baselines.push_back(report.baseline_m * 1e3);
    double mono_rms[2] = {-1.0, -1.0};
    const BoardDetection* detections[2] = {&pairs[leave].cam0, &pairs[leave].cam1};
    const CameraModel* cameras[2] = {&all.rig.cam0, &all.rig.cam1};
    std::optional<Rigid3d> own_pose[2];
    for (int c = 0; c < 2; ++c) {
      const std::vector<int>& permutation =
          symmetries[c == 0 ? 0 : all.pairs[leave].cam1_order].permutation;
      std::vector<Eigen::Vector3d> points;
      for (int id : detections[c]->corner_ids) points.push_back(object[permutation[id]]);
      own_pose[c] = EstimateBoardPose(*cameras[c], points, detections[c]->corners_px, &mono_rms[c]);
    }
    double offset_mm = NAN, rotation_deg = NAN;
    if (own_pose[0] && own_pose[1]) {
      const Rigid3d via_cam1 = all.rig.cam0_from_cam1 * *own_pose[1];
      offset_mm = 1e3 * (*own_pose[0] * centre - via_cam1 * centre).norm();
      rotation_deg = RotationDistanceRad(own_pose[0]->rotation, via_cam1.rotation) * kDegPerRad;
    }
    std::printf("  %s: %.3f | %.3f | %.3f / %.3f | %.2f mm, %.3f deg\n",
                pairs[leave].name.c_str(), report.baseline_m * 1e3, all.pairs[leave].rms_px,
                mono_rms[0], mono_rms[1], offset_mm, rotation_deg);
  }
  double mean = 0.0, var = 0.0;
  for (double b : baselines) mean += b / baselines.size();
  for (double b : baselines) var += (b - mean) * (b - mean) / baselines.size();
  const auto [lo, hi] = std::minmax_element(baselines.begin(), baselines.end());
  std::printf(
      "leave-one-pair-out (joint + intrinsics, %zu runs): baseline %.3f .. %.3f mm, "
      "mean %.3f, std %.3f mm (jackknife std of the estimate %.3f mm)\n",
      baselines.size(), *lo, *hi, mean, std::sqrt(var), std::sqrt(var * (baselines.size() - 1.0)));
  for (int half = 0; half < 2; ++half) {
    std::vector<StereoBoardPair> subset;
    for (size_t i = half; i < pairs.size(); i += 2) subset.push_back(pairs[i]);
    const RelativePoseReport report = EstimateRelativePose(cam0, cam1, board, subset, options);
    std::printf(
        "%s pairs only (joint + intrinsics): baseline %.3f mm +- %.3f, RMS %.3f px, %d "
        "pairs used\n",
        half == 0 ? "odd-numbered" : "even-numbered", report.baseline_m * 1e3,
        report.baseline_std_m * 1e3, report.rms_px, report.num_pairs_used);
  }
}

// Each camera's tangential terms (k3, k4) from its own calibration, against their standard
// deviations: whether a camera alone can tell them from zero.
void PrintTangentialSignificance(const std::vector<StereoBoardPair>& pairs, cv::Size size,
                                 const BoardSpec& board) {
  for (int camera = 0; camera < 2; ++camera) {
    std::vector<CalibrationView> views;
    for (const StereoBoardPair& pair : pairs) {
      views.push_back({pair.name, camera == 0 ? pair.cam0 : pair.cam1});
    }
    const CalibrationReport report = Calibrate(views, size.width, size.height, board,
                                               CalibrationOptions(), ProgressSink());
    const auto& p = report.camera.intrinsics.params;
    const auto& s = report.intrinsics_std;
    std::printf("cam%d alone: k3 = %.2e +- %.1e (%.1f std), k4 = %.2e +- %.1e (%.1f std)\n",
                camera, p[UnifiedIntrinsics::kK3], s[UnifiedIntrinsics::kK3],
                std::abs(p[UnifiedIntrinsics::kK3]) / s[UnifiedIntrinsics::kK3],
                p[UnifiedIntrinsics::kK4], s[UnifiedIntrinsics::kK4],
                std::abs(p[UnifiedIntrinsics::kK4]) / s[UnifiedIntrinsics::kK4]);
  }
}

// The job's default ("intrinsics_model": "auto"): the candidate models scored by
// leave-one-pair-out prediction (engine/rig/relpose_model_select.h), and the one chosen.
RigModelSelection PrintModelSelection(const std::vector<RigModelCandidate>& candidates,
                                      const BoardSpec& board,
                                      const std::vector<StereoBoardPair>& pairs,
                                      double reference_baseline_m,
                                      const RelativePoseOptions& options, const char* what) {
  const auto start = std::chrono::steady_clock::now();
  const auto cpu_start = std::clock();
  const RigModelSelection selection = SelectRigIntrinsicsModel(board, pairs, candidates, options);
  std::printf(
      "\nModel selection by leave-one-pair-out cross-validation (%s; %.1f s wall, %.1f s CPU): "
      "held-out error = cam1's corners predicted from cam0's board pose through the rig and "
      "vice versa\n",
      what, Seconds(start), static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC);
  std::printf("| %-18s | %5s | %12s | %8s | %8s | %10s | %21s | %s\n", "model", "free",
              "baseline mm", "error %", "fit RMS", "CV RMS px", "CV excess MSE +- SE", "");
  std::printf("|%s|%s|%s|%s|%s|%s|%s|---\n", std::string(20, '-').c_str(),
              std::string(7, '-').c_str(), std::string(14, '-').c_str(),
              std::string(10, '-').c_str(), std::string(10, '-').c_str(),
              std::string(12, '-').c_str(), std::string(23, '-').c_str());
  for (size_t k = 0; k < selection.candidates.size(); ++k) {
    const RigModelScore& score = selection.candidates[k];
    const double baseline = score.fit.baseline_m;
    std::printf("| %-18s | %5d | %12.4f | %+8.4f | %8.4f | %10.4f | %9.5f +- %8.5f | %s\n",
                score.name.c_str(), score.num_free_intrinsics, baseline * 1e3,
                100.0 * (baseline - reference_baseline_m) / reference_baseline_m,
                score.fit.rms_px, score.cv_rms_px, score.cv_excess_mse_px2,
                score.cv_excess_se_px2,
                static_cast<int>(k) == selection.chosen ? "<- chosen" : "");
  }
  std::printf("rule: %s\n", selection.rule.c_str());
  return selection;
}

// The synchronisation test of one fit (engine/rig/relpose_sync.h): the noise it found, its
// limit, and every pair's statistic and board disagreement, with the reason of those left out.
void PrintSyncTest(const std::string& name, const RelativePoseReport& report) {
  const SyncTestReport& test = report.sync_test;
  std::printf(
      "\nSynchronisation test, %s: corner noise %.4f / %.4f px per coordinate, median "
      "statistic %.2f (chi^2_6: 5.35), dispersion %.2f, limit %.2f (final round); %d pairs left "
      "out\n",
      name.c_str(), test.corner_noise_px[0], test.corner_noise_px[1], test.median_statistic,
      test.dispersion, test.limit, report.sync_rounds);
  std::printf("per pair: statistic | board offset mm, rotation deg | joint RMS px (or why unused)\n");
  for (const RelativePosePairReport& pair : report.pairs) {
    std::printf("  %s: %.1f | %.2f mm, %.3f deg | ", pair.name.c_str(), pair.sync_statistic,
                pair.board_offset_m * 1e3, pair.board_rotation_deg);
    if (pair.used) {
      std::printf("%.3f\n", pair.rms_px);
    } else {
      std::printf("unused: %s\n", pair.reason.c_str());
    }
  }
}

void RunRealFisheye(const std::filesystem::path& data_dir) {
  const std::filesystem::path dir = data_dir / "fisheye-stereo-pairs";
  if (!std::filesystem::is_directory(dir)) {
    std::printf("\nReal fisheye pairs: %s not found, skipped\n", dir.string().c_str());
    return;
  }
  BoardSpec board;
  board.cols = 9;
  board.rows = 6;
  board.square_size_m = 0.02423;
  cv::Size size;
  const auto start = std::chrono::steady_clock::now();
  const std::vector<StereoBoardPair> pairs = LoadRealPairs(dir, board, &size);
  int found0 = 0, found1 = 0;
  for (const auto& pair : pairs) found0 += pair.cam0.found, found1 += pair.cam1.found;
  std::printf(
      "\nReal fisheye pairs: %zu pairs, board found in %d left / %d right images "
      "(%.1f s)\n",
      pairs.size(), found0, found1, Seconds(start));
  const std::optional<Rigid3d> reference = ReadReference(dir / "reference_cv_fisheye_stereo.yml");
  const double reference_baseline_m = reference ? reference->translation.norm() : 0.10996;

  // The set holds the pairs only: each camera is calibrated from its 29 images of them.
  double rms0 = 0.0, rms1 = 0.0, rms0_k5 = 0.0, rms1_k5 = 0.0, rms0_nt = 0.0, rms1_nt = 0.0;
  const CameraModel cam0 = CalibrateCamera(pairs, 0, size.width, size.height, board, &rms0);
  const CameraModel cam1 = CalibrateCamera(pairs, 1, size.width, size.height, board, &rms1);
  CalibrationOptions free_k5;
  free_k5.SetFixed("k5", false);
  const CameraModel cam0_k5 =
      CalibrateCamera(pairs, 0, size.width, size.height, board, &rms0_k5, free_k5);
  const CameraModel cam1_k5 =
      CalibrateCamera(pairs, 1, size.width, size.height, board, &rms1_k5, free_k5);
  CalibrationOptions no_tangential;
  no_tangential.SetFixed("tangential", true);
  const CameraModel cam0_nt =
      CalibrateCamera(pairs, 0, size.width, size.height, board, &rms0_nt, no_tangential);
  const CameraModel cam1_nt =
      CalibrateCamera(pairs, 1, size.width, size.height, board, &rms1_nt, no_tangential);
  std::printf(
      "per-camera calibration RMS (px), left / right: %.4f / %.4f (k5 and skew fixed, "
      "the default); %.4f / %.4f (k5 free); %.4f / %.4f (tangential fixed); xi %.3f / "
      "%.3f; largest corner field angle %.1f deg off the axis\n",
      rms0, rms1, rms0_k5, rms1_k5, rms0_nt, rms1_nt, cam0.intrinsics.params[0],
      cam1.intrinsics.params[0], MaxFieldAngleDeg(pairs, cam0, cam1));

  PrintTangentialSignificance(pairs, size, board);
  // Each camera from its calibration with or without the tangential terms, as the model says.
  const auto candidate_of = [&](const RigIntrinsicsModel& model) {
    return RigModelCandidate{model,
                             model.CalibrationFixed(0)[UnifiedIntrinsics::kK3] ? cam0_nt : cam0,
                             model.CalibrationFixed(1)[UnifiedIntrinsics::kK3] ? cam1_nt : cam1};
  };
  std::vector<RigModelCandidate> candidates;
  for (const RigIntrinsicsModel& model : AutoRigIntrinsicsModels(DefaultFixedIntrinsics())) {
    candidates.push_back(candidate_of(model));
  }
  const RigModelSelection selection =
      PrintModelSelection(candidates, board, pairs, reference_baseline_m, RelativePoseOptions(),
                          "the job's default, \"intrinsics_model\": \"auto\"");
  if (selection.chosen >= 0) {
    const RigModelScore& chosen = selection.candidates[selection.chosen];
    PrintSyncTest("the job's default (" + chosen.name + ")", chosen.fit);
  }
  // The job's threads run the candidates' fits and the folds side by side (one solver thread
  // each): the same answers whatever the thread count, less wall time on a quiet machine.
  RelativePoseOptions two_threads;
  two_threads.num_threads = 2;
  const RigModelSelection parallel =
      PrintModelSelection(candidates, board, pairs, reference_baseline_m, two_threads,
                          "the same on 2 threads");
  bool identical = parallel.chosen == selection.chosen;
  for (size_t k = 0; k < parallel.candidates.size() && identical; ++k) {
    const RigModelScore& a = parallel.candidates[k];
    const RigModelScore& b = selection.candidates[k];
    identical = a.fit.baseline_m == b.fit.baseline_m && a.fit.rms_px == b.fit.rms_px &&
                a.cv_rms_px == b.cv_rms_px && a.fit.num_pairs_used == b.fit.num_pairs_used;
  }
  std::printf("2 threads against 1: %s\n",
              identical ? "identical (chosen model, baselines, RMS, CV errors, pairs used)"
                        : "DIFFERENT");
  RelativePoseOptions no_sync_test;
  no_sync_test.sync_test.false_alarm_rate = 0.0;
  PrintModelSelection(candidates, board, pairs, reference_baseline_m, no_sync_test,
                      "the same with the synchronisation test off");

  RelativePoseOptions fixed_cameras;
  RelativePoseOptions joint;
  joint.refine_intrinsics = true;
  RelativePoseReport fixed_report, joint_report;
  std::vector<Row> rows;
  rows.push_back(OurRow("omnirig joint (eq. 20), cameras fixed", cam0, cam1, board, pairs,
                        fixed_cameras, &fixed_report));
  rows.push_back({"omnirig eq. (9) + SVD, no refinement", fixed_report.success,
                  fixed_report.linear_cam0_from_cam1, NAN, NAN, ""});
  rows.push_back({"paper: average of per-pair poses", fixed_report.success,
                  fixed_report.averaged_cam0_from_cam1, NAN, NAN, ""});
  rows.push_back(OurRow("omnirig joint + intrinsics (all but skew, k5)", cam0, cam1, board, pairs,
                        joint, &joint_report));
  RelativePoseOptions joint_k5 = joint;
  joint_k5.fixed_intrinsics[UnifiedIntrinsics::kK5] = false;
  rows.push_back(
      OurRow("  ... k5 free (calibration and joint)", cam0_k5, cam1_k5, board, pairs, joint_k5));
  RelativePoseOptions joint_skew = joint;
  joint_skew.fixed_intrinsics[UnifiedIntrinsics::kAlpha] = false;
  rows.push_back(OurRow("  ... skew free in the joint fit", cam0, cam1, board, pairs, joint_skew));
  RelativePoseOptions joint_nt = joint;
  joint_nt.fixed_intrinsics[UnifiedIntrinsics::kK3] = true;
  joint_nt.fixed_intrinsics[UnifiedIntrinsics::kK4] = true;
  rows.push_back(OurRow("  ... tangential fixed at 0", cam0_nt, cam1_nt, board, pairs, joint_nt));
  RelativePoseOptions joint_l2 = joint;
  joint_l2.huber_loss_px = 0.0;
  rows.push_back(
      OurRow("  ... plain least squares (no Huber)", cam0, cam1, board, pairs, joint_l2));
  RelativePoseOptions joint_all = joint;
  joint_all.sync_test.false_alarm_rate = 0.0;
  rows.push_back(OurRow("  ... no synchronisation test", cam0, cam1, board, pairs, joint_all));
  // The largest field angle of these corners is about 70 deg (printed above): the board never
  // reaches the >180 deg lens's rim, so edge bias is tested by dropping the outer corners.
  for (double max_angle : {60.0, 50.0}) {
    std::vector<StereoBoardPair> central = pairs;
    for (auto& pair : central) {
      pair.cam0 = WithinFieldAngle(pair.cam0, cam0, max_angle);
      pair.cam1 = WithinFieldAngle(pair.cam1, cam1, max_angle);
    }
    rows.push_back(OurRow("  ... corners within " + std::to_string(static_cast<int>(max_angle)) +
                              " deg of the axis only",
                          cam0, cam1, board, central, joint));
  }
  if (selection.chosen >= 0) {
    const RigModelScore& chosen = selection.candidates[selection.chosen];
    Row row{"omnirig, model chosen by CV (job default): " + chosen.name, chosen.fit.success,
            chosen.fit.rig.cam0_from_cam1, chosen.fit.rms_px, NAN, ""};
    char note[96];
    std::snprintf(note, sizeof(note), "%d/%zu pairs, baseline std %.4f mm",
                  chosen.fit.num_pairs_used, pairs.size(), chosen.fit.baseline_std_m * 1e3);
    row.note = note;
    rows.push_back(row);
  }
  rows.push_back(RunOmnidirStereo(board, pairs, joint_report, size, size));
  rows.push_back(RunFisheyeStereo("cv::fisheye::stereoCalibrate, as the reference", board, pairs,
                                  joint_report, size, cv::TermCriteria(3, 12, 0)));
  rows.push_back(RunFisheyeStereo(
      "cv::fisheye::stereoCalibrate, converged", board, pairs, joint_report, size,
      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 300, 1e-12)));
  if (reference) rows.push_back({"reference (its yml)", true, *reference, NAN, NAN, ""});
  PrintRows("Real fisheye pairs, reference baseline " +
                std::to_string(reference_baseline_m * 1e3).substr(0, 6) +
                " mm (targets: within 0.2%, RMS < 0.5 px); rot err = angle to the reference's "
                "rotation",
            rows, reference ? &*reference : nullptr, reference_baseline_m);
  for (const auto& [name, report] : {std::pair{"cameras fixed", &fixed_report},
                                     std::pair{"joint + intrinsics", &joint_report}}) {
    std::printf("per-pair RMS (px, %s; cam1 corner order in brackets):", name);
    for (const auto& pair : report->pairs) {
      if (pair.used) {
        std::printf(" %s=%.2f[%d]", pair.name.c_str(), pair.rms_px, pair.cam1_order);
      } else {
        std::printf(" %s=unused", pair.name.c_str());
      }
    }
    std::printf("\n");
  }
  PrintPairSubsets(cam0, cam1, board, pairs, joint_report, joint);
}


// The probability of at most k successes in n trials of probability p.
double BinomialCdf(int k, int n, double p) {
  if (k < 0) return 0.0;
  if (k >= n) return 1.0;
  double sum = 0.0;
  for (int i = 0; i <= k; ++i) {
    sum += std::exp(std::lgamma(n + 1.0) - std::lgamma(i + 1.0) - std::lgamma(n - i + 1.0) +
                    i * std::log(p) + (n - i) * std::log1p(-p));
  }
  return std::min(1.0, sum);
}

// Clopper-Pearson 95 % interval of a rate from k of n.
std::pair<double, double> RateInterval(int k, int n) {
  const auto solve = [&](bool lower) {
    if ((lower && k == 0) || (!lower && k == n)) return lower ? 0.0 : 1.0;
    double low = 0.0, high = 1.0;
    for (int i = 0; i < 60; ++i) {
      const double mid = 0.5 * (low + high);
      // lower: P(X >= k | mid) = 0.025; upper: P(X <= k | mid) = 0.025.
      const bool too_high = lower ? 1.0 - BinomialCdf(k - 1, n, mid) > 0.025
                                  : BinomialCdf(k, n, mid) < 0.025;
      (too_high ? high : low) = mid;
    }
    return 0.5 * (low + high);
  };
  return {solve(true), solve(false)};
}

std::string RateText(int k, int n) {
  const auto [low, high] = RateInterval(k, n);
  char text[120];
  std::snprintf(text, sizeof(text), "%d/%d = %.1f %% (95 %% CI %.1f-%.1f %%)", k, n,
                100.0 * k / std::max(1, n), 100.0 * low, 100.0 * high);
  return text;
}

// The rendered rigs of RunSyncFalseAlarms, kept in a folder (--cache DIR) so that a rerun
// measures the test alone: per seed, both cameras' calibrations, the synchronised pairs and
// the same pairs with three boards moved.
struct SyncRenderedRig {
  CameraModel cam0, cam1;
  std::vector<StereoBoardPair> pairs, moved_pairs;
};

void WriteDetections(std::ostream& out, const std::vector<StereoBoardPair>& pairs) {
  out << pairs.size() << "\n";
  for (const StereoBoardPair& pair : pairs) {
    for (const BoardDetection* detection : {&pair.cam0, &pair.cam1}) {
      out << detection->found << " " << detection->corners_px.size();
      for (size_t c = 0; c < detection->corners_px.size(); ++c) {
        out << " " << detection->corner_ids[c] << " " << detection->corners_px[c].x() << " "
            << detection->corners_px[c].y();
      }
      out << "\n";
    }
  }
}

std::vector<StereoBoardPair> ReadDetections(std::istream& in) {
  size_t num_pairs = 0;
  in >> num_pairs;
  std::vector<StereoBoardPair> pairs(num_pairs);
  for (size_t i = 0; i < num_pairs; ++i) {
    pairs[i].name = "pair_" + std::to_string(i);
    for (BoardDetection* detection : {&pairs[i].cam0, &pairs[i].cam1}) {
      size_t n = 0;
      in >> detection->found >> n;
      detection->corners_px.resize(n);
      detection->corner_ids.resize(n);
      for (size_t c = 0; c < n; ++c) {
        in >> detection->corner_ids[c] >> detection->corners_px[c].x() >>
            detection->corners_px[c].y();
      }
      if (!detection->found) detection->reason = "not found";
    }
  }
  return pairs;
}

void WriteCamera(std::ostream& out, const CameraModel& camera) {
  out << camera.width << " " << camera.height;
  for (double p : camera.intrinsics.params) out << " " << p;
  out << "\n";
}

CameraModel ReadCamera(std::istream& in) {
  CameraModel camera;
  in >> camera.width >> camera.height;
  for (double& p : camera.intrinsics.params) in >> p;
  return camera;
}

// Tallies of the synchronisation test over rendered rigs, per intrinsics setting.
struct SyncTally {
  int rigs = 0, rigs_losing = 0;
  int pairs = 0, pairs_over_5 = 0, pairs_over_1 = 0, pairs_over_01 = 0;
  std::array<int, 3> moved_found{}, moved_tried{};
  int moved_rigs = 0, others_flagged = 0, others = 0;
  double max_ratio = 0.0;
};

// How many pairs the test left out as unsynchronised.
int NumLeftOutAsUnsynchronised(const RelativePoseReport& report) {
  int count = 0;
  for (const RelativePosePairReport& pair : report.pairs) {
    count += pair.reason.find("exposures not simultaneous?") != std::string::npos ? 1 : 0;
  }
  return count;
}


// Pairs 3, 9 and 15 of the moved copy: boards moved by 1, 2 and 3 mm.
SyncRenderedRig RenderSyncRig(uint64_t seed, const std::string& cache_dir) {
  const std::string file = "sync_" + std::to_string(seed) + ".txt";
  const std::filesystem::path path =
      cache_dir.empty() ? std::filesystem::path() : std::filesystem::path(cache_dir) / file;
  SyncRenderedRig rig;
  if (!path.empty() && std::filesystem::exists(path)) {
    std::ifstream in(path);
    rig.cam0 = ReadCamera(in);
    rig.cam1 = ReadCamera(in);
    rig.pairs = ReadDetections(in);
    rig.moved_pairs = ReadDetections(in);
    return rig;
  }
  const synth::StereoBoardSet set =
      synth::MakeStereoBoardSet(synth::QuickStereoBoardOptions(20, seed));
  const BoardSpec board = ToBoardSpec(set.board);
  double max_error = 0.0, rms0 = 0.0, rms1 = 0.0;
  rig.pairs = DetectPairs(set, board, 0.0, false, &max_error);
  rig.cam0 = CalibrateCamera(rig.pairs, 0, set.rig.cam0.width, set.rig.cam0.height, board, &rms0);
  rig.cam1 = CalibrateCamera(rig.pairs, 1, set.rig.cam1.width, set.rig.cam1.height, board, &rms1);
  std::mt19937 rng(static_cast<uint32_t>(seed));
  std::normal_distribution<double> normal(0.0, 1.0);
  rig.moved_pairs = rig.pairs;
  const size_t moved[3] = {3, 9, 15};
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d direction =
        Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
    if (!rig.moved_pairs[moved[k]].cam1.found) continue;
    MoveBoardBeforeCam1(set, moved[k], 0.001 * (k + 1) * direction,
                        &rig.moved_pairs[moved[k]].cam1);
  }
  if (!path.empty()) {
    std::ofstream out(path);
    out.precision(17);
    WriteCamera(out, rig.cam0);
    WriteCamera(out, rig.cam1);
    WriteDetections(out, rig.pairs);
    WriteDetections(out, rig.moved_pairs);
  }
  return rig;
}

// The first round of the synchronisation test on a rig's pairs, nothing left out: each pair's
// statistic and p-value (the limit set out of reach; the statistics do not depend on it).
SyncTestReport FirstRoundSyncTest(const SyncRenderedRig& rig, const BoardSpec& board,
                                  RelativePoseOptions options) {
  options.sync_test.false_alarm_rate = 1e-12;
  const RelativePoseReport report =
      EstimateRelativePose(rig.cam0, rig.cam1, board, rig.pairs, options);
  return report.success ? report.sync_test : SyncTestReport();
}

// One rig with one intrinsics setting into `tally`: its first round (per-pair p-values), the
// test as the job runs it (did it lose a pair?), and the copy with three boards moved.
void TallySyncRig(const SyncRenderedRig& rig, const BoardSpec& board,
                  const RelativePoseOptions& options, const std::string& label, std::FILE* csv,
                  SyncTally* tally) {
  const SyncTestReport first = FirstRoundSyncTest(rig, board, options);
  const RelativePoseReport report =
      EstimateRelativePose(rig.cam0, rig.cam1, board, rig.pairs, options);
  if (!report.success || !first.run) return;
  ++tally->rigs;
  const int lost = NumLeftOutAsUnsynchronised(report);
  tally->rigs_losing += lost > 0 ? 1 : 0;
  double largest = 0.0;
  for (size_t k = 0; k < first.pairs.size(); ++k) {
    const PairSyncStatistic& pair = first.pairs[k];
    if (!pair.valid) continue;
    const double p = SyncStatisticSurvival(pair.statistic);
    ++tally->pairs;
    tally->pairs_over_5 += p < 0.05 ? 1 : 0;
    tally->pairs_over_1 += p < 0.01 ? 1 : 0;
    tally->pairs_over_01 += p < 0.001 ? 1 : 0;
    largest = std::max(largest, pair.statistic);
    if (csv == nullptr) continue;
    std::fprintf(csv, "%s,%zu,%.4f,%.4f,%.4f,%.4f,%.5f,%.5f,%.4e,%.4e,%d,%d,%.4f,%d\n",
                 label.c_str(), k, pair.statistic, pair.raw_statistic, first.limit,
                 first.dispersion, first.corner_noise_px[0], first.corner_noise_px[1],
                 pair.own_variance_px2[0], pair.own_variance_px2[1], pair.own_dof[0],
                 pair.own_dof[1], pair.reference_variance, lost);
  }
  tally->max_ratio = std::max(tally->max_ratio, largest / report.sync_test.limit);
  std::printf("%s: %zu pairs tested, %d left out (largest first-round statistic %.1f, limit %.1f, "
              "dispersion %.2f, noise %.4f / %.4f px)\n",
              label.c_str(), first.pairs.size(), lost, largest, report.sync_test.limit,
              first.dispersion, first.corner_noise_px[0], first.corner_noise_px[1]);
  const RelativePoseReport moved =
      EstimateRelativePose(rig.cam0, rig.cam1, board, rig.moved_pairs, options);
  if (!moved.success) return;
  ++tally->moved_rigs;
  for (size_t i = 0; i < rig.moved_pairs.size(); ++i) {
    const int k = i == 3 ? 0 : i == 9 ? 1 : i == 15 ? 2 : -1;
    const bool left_out =
        moved.pairs[i].reason.find("exposures not simultaneous?") != std::string::npos;
    if (k >= 0 && rig.moved_pairs[i].cam0.found && rig.moved_pairs[i].cam1.found) {
      ++tally->moved_tried[k];
      tally->moved_found[k] += left_out ? 1 : 0;
    } else if (k < 0 && moved.pairs[i].sync_statistic >= 0.0) {
      ++tally->others;
      tally->others_flagged += left_out ? 1 : 0;
    }
  }
}

void PrintSyncTallies(const std::array<SyncTally, 2>& tally) {
  std::printf("| intrinsics | rigs losing a pair (target 1 %%) | pairs with p < 5 %% | < 1 %% | "
              "< 0.1 %% | largest statistic / limit |\n|---|---|---|---|---|---|\n");
  for (int refine = 0; refine < 2; ++refine) {
    const SyncTally& t = tally[refine];
    std::printf("| %s | %s | %s | %s | %s | %.2f |\n",
                refine ? "refined with the rig" : "kept (fixed)",
                RateText(t.rigs_losing, t.rigs).c_str(), RateText(t.pairs_over_5, t.pairs).c_str(),
                RateText(t.pairs_over_1, t.pairs).c_str(),
                RateText(t.pairs_over_01, t.pairs).c_str(), t.max_ratio);
  }
  std::printf("\nPower: the same rigs with 3 pairs whose board moved between the exposures\n"
              "| intrinsics | 1 mm found | 2 mm found | 3 mm found | other pairs left out |\n"
              "|---|---|---|---|---|\n");
  for (int refine = 0; refine < 2; ++refine) {
    const SyncTally& t = tally[refine];
    std::printf("| %s | %s | %s | %s | %s |\n", refine ? "refined with the rig" : "kept (fixed)",
                RateText(t.moved_found[0], t.moved_tried[0]).c_str(),
                RateText(t.moved_found[1], t.moved_tried[1]).c_str(),
                RateText(t.moved_found[2], t.moved_tried[2]).c_str(),
                RateText(t.others_flagged, t.others).c_str());
  }
}

// 7. The synchronisation test (engine/rig/relpose_sync.h) on the renderer's synchronised
// pairs: QuickStereoBoardOptions(20, 3000 + seed), each camera calibrated from its own 20
// images, the rig with the cameras kept at those calibrations ("fixed") and with the
// intrinsics refined. The false-alarm rate (rigs losing a pair; the option promises at most
// sync_false_alarm_rate) with its 95 % interval, each tested pair's p-value against the
// nominal levels (first round), and the power: three pairs per rig whose board moved by 1, 2
// and 3 mm (random directions) between the two exposures. --csv writes the first round's
// per-pair statistics.
void RunSyncFalseAlarms(bool quick, int first_seed, int num_seeds, const std::string& csv_path,
                        const std::string& cache_dir) {
  if (num_seeds <= 0) num_seeds = quick ? 3 : 40;
  const auto start = std::chrono::steady_clock::now();
  const auto cpu_start = std::clock();
  std::array<SyncTally, 2> tally;
  std::FILE* csv = csv_path.empty() ? nullptr : std::fopen(csv_path.c_str(), "w");
  if (csv != nullptr) {
    std::fprintf(csv, "seed,refine,pair,statistic,raw,limit,dispersion,noise0,noise1,var0,var1,"
                      "dof0,dof1,reference_variance,lost\n");
  }
  for (int s = first_seed; s < first_seed + num_seeds; ++s) {
    const uint64_t seed = 3000 + s;
    const SyncRenderedRig rig = RenderSyncRig(seed, cache_dir);
    const BoardSpec board = ToBoardSpec(synth::QuickStereoBoardOptions(20, seed).board);
    for (int refine = 0; refine < 2; ++refine) {
      RelativePoseOptions options;
      options.refine_intrinsics = refine == 1;
      TallySyncRig(rig, board, options, std::to_string(seed) + "," + std::to_string(refine), csv,
                   &tally[refine]);
    }
  }
  if (csv != nullptr) std::fclose(csv);
  std::printf(
      "\nSynchronisation test on synchronised renders (QuickStereoBoardOptions(20, 3000 + seed), "
      "seeds %d-%d, each camera calibrated from its 20 images; %.0f s CPU, %.0f s wall); "
      "sync_false_alarm_rate 0.01\n",
      3000 + first_seed, 3000 + first_seed + num_seeds - 1,
      static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC, Seconds(start));
  PrintSyncTallies(tally);
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // tables appear as they are measured
  bool quick = false;
  std::string only;  // "synthetic" or "real": one part alone
  int num_seeds = 0;     // --only sync: rendered rigs (0: the part's default)
  int first_seed = 0;    // --only sync: the first (seed 3000 + it)
  std::string csv_path;  // --only sync: per-pair statistics to this file
  std::string cache_dir;  // --only sync: rendered rigs kept here for reruns
  std::filesystem::path data_dir =
      std::filesystem::path(OMNIRIG_SOURCE_DIR) / ".." / "shared" / "data" / "real";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    if (std::strcmp(argv[i], "--data") == 0 && i + 1 < argc) data_dir = argv[++i];
    if (std::strcmp(argv[i], "--only") == 0 && i + 1 < argc) only = argv[++i];
    if (std::strcmp(argv[i], "--seeds") == 0 && i + 1 < argc) num_seeds = std::atoi(argv[++i]);
    if (std::strcmp(argv[i], "--first-seed") == 0 && i + 1 < argc) {
      first_seed = std::atoi(argv[++i]);
    }
    if (std::strcmp(argv[i], "--csv") == 0 && i + 1 < argc) csv_path = argv[++i];
    if (std::strcmp(argv[i], "--cache") == 0 && i + 1 < argc) cache_dir = argv[++i];
  }
  try {
    if (only.empty() || only == "synthetic") omnirig::RunSynthetic(quick);
    if (only.empty() || only == "synthetic" || only == "floor") {
      omnirig::RunCornerLevelFloor(quick);
    }
    if (only == "preset") omnirig::RunSyntheticPreset(quick);  // long: on request only
    if (only.empty() || only == "chain") omnirig::RunCameraChain(quick);
    if (only.empty() || only == "real") omnirig::RunRealFisheye(data_dir);
    if (only == "sync") {
      omnirig::RunSyncFalseAlarms(quick, first_seed, num_seeds, csv_path, cache_dir);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_relpose: %s\n", e.what());
    return 1;
  }
  return 0;
}
