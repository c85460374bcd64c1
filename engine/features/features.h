#pragma once
// Per-image features for SLAM: the mirror disk mask, SIFT keypoints and descriptors (OpenCV),
// each keypoint lifted to its unit bearing through the unified model (eq. 6).

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/geometry/camera_model.h"

namespace omnirig {

struct FeatureOptions {
  // Per image, strongest first (0 = no limit). SIFT's descriptors cost ~35 us each and dominate
  // the front end; on the synthetic room 1000 track as well as 1500 (drift and map accuracy
  // unchanged) for two thirds of the detection time, and 800 as well as 1000 (room: drift
  // 0.121 / 0.123 %, map median 0.52 / 0.53 % of range; 100 m loop driven twice: recall 100 %,
  // ATE 0.0103 % either way) for 12-18 % less CPU per frame end to end (docs/accuracy.md).
  int max_features = 800;
  double contrast_threshold = 0.03; // SIFT's, on the [0, 1] intensity scale
  // Grey level below which a pixel counts as outside the mirror (rim, central hole).
  double dark_level = 24.0;
  // Keypoints closer than this to the mirror's rim or hole are dropped: the rim's edge is
  // not a scene feature.
  double mask_margin_px = 8.0;
  // SIFT runs on the image resized by this factor (1 = full resolution). OpenCV's SIFT first
  // doubles its input, so 0.5 detects at the full image's own resolution for a quarter of the
  // work; keypoints are mapped back to full-resolution pixels.
  double detection_scale = 0.5;
  void Check() const;
};

// The mirror's image: pixels between hole_radius_px and rim_radius_px around centre_px.
struct MirrorAnnulus {
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();
  double hole_radius_px = 0.0;
  double rim_radius_px = 0.0;
};

// Finds the annulus of `image` around the calibration's principal point: the rim is where the
// share of dark pixels on a circle first exceeds 80% going outwards from the brightest radius,
// the hole where it does so going inwards. An image with no dark border (a fisheye) gives
// hole 0 and a rim beyond the image corners.
MirrorAnnulus EstimateMirrorAnnulus(const CameraModel& camera, const cv::Mat& image,
                                    double dark_level);

// CV_8U mask (255 inside): the annulus shrunk by margin_px on both sides. Pixels that do not
// lift are not excluded here (lifting every pixel is slow); DetectFeatures drops such keypoints.
cv::Mat MirrorMask(const CameraModel& camera, const MirrorAnnulus& annulus, double margin_px);

// Mean grey level of `image` inside `mask` (a black image or a covered lens is near 0).
double MeanIntensity(const cv::Mat& image, const cv::Mat& mask);

struct CameraFeatures {
  std::vector<Eigen::Vector2d> pixels;    // keypoint centres, pixels
  std::vector<Eigen::Vector3d> bearings;  // unit, in the camera frame
  std::vector<std::array<std::uint8_t, 3>> rgb;
  cv::Mat descriptors;                    // CV_32F, one row per feature
  int size() const { return static_cast<int>(pixels.size()); }
};

// SIFT inside `mask` on an 8-bit BGR or grey image; keypoints that do not lift are dropped.
CameraFeatures DetectFeatures(const CameraModel& camera, const cv::Mat& image,
                              const cv::Mat& mask, const FeatureOptions& options);

}  // namespace omnirig
