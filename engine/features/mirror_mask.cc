#include "engine/features/mirror_mask.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <set>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "engine/features/image.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

// 255 where the 5x5-blurred grey level is at or below dark_level.
cv::Mat DarkPixels(const cv::Mat& grey, double dark_level) {
  cv::Mat blurred;
  cv::GaussianBlur(grey, blurred, cv::Size(5, 5), 0.0);
  return blurred <= dark_level;
}

cv::Mat AnnulusMask(const cv::Size& size, const MirrorAnnulus& annulus, double margin_px) {
  cv::Mat mask(size, CV_8U, cv::Scalar(0));
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

cv::Mat DarkRegionsMask(const cv::Mat& grey, const Eigen::Vector2d& centre_px, double dark_level) {
  cv::Mat labels;
  cv::connectedComponents(DarkPixels(grey, dark_level), labels, 8, CV_32S);
  // Labels of the dark regions outside the rim (touching the border) and of the hole (at the
  // principal point); label 0 is the bright background of connectedComponents.
  std::set<int> excluded;
  for (int x = 0; x < labels.cols; ++x) {
    excluded.insert(labels.at<int>(0, x));
    excluded.insert(labels.at<int>(labels.rows - 1, x));
  }
  for (int y = 0; y < labels.rows; ++y) {
    excluded.insert(labels.at<int>(y, 0));
    excluded.insert(labels.at<int>(y, labels.cols - 1));
  }
  const int cx = static_cast<int>(std::lround(centre_px.x()));
  const int cy = static_cast<int>(std::lround(centre_px.y()));
  if (cx >= 0 && cy >= 0 && cx < labels.cols && cy < labels.rows) {
    excluded.insert(labels.at<int>(cy, cx));
  }
  excluded.erase(0);
  cv::Mat mask(grey.size(), CV_8U, cv::Scalar(255));
  for (int y = 0; y < labels.rows; ++y) {
    const int* row = labels.ptr<int>(y);
    std::uint8_t* out = mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < labels.cols; ++x) {
      if (excluded.count(row[x])) out[x] = 0;
    }
  }
  return mask;
}

cv::Mat DarkRowEndsMask(const cv::Mat& grey, const cv::Mat& valid, double dark_level) {
  const cv::Mat dark = DarkPixels(grey, dark_level);
  cv::Mat mask = valid.empty() ? cv::Mat(grey.size(), CV_8U, cv::Scalar(255)) : valid.clone();
  const auto outside = [&](int r, int c) {
    return !mask.at<std::uint8_t>(r, c) || dark.at<std::uint8_t>(r, c);
  };
  for (int r = 0; r < mask.rows; ++r) {
    std::uint8_t* out = mask.ptr<std::uint8_t>(r);
    int first = 0;
    while (first < mask.cols && outside(r, first)) ++first;
    int last = mask.cols - 1;
    while (last >= first && outside(r, last)) --last;
    for (int c = 0; c < first; ++c) out[c] = 0;
    for (int c = last + 1; c < mask.cols; ++c) out[c] = 0;
  }
  return mask;
}

}  // namespace

void MirrorMaskOptions::Check() const {
  OMNIRIG_CHECK_IN(dark_level, '[', 0, 255, ')');
  OMNIRIG_CHECK_IN(margin_px, '[', 0, 200, ']');
}

Eigen::Vector2d PrincipalPoint(const CameraModel& camera) {
  return Eigen::Vector2d(camera.intrinsics.u0(), camera.intrinsics.v0());
}

cv::Mat MirrorMask(const cv::Mat& image, const Eigen::Vector2d& centre_px,
                   const MirrorMaskOptions& options, const cv::Mat& valid) {
  options.Check();
  OMNIRIG_CHECK(!image.empty(), "empty image");
  OMNIRIG_CHECK(valid.empty() || (valid.type() == CV_8U && valid.size() == image.size()),
                "the valid mask must be CV_8U of the image's size");
  const cv::Mat grey = ToGreyscale8(image);
  using Shape = MirrorMaskOptions::Shape;
  if (options.shape == Shape::kAnnulus) {
    return AnnulusMask(grey.size(), EstimateMirrorAnnulus(grey, centre_px, options.dark_level),
                       options.margin_px);
  }
  cv::Mat mask = options.shape == Shape::kDarkRegions
                     ? DarkRegionsMask(grey, centre_px, options.dark_level)
                     : DarkRowEndsMask(grey, valid, options.dark_level);
  const int margin = static_cast<int>(std::lround(options.margin_px));
  if (margin > 0) {
    const int k = 2 * margin + 1;
    const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(k, k));
    if (options.shape == Shape::kDarkRowEnds) {
      cv::erode(mask, mask, kernel, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
    } else {
      // A mirror cut by the image's edge keeps its pixels up to the edge.
      cv::erode(mask, mask, kernel);
    }
  }
  return mask;
}

MirrorAnnulus EstimateMirrorAnnulus(const cv::Mat& image, const Eigen::Vector2d& centre_px,
                                    double dark_level) {
  const cv::Mat grey = ToGreyscale8(image);
  MirrorAnnulus annulus;
  annulus.centre_px = centre_px;
  const double max_radius = std::hypot(std::max(centre_px.x(), grey.cols - centre_px.x()),
                                       std::max(centre_px.y(), grey.rows - centre_px.y()));
  const int num_bins = static_cast<int>(max_radius) + 2;
  std::vector<int> dark(num_bins, 0), total(num_bins, 0);
  for (int v = 0; v < grey.rows; v += 2) {  // every other row and column is plenty
    const std::uint8_t* row = grey.ptr<std::uint8_t>(v);
    for (int u = 0; u < grey.cols; u += 2) {
      const int bin = static_cast<int>(std::hypot(u - centre_px.x(), v - centre_px.y()));
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

}  // namespace omnirig
