#pragma once
// The mirror's image in an omnidirectional image: what lies between the central hole and the
// rim, without the housing and the dark border beyond the rim. One function for the sparse
// stereo pair, SLAM and dense stereo; the shape option says how each finds the outside.

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/geometry/camera_model.h"

namespace omnirig {

struct MirrorMaskOptions {
  enum class Shape {
    // A circular annulus around centre_px (EstimateMirrorAnnulus), shrunk by margin_px on both
    // sides. SLAM makes it once per sequence: a circle does not follow a dark scene patch at
    // the rim from frame to frame.
    kAnnulus,
    // Dark regions (8-connected) that touch the image border (beyond the rim) or hold
    // centre_px (the central hole) are outside; dark patches of the scene inside the mirror are
    // kept. Then eroded by margin_px. One raw image (the sparse stereo pair).
    kDarkRegions,
    // Along each row, the dark runs from either end are outside (cells outside `valid` count as
    // dark); then eroded by margin_px, beyond the grid counting as outside. The spherically
    // rectified grid, whose rows run from beyond the rim to the hole (dense stereo).
    kDarkRowEnds,
  };
  Shape shape = Shape::kDarkRegions;
  // kDarkRegions, kDarkRowEnds: a pixel is dark when its 5x5-blurred grey level is at or below
  // dark_level. kAnnulus: the annulus's edges are where most unblurred pixels on a circle are
  // below dark_level.
  double dark_level = 20.0;
  // Kept clear of the mirror's edges: the rim's edge is not a scene feature. The erosions
  // (kDarkRegions, kDarkRowEnds) round it to whole pixels.
  double margin_px = 6.0;
  void Check() const;
};

// CV_8U mask of `image` (8-bit grey or BGR, or any image ToGreyscale8 takes), 255 inside the
// mirror. centre_px is the principal point (kAnnulus, kDarkRegions); `valid` (CV_8U, the
// image's size or empty) marks the cells that have an image (kDarkRowEnds). Pixels that do
// not lift are not excluded (lifting every pixel is slow): the detectors drop such keypoints.
cv::Mat MirrorMask(const cv::Mat& image, const Eigen::Vector2d& centre_px,
                   const MirrorMaskOptions& options, const cv::Mat& valid = cv::Mat());

// The principal point of `camera`, for MirrorMask.
Eigen::Vector2d PrincipalPoint(const CameraModel& camera);

// The mirror's image: pixels between hole_radius_px and rim_radius_px around centre_px.
struct MirrorAnnulus {
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();
  double hole_radius_px = 0.0;
  double rim_radius_px = 0.0;
};

// Finds the annulus of `image` around centre_px: the rim is where the share of dark pixels on
// a circle first exceeds 80% going outwards from the brightest radius, the hole where it does
// so going inwards. An image with no dark border (a fisheye) gives hole 0 and a rim beyond the
// image corners.
MirrorAnnulus EstimateMirrorAnnulus(const cv::Mat& image, const Eigen::Vector2d& centre_px,
                                    double dark_level);

}  // namespace omnirig
