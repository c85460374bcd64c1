#include "engine/features/features.h"

#include <algorithm>
#include <cmath>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/features/sift_bias.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

cv::Mat ToGray(const cv::Mat& image) {
  OMNIRIG_CHECK(!image.empty() && image.depth() == CV_8U &&
                    (image.channels() == 1 || image.channels() == 3),
                "SLAM images must be 8-bit grey or BGR");
  if (image.channels() == 1) return image;
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

}  // namespace

void FeatureOptions::Check() const {
  OMNIRIG_CHECK_NON_NEGATIVE(max_features);
  OMNIRIG_CHECK_IN(contrast_threshold, '(', 0, 1, ')');
  OMNIRIG_CHECK_IN(dark_level, '[', 0, 255, ')');
  OMNIRIG_CHECK_NON_NEGATIVE(mask_margin_px);
  OMNIRIG_CHECK_IN(detection_scale, '(', 0.1, 1, ']');
}

MirrorAnnulus EstimateMirrorAnnulus(const CameraModel& camera, const cv::Mat& image,
                                    double dark_level) {
  const cv::Mat gray = ToGray(image);
  MirrorAnnulus annulus;
  annulus.centre_px = Eigen::Vector2d(camera.intrinsics.u0(), camera.intrinsics.v0());
  const double max_radius = std::hypot(std::max(annulus.centre_px.x(), gray.cols - annulus.centre_px.x()),
                                       std::max(annulus.centre_px.y(), gray.rows - annulus.centre_px.y()));
  const int num_bins = static_cast<int>(max_radius) + 2;
  std::vector<int> dark(num_bins, 0), total(num_bins, 0);
  for (int v = 0; v < gray.rows; v += 2) {  // every other row and column is plenty
    const std::uint8_t* row = gray.ptr<std::uint8_t>(v);
    for (int u = 0; u < gray.cols; u += 2) {
      const int bin = static_cast<int>(std::hypot(u - annulus.centre_px.x(), v - annulus.centre_px.y()));
      ++total[bin];
      if (row[u] < dark_level) ++dark[bin];
    }
  }
  // Share of dark pixels per radius, smoothed over 3 px so single rings do not decide.
  auto dark_share = [&](int bin) {
    int d = 0, t = 0;
    for (int b = std::max(0, bin - 1); b <= std::min(num_bins - 1, bin + 1); ++b) {
      d += dark[b];
      t += total[b];
    }
    return t > 0 ? static_cast<double>(d) / t : 1.0;
  };
  int brightest = 0;
  for (int bin = 0; bin < num_bins; ++bin) {
    if (total[bin] >= 8 && dark_share(bin) < dark_share(brightest)) brightest = bin;
  }
  annulus.rim_radius_px = max_radius + 1;
  for (int bin = brightest; bin < num_bins; ++bin) {
    if (total[bin] >= 8 && dark_share(bin) > 0.8) {
      annulus.rim_radius_px = bin;
      break;
    }
  }
  for (int bin = brightest; bin >= 0; --bin) {
    if (total[bin] >= 4 && dark_share(bin) > 0.8) {
      annulus.hole_radius_px = bin + 1;
      break;
    }
  }
  return annulus;
}

cv::Mat MirrorMask(const CameraModel& camera, const MirrorAnnulus& annulus, double margin_px) {
  OMNIRIG_CHECK(camera.width > 0 && camera.height > 0, "camera without an image size");
  cv::Mat mask(camera.height, camera.width, CV_8U, cv::Scalar(0));
  const double inner = annulus.hole_radius_px + margin_px;
  const double outer = annulus.rim_radius_px - margin_px;
  for (int v = 0; v < mask.rows; ++v) {
    std::uint8_t* row = mask.ptr<std::uint8_t>(v);
    for (int u = 0; u < mask.cols; ++u) {
      const double r = std::hypot(u - annulus.centre_px.x(), v - annulus.centre_px.y());
      if (r >= inner && r <= outer) row[u] = 255;
    }
  }
  return mask;
}

double MeanIntensity(const cv::Mat& image, const cv::Mat& mask) {
  return cv::mean(ToGray(image), mask)[0];
}

CameraFeatures DetectFeatures(const CameraModel& camera, const cv::Mat& image, const cv::Mat& mask,
                              const FeatureOptions& options) {
  options.Check();
  const cv::Mat gray = ToGray(image);
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
