#include "engine/dense/range_io.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/util/check.h"

namespace omnirig::dense {

void WriteRangeTiff(const std::filesystem::path& path, const cv::Mat& range_m) {
  OMNIRIG_CHECK(range_m.type() == CV_32FC1, "a range panorama is single-channel 32-bit float");
  bool written = false;
  try {
    written = cv::imwrite(path.string(), range_m);
  } catch (const cv::Exception&) {
    written = false;
  }
  if (!written) throw std::runtime_error("cannot write " + path.string());
}

cv::Mat RangePreview(const cv::Mat& range_m) {
  OMNIRIG_CHECK(range_m.type() == CV_32FC1, "a range panorama is single-channel 32-bit float");
  // The percentiles from every 8th known cell (a panorama holds about a million): the log is
  // monotonic, so they are taken on the ranges and their logs used.
  std::vector<float> known;
  int seen = 0;
  for (int r = 0; r < range_m.rows; ++r) {
    const float* row = range_m.ptr<float>(r);
    for (int c = 0; c < range_m.cols; ++c) {
      if (row[c] > 0.f && seen++ % 8 == 0) known.push_back(row[c]);
    }
  }
  cv::Mat preview(range_m.size(), CV_8UC3, cv::Scalar::all(0));
  if (known.empty()) return preview;
  const auto percentile = [&](double q) {
    auto it = known.begin() + static_cast<std::ptrdiff_t>(q * (known.size() - 1));
    std::nth_element(known.begin(), it, known.end());
    return std::log(*it);
  };
  const float lo = percentile(0.02), hi = std::max(percentile(0.98), lo + 1e-3f);
  // Serial on purpose: the job writes previews on a thread of its own while it matches the next
  // pair, and OpenCV runs a parallel_for_ that starts while another one runs (process-wide)
  // serially, so a parallel loop here could leave the matching on one core.
  static const cv::Mat turbo = [] {
    cv::Mat levels(1, 256, CV_8U), colours;
    for (int i = 0; i < 256; ++i) levels.at<uint8_t>(0, i) = static_cast<uint8_t>(i);
    cv::applyColorMap(levels, colours, cv::COLORMAP_TURBO);
    return colours;
  }();
  for (int r = 0; r < range_m.rows; ++r) {
    const float* row = range_m.ptr<float>(r);
    cv::Vec3b* out = preview.ptr<cv::Vec3b>(r);
    for (int c = 0; c < range_m.cols; ++c) {
      if (!(row[c] > 0.f)) continue;  // unknown stays black
      const float t = std::clamp((std::log(row[c]) - lo) / (hi - lo), 0.f, 1.f);
      const int level = static_cast<int>(std::lround(255.f * (1.f - t)));  // near = high = red
      out[c] = turbo.at<cv::Vec3b>(0, level);
    }
  }
  return preview;
}

void WriteRangePng(const std::filesystem::path& path, const cv::Mat& range_m) {
  bool written = false;
  try {
    written = cv::imwrite(path.string(), RangePreview(range_m));
  } catch (const cv::Exception&) {
    written = false;
  }
  if (!written) throw std::runtime_error("cannot write " + path.string());
}

}  // namespace omnirig::dense
