#pragma once
// Per-image features for SLAM: SIFT keypoints and descriptors (OpenCV),
// each keypoint lifted to its unit bearing through the unified model (eq. 6).

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "engine/features/mirror_mask.h"
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
  // The mirror's mask, made once per sequence on the first usable images: keypoints closer
  // than margin_px to the rim or the hole are dropped.
  MirrorMaskOptions mirror_mask = {MirrorMaskOptions::Shape::kAnnulus, 24.0, 8.0};
  // SIFT runs on the image resized by this factor (1 = full resolution). OpenCV's SIFT first
  // doubles its input, so 0.5 detects at the full image's own resolution for a quarter of the
  // work; keypoints are mapped back to full-resolution pixels.
  double detection_scale = 0.5;
  void Check() const;
};

// Mean grey level of `image` (8-bit grey or BGR) inside `mask` (a black image or a covered
// lens is near 0).
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

// The keypoints (full-resolution pixels, bias corrected) that lift through `camera`, with their
// unit bearings, the colour of `image` (8-bit grey or BGR) at each and their rows of
// `descriptors` (CV_32F, one row per keypoint).
CameraFeatures LiftKeypoints(const CameraModel& camera, const cv::Mat& image,
                             const std::vector<cv::KeyPoint>& keypoints,
                             const cv::Mat& descriptors);

}  // namespace omnirig
