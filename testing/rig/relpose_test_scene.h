#pragma once
// Synthetic scenes for the stereo rig's tests: the paper's vertical rig of two hyperbolic-mirror
// cameras and boards around it, corners projected exactly (plus optional Gaussian noise).

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "engine/rig/relative_pose.h"

namespace omnirig {
namespace relpose_test {

constexpr double kDegPerRad = 180.0 / M_PI;

// A hyperbolic-mirror-like camera of 1024 x 768 (the camera's +z points down from the mirror
// towards the camera, so the horizon images on a ring around the principal point).
inline CameraModel MakeCamera(double gamma, double u0, double v0) {
  CameraModel camera;
  camera.width = 1024;
  camera.height = 768;
  camera.intrinsics.params = {0.94,  gamma, gamma * 1.002, u0,      v0, 0.0,
                              -0.06, 0.012, 0.0004,        -0.0003, 0.0};
  return camera;
}

// The paper's vertical rig: cam1 100 mm above cam0 (above = -z in these camera frames), with a
// small misalignment.
inline Rigid3d VerticalRig() {
  const Eigen::Quaterniond rotation(
      Eigen::AngleAxisd(0.8 / kDegPerRad, Eigen::Vector3d(0.3, -0.5, 1.0).normalized()));
  return Rigid3d(rotation, Eigen::Vector3d(0.0021, -0.0013, -0.0998));
}

// A board facing the rig at `azimuth_deg` around it, `distance_m` away, tilted a little.
inline Rigid3d BoardPose(const BoardSpec& board, double azimuth_deg, double distance_m,
                         double tilt_deg, double height_m) {
  const double a = azimuth_deg / kDegPerRad;
  const Eigen::Vector3d centre(distance_m * std::cos(a), distance_m * std::sin(a), height_m);
  const Eigen::Vector3d z_axis = Eigen::Vector3d(centre.x(), centre.y(), 0.0).normalized();
  const Eigen::Vector3d x_axis(-std::sin(a), std::cos(a), 0.0);
  Eigen::Matrix3d facing;
  facing << x_axis, z_axis.cross(x_axis), z_axis;
  const Eigen::Matrix3d tilt =
      Eigen::AngleAxisd(tilt_deg / kDegPerRad, Eigen::Vector3d(1.0, 0.6, 0.2).normalized())
          .toRotationMatrix();
  const Eigen::Matrix3d rotation = facing * tilt;
  const Eigen::Vector3d board_centre(0.5 * (board.cols - 1) * board.square_size_m,
                                     0.5 * (board.rows - 1) * board.square_size_m, 0.0);
  return Rigid3d(Eigen::Quaterniond(rotation), centre - rotation * board_centre);
}

inline BoardDetection Detect(const CameraModel& camera, const BoardSpec& board,
                             const Rigid3d& cam_from_board, double noise_px, std::mt19937* rng) {
  std::normal_distribution<double> noise(0.0, noise_px);
  BoardDetection detection;
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  for (size_t id = 0; id < object_points.size(); ++id) {
    const auto pixel = Project(camera.intrinsics, cam_from_board * object_points[id]);
    if (!pixel) continue;
    const Eigen::Vector2d offset =
        noise_px > 0.0 ? Eigen::Vector2d(noise(*rng), noise(*rng)) : Eigen::Vector2d::Zero();
    detection.corners_px.push_back(*pixel + offset);
    detection.corner_ids.push_back(static_cast<int>(id));
  }
  detection.found = detection.corners_px.size() == object_points.size();
  if (!detection.found) detection.reason = "corners outside the image";
  return detection;
}

// Renumbers a detection as if the detector had started from the other end of the grid.
inline void HalfTurn(const BoardSpec& board, BoardDetection* detection) {
  for (int& id : detection->corner_ids) id = board.NumCorners() - 1 - id;
}

struct Scene {
  BoardSpec board;
  StereoRig rig;
  std::vector<StereoBoardPair> pairs;
};

// The board's pose in cam0 for pair i of num_pairs: around the rig, 0.6 to 0.9 m away.
inline Rigid3d PairBoardPose(const BoardSpec& board, int i, int num_pairs) {
  return BoardPose(board, 360.0 * i / num_pairs, 0.6 + 0.1 * (i % 4), 15.0 + 7.0 * (i % 3),
                   -0.05 + 0.02 * (i % 5));
}

// Pairs of `scene.board` seen by `scene.rig` (both set), replacing scene->pairs.
inline void ProjectPairs(double noise_px, int num_pairs, unsigned seed, Scene* scene) {
  std::mt19937 rng(seed);
  scene->pairs.clear();
  for (int i = 0; i < num_pairs; ++i) {
    const Rigid3d cam0_from_board = PairBoardPose(scene->board, i, num_pairs);
    const Rigid3d cam1_from_board = scene->rig.cam0_from_cam1.Inverse() * cam0_from_board;
    StereoBoardPair pair;
    pair.name = "pair" + std::to_string(i);
    pair.cam0 = Detect(scene->rig.cam0, scene->board, cam0_from_board, noise_px, &rng);
    pair.cam1 = Detect(scene->rig.cam1, scene->board, cam1_from_board, noise_px, &rng);
    scene->pairs.push_back(pair);
  }
}

inline Scene MakeScene(double noise_px, int num_pairs, unsigned seed, int cols = 7, int rows = 5) {
  Scene scene;
  scene.board.cols = cols;
  scene.board.rows = rows;
  scene.board.square_size_m = 0.04;
  scene.rig.cam0 = MakeCamera(238.0, 515.0, 381.0);
  scene.rig.cam1 = MakeCamera(241.0, 509.0, 386.0);
  scene.rig.cam0_from_cam1 = VerticalRig();
  ProjectPairs(noise_px, num_pairs, seed, &scene);
  return scene;
}

// Unsynchronised exposures: pair `index`'s board moved by `shift_in_cam0_m` (cam0's frame)
// after cam0's shot and before cam1's; cam1's corners are projected again from the moved
// board with fresh noise of `noise_px`.
inline void MoveBoardBeforeCam1(int index, const Eigen::Vector3d& shift_in_cam0_m, double noise_px,
                                unsigned seed, Scene* scene) {
  const int num_pairs = static_cast<int>(scene->pairs.size());
  const Rigid3d cam0_from_board = PairBoardPose(scene->board, index, num_pairs);
  const Rigid3d moved(cam0_from_board.rotation, cam0_from_board.translation + shift_in_cam0_m);
  std::mt19937 rng(seed);
  scene->pairs[index].cam1 = Detect(scene->rig.cam1, scene->board,
                                    scene->rig.cam0_from_cam1.Inverse() * moved, noise_px, &rng);
}

inline RelativePoseReport Estimate(const Scene& scene, const RelativePoseOptions& options = {}) {
  return EstimateRelativePose(scene.rig.cam0, scene.rig.cam1, scene.board, scene.pairs, options);
}

inline double RotationErrorDeg(const Rigid3d& a, const Rigid3d& b) {
  return RotationDistanceRad(a.rotation, b.rotation) * kDegPerRad;
}

}  // namespace relpose_test
}  // namespace omnirig
