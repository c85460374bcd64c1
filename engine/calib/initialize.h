#pragma once
// Closed-form initialisation of the unified model from board detections (Mei and Rives 2007,
// section IV, as the paper's section 3.2 uses it): xi = 1 and no distortion, the principal point
// from the mirror rim circle or the image centre, the generalised focal length gamma from
// collinear board corners, and each board's pose from its lifted bearings.

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"

namespace omnirig {

// A view's corners and their points on the board.
struct InitView {
  std::vector<Eigen::Vector3d> object_points;
  std::vector<Eigen::Vector2d> corners_px;
  // Groups of indices (into the two vectors above) of corners on one board line (rows and
  // columns), each with at least 3 corners.
  std::vector<std::vector<int>> lines;
};

// Gamma from collinear pixels, with xi = 1 and the principal point at `principal_point_px`:
// the points' bearings (u, v, gamma/2 - rho^2/(2 gamma)) lie on a plane through the centre, so
// [u v 1 rho^2] c = 0 and gamma^2 = -c3/c4. nullopt for a line through the centre (degenerate)
// or a negative ratio.
std::optional<double> GammaFromLine(const std::vector<Eigen::Vector2d>& pixels,
                                    const Eigen::Vector2d& principal_point_px);

struct InitResult {
  CameraModel camera;
  std::vector<std::optional<Rigid3d>> cam_from_board;  // per view; nullopt when it failed
  double score_px = 0.0;  // median view RMS that chose this candidate
};

// Tries every principal point candidate with every gamma candidate (from all board lines),
// scores each by the median per-view RMS of the linear board poses, and returns the best one
// with refined poses. nullopt when no candidate gives a pose for any view.
std::optional<InitResult> InitializeUnified(const std::vector<InitView>& views, int width,
                                            int height,
                                            const std::vector<Eigen::Vector2d>& principal_points);

}  // namespace omnirig
