#pragma once
// Single-viewpoint check (the paper's section 2.2, Fig. 3): a catadioptric sensor has a single
// viewpoint only when the camera sits at the mirror's second focus. Then the mirror's rim, a
// circle of known radius at a known height above the mirror's focus, projects where the
// calibrated model predicts it. This predicts the rim circle in the image, finds the actual rim
// (radial intensity profiles around the prediction, strongest dark-bright edge, robust circle
// fit) and reports the offset. Without the mirror's dimensions, DetectRim finds the rim around
// the principal point alone and reports its centre against the principal point (for a
// single-viewpoint sensor with a radially symmetric model they coincide).

#include <optional>
#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/geometry/camera_model.h"

namespace omnirig {

// The mirror's rim in the model (mirror) frame: a circle of radius rim_radius_m in the plane
// z = rim_height_m, centred on the z axis. For a hyperbolic mirror z^2/a^2 - r^2/b^2 = 1 with its
// focus at the origin, rim_height_m is the rim's z minus the focus' z.
struct MirrorRim {
  double rim_radius_m = 0.0;
  double rim_height_m = 0.0;
  void Check() const;
};

struct SvpCheckOptions {
  double search_margin_px = 40.0;  // radial search range around the predicted rim
  int num_profiles = 360;          // radial profiles, evenly spaced in angle
  double inlier_px = 2.0;          // circle-fit inlier distance
  void Check() const;
};

struct SvpCheckReport {
  // u, v, radius (px). predicted_circle_px is absent when no mirror was given (DetectRim);
  // found_circle_px when the rim was not found (see reason).
  std::optional<Eigen::Vector3d> predicted_circle_px;
  std::optional<Eigen::Vector3d> found_circle_px;
  double centre_offset_px = 0.0;  // |found centre - predicted centre|
  double radius_offset_px = 0.0;  // found radius - predicted radius
  Eigen::Vector2d principal_point_px = Eigen::Vector2d::Zero();  // (u0, v0) of the model
  double principal_point_offset_px = 0.0;                        // |found centre - principal point|
  int num_edge_points = 0;                                       // inliers of the fit
  std::string reason;                                            // why the rim was not found
};

// Throws InvalidArgument for an empty image, a rim that does not project, or invalid options.
SvpCheckReport CheckSingleViewpoint(const cv::Mat& image, const CameraModel& camera,
                                    const MirrorRim& rim, const SvpCheckOptions& options);

// The rim without the mirror's dimensions: the radius at which the intensity, averaged over
// every direction around the principal point, steps most sharply, refined as in
// CheckSingleViewpoint. Throws InvalidArgument for an empty image or invalid options.
SvpCheckReport DetectRim(const cv::Mat& image, const CameraModel& camera,
                         const SvpCheckOptions& options);

// The image with the predicted rim (red), the found rim (green), the principal point (blue
// cross), and the offsets as text.
cv::Mat DrawSvpOverlay(const cv::Mat& image, const SvpCheckReport& report);

}  // namespace omnirig
