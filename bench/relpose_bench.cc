// bench_relpose: accuracy of the stereo rig's relative pose (issue 4's targets), next to the
// paper's method and cv::omnidir::stereoCalibrate on the same corners, in the same run.
//
//   1. Synthetic vertical rig (100 mm), 20 pairs rendered at 1024x768 (image noise of 2 grey
//      levels, blur 0.5 px), corners from omnirig's own detector, once as detected and once
//      with 0.2 px Gaussian noise added to every corner. Cameras known (the rig alone is
//      measured) and calibrated from the same images (the whole chain). Baseline error (target
//      < 0.01%) and rotation error (< 0.01 deg). Rows: the joint refinement (eq. 20), eq. (9)
//      alone, the paper's average of per-pair poses, the joint refinement with both cameras'
//      intrinsics, cv::omnidir::stereoCalibrate (its own initialisation, COUNT 300 / EPS 1e-8).
//   2. Triangulation of the board corners of 10 new pairs about 1 m away with each estimated
//      rig (target: mean error < 0.5% of the range).
//   3. Real fisheye pairs (../shared/data/real/fisheye-stereo-pairs, left = cam0, right =
//      cam1, 9 x 6 corners, 24.23 mm): baseline against the reference 109.96 mm (target within
//      0.2%) and RMS (< 0.5 px).
// RMS everywhere is sqrt(mean |e|^2) of the Euclidean corner error, as OpenCV reports it.
//
// Usage: bench_relpose [--quick] [--data DIR]   (DIR: the folder holding the real data sets)

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/calib3d.hpp>
#include <opencv2/ccalib/omnidir.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>

#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/stereo/relative_pose.h"
#include "engine/stereo/relpose_corner_order.h"
#include "engine/stereo/triangulation.h"
#include "engine/synth/presets.h"

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
  std::printf("| %-44s | %12s | %10s | %10s | %8s | %7s | %s\n", "method", "baseline mm",
              "error %", "rot err deg", "RMS px", "time s", "note");
  std::printf("|%s|%s|%s|%s|%s|%s|---\n", std::string(46, '-').c_str(),
              std::string(14, '-').c_str(), std::string(12, '-').c_str(),
              std::string(12, '-').c_str(), std::string(10, '-').c_str(),
              std::string(9, '-').c_str());
  for (const Row& row : rows) {
    if (!row.ok) {
      std::printf("| %-44s | %12s | %10s | %10s | %8s | %7s | %s\n", row.method.c_str(), "-",
                  "-", "-", "-", "-", row.note.c_str());
      continue;
    }
    const double baseline = row.cam0_from_cam1.translation.norm();
    const double error_pct = 100.0 * (baseline - reference_baseline_m) / reference_baseline_m;
    char rotation[32] = "-";
    if (truth != nullptr) {
      std::snprintf(rotation, sizeof(rotation), "%.5f",
                    RotationDistanceRad(row.cam0_from_cam1.rotation, truth->rotation) *
                        kDegPerRad);
    }
    char rms[32] = "-";
    if (std::isfinite(row.rms_px)) std::snprintf(rms, sizeof(rms), "%.4f", row.rms_px);
    char time[32] = "-";
    if (std::isfinite(row.time_s)) std::snprintf(time, sizeof(time), "%.3f", row.time_s);
    std::printf("| %-44s | %12.4f | %+10.4f | %10s | %8s | %7s | %s\n", row.method.c_str(),
                baseline * 1e3, error_pct, rotation, rms, time, row.note.c_str());
  }
}

BoardSpec ToBoardSpec(const synth::CheckerboardSpec& spec) {
  BoardSpec board;
  board.cols = spec.cols;
  board.rows = spec.rows;
  board.square_size_m = spec.square_size_m;
  return board;
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
                                         double* max_detection_error_px) {
  std::mt19937 rng(42);
  std::vector<StereoBoardPair> pairs;
  *max_detection_error_px = 0.0;
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
        *max_detection_error_px = std::max(
            *max_detection_error_px,
            (labelled.corners_px[k] - set.corners_px[c][i][labelled.corner_ids[k]]).norm());
      }
      if (label_by_truth) *detections[c] = labelled;
      AddCornerNoise(corner_noise_px, &rng, detections[c]);
    }
    pairs.push_back(pair);
  }
  return pairs;
}

// cv::omnidir::stereoCalibrate on the pairs that our estimate used, cam1's corners in the
// order our estimate settled on (so that both methods see identical correspondences).
Row RunOmnidirStereo(const BoardSpec& board, const std::vector<StereoBoardPair>& pairs,
                     const RelativePoseReport& ours, cv::Size size0, cv::Size size1) {
  Row row;
  row.method = "cv::omnidir::stereoCalibrate";
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
      img0.at<cv::Vec2d>(0, c) = cv::Vec2d(pairs[i].cam0.corners_px[c].x(),
                                           pairs[i].cam0.corners_px[c].y());
    }
    for (int c = 0; c < n; ++c) {
      const int id = permutation[pairs[i].cam1.corner_ids[c]];
      // Position of corner `id` in cam0's list (ids of a full detection are a permutation).
      const int slot = static_cast<int>(
          std::find(pairs[i].cam0.corner_ids.begin(), pairs[i].cam0.corner_ids.end(), id) -
          pairs[i].cam0.corner_ids.begin());
      img1.at<cv::Vec2d>(0, slot) = cv::Vec2d(pairs[i].cam1.corners_px[c].x(),
                                              pairs[i].cam1.corners_px[c].y());
    }
    object_points.push_back(obj);
    image_points0.push_back(img0);
    image_points1.push_back(img1);
  }
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

std::vector<Row> OurRows(const CameraModel& cam0, const CameraModel& cam1, const BoardSpec& board,
                         const std::vector<StereoBoardPair>& pairs, const std::string& prefix,
                         RelativePoseReport* fixed_report) {
  std::vector<Row> rows;
  for (bool refine : {false, true}) {
    RelativePoseOptions options;
    options.refine_intrinsics = refine;
    const auto start = std::chrono::steady_clock::now();
    const RelativePoseReport report = EstimateRelativePose(cam0, cam1, board, pairs, options);
    const double time_s = Seconds(start);
    if (!refine && fixed_report != nullptr) *fixed_report = report;
    Row row;
    row.method = prefix + (refine ? "omnirig joint + intrinsics" : "omnirig joint (eq. 20)");
    row.ok = report.success;
    row.cam0_from_cam1 = report.rig.cam0_from_cam1;
    row.rms_px = report.rms_px;
    row.time_s = time_s;
    char note[160];
    std::snprintf(note, sizeof(note), "%d/%zu pairs, baseline std %.4f mm, rot std %.5f deg",
                  report.num_pairs_used, pairs.size(), report.baseline_std_m * 1e3,
                  report.rotation_std_deg);
    row.note = report.success ? note : report.message;
    rows.push_back(row);
    if (refine) continue;
    Row linear{prefix + "omnirig eq. (9) + SVD, no refinement", report.success,
               report.linear_cam0_from_cam1, NAN, NAN, ""};
    Row average{prefix + "paper: average of per-pair poses", report.success,
                report.averaged_cam0_from_cam1, NAN, NAN, ""};
    rows.push_back(linear);
    rows.push_back(average);
  }
  return rows;
}

CameraModel CalibrateCamera(const std::vector<StereoBoardPair>& pairs, int camera, int width,
                            int height, const BoardSpec& board, double* rms_px) {
  std::vector<CalibrationView> views;
  for (const StereoBoardPair& pair : pairs) {
    views.push_back({pair.name, camera == 0 ? pair.cam0 : pair.cam1});
  }
  const CalibrationReport report =
      Calibrate(views, width, height, board, CalibrationOptions(), ProgressSink());
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
      const TriangulatedPoint point = TriangulateOptimalAngular(cam1_from_cam0, *bearing0,
                                                                *bearing1);
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
                                uint64_t seed) {
  synth::StereoBoardOptions options;
  options.num_pairs = num_pairs;
  options.poses.min_distance_m = min_distance_m;
  options.poses.max_distance_m = max_distance_m;
  options.render.noise_sigma = 2.0;
  options.render.blur_sigma_px = 0.5;
  options.render.grayscale = true;
  options.seed = seed;
  return synth::MakeStereoBoardSet(options);
}

void PrintTriangulationHeader() {
  std::printf("\nTriangulation of board corners about 1 m away (target: mean error < 0.5%% of "
              "the range; optimal angular triangulation, corners labelled by the ground truth)\n");
  std::printf("| %-48s | %8s | %10s | %14s | %12s |\n", "rig", "points", "range m",
              "mean error %", "max error %");
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

void RunSynthetic(bool quick) {
  auto start = std::chrono::steady_clock::now();
  const synth::StereoBoardSet set = RenderSet(quick ? 8 : 20, 0.35, 1.2, 7);
  const synth::StereoBoardSet far = RenderSet(quick ? 4 : 10, 0.9, 1.1, 11);
  const BoardSpec board = ToBoardSpec(set.board);
  std::printf("rendered %zu + %zu pairs of %dx%d (noise 2 grey levels, blur 0.5 px) in %.1f s; "
              "board %s\n",
              set.names.size(), far.names.size(), set.rig.cam0.width, set.rig.cam0.height,
              Seconds(start), board.Describe().c_str());
  const Rigid3d truth = set.rig.cam0_from_cam1;
  std::vector<std::pair<std::string, StereoRig>> triangulation_rigs = {{"ground truth rig",
                                                                        set.rig}};
  for (double corner_noise_px : {0.0, 0.2}) {
    char label[64];
    std::snprintf(label, sizeof(label), "corners + %.1f px noise", corner_noise_px);
    double max_detection_error_px = 0.0;
    const std::vector<StereoBoardPair> pairs =
        DetectPairs(set, board, corner_noise_px, false, &max_detection_error_px);
    RelativePoseReport known;
    std::vector<Row> rows =
        OurRows(set.rig.cam0, set.rig.cam1, board, pairs, "known cameras: ", &known);
    rows.push_back(RunOmnidirStereo(board, pairs, known,
                                    cv::Size(set.rig.cam0.width, set.rig.cam0.height),
                                    cv::Size(set.rig.cam1.width, set.rig.cam1.height)));
    double rms0 = 0.0, rms1 = 0.0;
    const CameraModel cam0 = CalibrateCamera(pairs, 0, set.rig.cam0.width, set.rig.cam0.height,
                                             board, &rms0);
    const CameraModel cam1 = CalibrateCamera(pairs, 1, set.rig.cam1.width, set.rig.cam1.height,
                                             board, &rms1);
    RelativePoseReport calibrated;
    for (const Row& row : OurRows(cam0, cam1, board, pairs, "calibrated: ", &calibrated)) {
      rows.push_back(row);
    }
    char title[400];
    std::snprintf(title, sizeof(title),
                  "Synthetic vertical rig, detector corners + %.1f px Gaussian noise (detector "
                  "error alone: max %.3f px); true baseline %.3f mm; per-camera calibration "
                  "RMS %.4f / %.4f px (targets: |error| < 0.01%%, rotation < 0.01 deg)",
                  corner_noise_px, max_detection_error_px, truth.translation.norm() * 1e3, rms0,
                  rms1);
    PrintRows(title, rows, &truth, truth.translation.norm());
    if (known.success) triangulation_rigs.push_back({std::string(label) + ", known cameras",
                                                     known.rig});
    if (calibrated.success) {
      triangulation_rigs.push_back({std::string(label) + ", calibrated", calibrated.rig});
    }
  }
  double max_detection_error_px = 0.0;
  for (double corner_noise_px : {0.0, 0.2}) {
    const std::vector<StereoBoardPair> far_pairs =
        DetectPairs(far, board, corner_noise_px, true, &max_detection_error_px);
    PrintTriangulationHeader();
    std::printf("(triangulated corners: detector + %.1f px noise)\n", corner_noise_px);
    for (const auto& [name, rig] : triangulation_rigs) {
      PrintTriangulation("rig: " + name, far, board, rig, far_pairs);
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
  std::vector<StereoBoardPair> pairs;
  cv::Size size;
  const auto start = std::chrono::steady_clock::now();
  for (int i = 1; i <= 29; ++i) {
    const cv::Mat left = cv::imread((dir / ("left" + std::to_string(i) + ".jpg")).string(),
                                    cv::IMREAD_GRAYSCALE);
    const cv::Mat right = cv::imread((dir / ("right" + std::to_string(i) + ".jpg")).string(),
                                     cv::IMREAD_GRAYSCALE);
    if (left.empty() || right.empty()) continue;
    size = left.size();
    pairs.push_back({"pair" + std::to_string(i), DetectBoard(left, board, DetectOptions()),
                     DetectBoard(right, board, DetectOptions())});
  }
  int found0 = 0, found1 = 0;
  for (const auto& pair : pairs) found0 += pair.cam0.found, found1 += pair.cam1.found;
  std::printf("\nReal fisheye pairs: %zu pairs, board found in %d left / %d right images "
              "(%.1f s)\n", pairs.size(), found0, found1, Seconds(start));
  double rms0 = 0.0, rms1 = 0.0;
  const CameraModel cam0 = CalibrateCamera(pairs, 0, size.width, size.height, board, &rms0);
  const CameraModel cam1 = CalibrateCamera(pairs, 1, size.width, size.height, board, &rms1);
  RelativePoseReport fixed;
  std::vector<Row> rows = OurRows(cam0, cam1, board, pairs, "", &fixed);
  rows.push_back(RunOmnidirStereo(board, pairs, fixed, size, size));
  PrintRows("Real fisheye pairs, reference baseline 109.96 mm (targets: within 0.2%, RMS < "
            "0.5 px); per-camera calibration RMS " + std::to_string(rms0) + " / " +
                std::to_string(rms1) + " px",
            rows, nullptr, 0.10996);
  std::printf("per-pair RMS (px, joint, cameras fixed):");
  for (const auto& pair : fixed.pairs) {
    std::printf(" %s=%.2f", pair.name.c_str(), pair.used ? pair.rms_px : -1.0);
  }
  std::printf("\n");
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // tables appear as they are measured
  bool quick = false;
  std::filesystem::path data_dir = std::filesystem::path(OMNIRIG_SOURCE_DIR) / ".." / "shared" /
                                   "data" / "real";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    if (std::strcmp(argv[i], "--data") == 0 && i + 1 < argc) data_dir = argv[++i];
  }
  try {
    omnirig::RunSynthetic(quick);
    omnirig::RunRealFisheye(data_dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_relpose: %s\n", e.what());
    return 1;
  }
  return 0;
}
