#include "engine/features/features.h"

#include <algorithm>
#include <cmath>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/features/image.h"
#include "engine/features/sift_bias.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {

void FeatureOptions::Check() const {
  OMNIRIG_CHECK_NON_NEGATIVE(max_features);
  OMNIRIG_CHECK_IN(contrast_threshold, '(', 0, 1, ')');
  mirror_mask.Check();
  OMNIRIG_CHECK_IN(detection_scale, '(', 0.1, 1, ']');
}

double MeanIntensity(const cv::Mat& image, const cv::Mat& mask) {
  CheckGreyOrBgr8(image);
  return cv::mean(ToGreyscale8(image), mask)[0];
}

CameraFeatures DetectFeatures(const CameraModel& camera, const cv::Mat& image, const cv::Mat& mask,
                              const FeatureOptions& options) {
  options.Check();
  CheckGreyOrBgr8(image);
  const cv::Mat gray = ToGreyscale8(image);
  OMNIRIG_CHECK(mask.empty() || mask.size() == gray.size(), "mask and image sizes differ");
  // Only the mask's bounding box is searched: the mirror's disk leaves the corners dark.
  const cv::Rect roi = mask.empty() ? cv::Rect(0, 0, gray.cols, gray.rows) : cv::boundingRect(mask);
  if (roi.area() == 0) return CameraFeatures();
  cv::Mat search = gray(roi), search_mask = mask.empty() ? cv::Mat() : mask(roi);
  const double scale = options.detection_scale;
  if (scale < 1) {
    cv::resize(search, search, cv::Size(), scale, scale, cv::INTER_AREA);
    if (!search_mask.empty()) {
      cv::resize(search_mask, search_mask, search.size(), 0, 0, cv::INTER_NEAREST);
    }
  }
  const cv::Ptr<cv::SIFT> sift = cv::SIFT::create(options.max_features, 3,
                                                  options.contrast_threshold);
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  sift->detectAndCompute(search, search_mask, keypoints, descriptors);
  // OpenCV's SIFT reports keypoints a quarter pixel off (sift_bias.h). At detection_scale 0.5
  // that is 0.5 full-size pixels: uncorrected, the calibration refinement moved u0 and v0 by
  // +0.5 px on renders.
  constexpr double kSiftUpscaleBias = kOpenCvSiftUpscaleBiasPx;
  for (cv::KeyPoint& keypoint : keypoints) {
    // Pixel centres: small pixel i covers full pixels [i / scale, (i + 1) / scale).
    keypoint.pt.x = static_cast<float>((keypoint.pt.x - kSiftUpscaleBias + 0.5) / scale - 0.5 +
                                       roi.x);
    keypoint.pt.y = static_cast<float>((keypoint.pt.y - kSiftUpscaleBias + 0.5) / scale - 0.5 +
                                       roi.y);
  }
  return LiftKeypoints(camera, image, keypoints, descriptors);
}

CameraFeatures LiftKeypoints(const CameraModel& camera, const cv::Mat& image,
                             const std::vector<cv::KeyPoint>& keypoints,
                             const cv::Mat& descriptors) {
  OMNIRIG_CHECK(descriptors.rows == static_cast<int>(keypoints.size()),
                "one descriptor row per keypoint");
  CameraFeatures features;
  std::vector<int> kept_rows;
  for (size_t i = 0; i < keypoints.size(); ++i) {
    const Eigen::Vector2d pixel(keypoints[i].pt.x, keypoints[i].pt.y);
    const std::optional<Eigen::Vector3d> bearing = Lift(camera.intrinsics, pixel);
    if (!bearing) continue;
    features.pixels.push_back(pixel);
    features.bearings.push_back(bearing->normalized());
    const int u = std::clamp(static_cast<int>(std::lround(pixel.x())), 0, image.cols - 1);
    const int v = std::clamp(static_cast<int>(std::lround(pixel.y())), 0, image.rows - 1);
    if (image.channels() == 3) {
      const cv::Vec3b bgr = image.at<cv::Vec3b>(v, u);
      features.rgb.push_back({bgr[2], bgr[1], bgr[0]});
    } else {
      const std::uint8_t g = image.at<std::uint8_t>(v, u);
      features.rgb.push_back({g, g, g});
    }
    kept_rows.push_back(static_cast<int>(i));
  }
  features.descriptors.create(static_cast<int>(kept_rows.size()), descriptors.cols, CV_32F);
  for (size_t r = 0; r < kept_rows.size(); ++r) {
    descriptors.row(kept_rows[r]).copyTo(features.descriptors.row(static_cast<int>(r)));
  }
  return features;
}

}  // namespace omnirig
