#pragma once
// The calibration board (engine/calib) that a rendered checkerboard (engine/synth) shows, for the
// tests and benchmarks that render a board and then detect or fit it, and the quick stereo board
// renders they use. Header-only, so that neither library depends on the other.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/estimators/board_pose.h"
#include "engine/geometry/unified_camera.h"
#include "engine/synth/presets.h"
#include "engine/synth/scene.h"

namespace omnirig {
namespace synth {

// Small, quick stereo renders for tests and the detector bench: num_pairs pairs at 800x600,
// 2x2 supersampling, 0.5 px blur, image noise of 2 grey levels, grey.
inline StereoBoardOptions QuickStereoBoardOptions(int num_pairs, uint64_t seed) {
  StereoBoardOptions options;
  options.num_pairs = num_pairs;
  options.width = 800;
  options.height = 600;
  options.render.supersampling = 2;
  options.render.noise_sigma = 2.0;
  options.render.blur_sigma_px = 0.5;
  options.render.grayscale = true;
  options.seed = seed;
  return options;
}

// A board waved in front of `camera` for num_frames frames: stretches of segment_frames frames
// of smooth motion (smoothstep in time, slerp) between poses drawn around the mirror
// (SampleBoardPose); of every five stretches the fourth carries the board away along the camera
// axis, where the mirror's hole hides it (partly out of view on the way), and the fifth holds it
// there for 40 % of the stretch, then brings it to the next pose.
inline std::vector<Rigid3d> WavedBoardTrajectory(const SynthCamera& camera,
                                                 const CheckerboardSpec& board, int num_frames,
                                                 int segment_frames, uint64_t seed) {
  const int num_segments = (num_frames + segment_frames - 1) / segment_frames;
  std::vector<Rigid3d> keys;
  for (int k = 0; k <= num_segments; ++k) {
    keys.push_back(SampleBoardPose({camera}, {Rigid3d()}, board, BoardPoseOptions(), k,
                                   num_segments + 1, seed));
  }
  auto interpolate = [](const Rigid3d& a, const Rigid3d& b, double t) {
    const double s = t * t * (3.0 - 2.0 * t);
    return Rigid3d(a.rotation.slerp(s, b.rotation), (1.0 - s) * a.translation + s * b.translation);
  };
  auto away = [](const Rigid3d& pose) {
    return Rigid3d(pose.rotation, Eigen::Vector3d(0.0, 0.0, pose.translation.norm()));
  };
  std::vector<Rigid3d> trajectory;
  for (int f = 0; f < num_frames; ++f) {
    const int segment = f / segment_frames;
    const double t = static_cast<double>(f % segment_frames) / segment_frames;
    const Rigid3d& from = keys[segment];
    const Rigid3d& to = keys[segment + 1];
    if (segment % 5 == 3) {
      trajectory.push_back(interpolate(from, away(from), t));
    } else if (segment % 5 == 4) {
      trajectory.push_back(t < 0.4 ? away(to) : interpolate(away(to), to, (t - 0.4) / 0.6));
    } else {
      trajectory.push_back(interpolate(from, to, t));
    }
  }
  return trajectory;
}

}  // namespace synth

inline BoardSpec ToBoardSpec(const synth::CheckerboardSpec& spec) {
  BoardSpec board;
  board.cols = spec.cols;
  board.rows = spec.rows;
  board.square_size_m = spec.square_size_m;
  return board;
}

// The RMS reprojection error (px) of `camera` over every corner of the found views of `views`,
// each view's board pose fitted with the camera (EstimateBoardPose): two calibrations compared on
// the same corners. Views whose pose does not fit count as missing (num_missing).
inline double RmsOverViews(const CameraModel& camera, const BoardSpec& board,
                           const std::vector<CalibrationView>& views, int* num_missing) {
  const std::vector<Eigen::Vector3d> object = board.ObjectPoints();
  double sum2 = 0.0;
  size_t n = 0;
  *num_missing = 0;
  for (const CalibrationView& view : views) {
    if (!view.detection.found) continue;
    std::vector<Eigen::Vector3d> points;
    for (int id : view.detection.corner_ids) points.push_back(object[id]);
    double rms = 0.0;
    if (!EstimateBoardPose(camera, points, view.detection.corners_px, &rms)) {
      ++*num_missing;
      continue;
    }
    sum2 += rms * rms * points.size();
    n += points.size();
  }
  return n ? std::sqrt(sum2 / n) : 0.0;
}

// Mean distance in pixels of a detection's corners to the rendered truth (indexed by corner id).
// A checkerboard's numbering is defined up to the 180 degree turn of the board (both are rigid
// poses), so the better of the two is taken.
inline double MeanCornerError(const BoardDetection& detection,
                              const std::vector<Eigen::Vector2d>& truth) {
  double direct = 0.0, turned = 0.0;
  const int n = static_cast<int>(truth.size());
  for (size_t i = 0; i < detection.corners_px.size(); ++i) {
    const int id = detection.corner_ids[i];
    direct += (detection.corners_px[i] - truth[id]).norm();
    turned += (detection.corners_px[i] - truth[n - 1 - id]).norm();
  }
  return std::min(direct, turned) / std::max<size_t>(1, detection.corners_px.size());
}

// cam1's detection of rendered pair `pair` of `set` as if the board had moved by
// `shift_in_cam0_m` (cam0's frame) between the two exposures: each detected corner displaced
// by the exact change of its projection in the true camera (the corner it is: the nearest
// rendered one), so that the detector's own error stays as rendered. Unsynchronised pairs for
// the synchronisation test's power, without rendering again.
inline void MoveBoardBeforeCam1(const synth::StereoBoardSet& set, size_t pair,
                                const Eigen::Vector3d& shift_in_cam0_m, BoardDetection* cam1) {
  const Rigid3d& cam0_from_board = set.cam0_from_board[pair];
  const Rigid3d moved(cam0_from_board.rotation, cam0_from_board.translation + shift_in_cam0_m);
  const Rigid3d cam1_from_cam0 = set.rig.cam0_from_cam1.Inverse();
  const std::vector<Eigen::Vector3d> object = ToBoardSpec(set.board).ObjectPoints();
  const std::vector<Eigen::Vector2d>& truth = set.corners_px[1][pair];
  for (Eigen::Vector2d& corner : cam1->corners_px) {
    size_t id = 0;
    for (size_t k = 1; k < truth.size(); ++k) {
      if ((truth[k] - corner).squaredNorm() < (truth[id] - corner).squaredNorm()) id = k;
    }
    const auto before =
        Project(set.rig.cam1.intrinsics, cam1_from_cam0 * cam0_from_board * object[id]);
    const auto after = Project(set.rig.cam1.intrinsics, cam1_from_cam0 * moved * object[id]);
    if (before && after) corner += *after - *before;
  }
}

}  // namespace omnirig
