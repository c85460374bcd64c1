#pragma once
// Range panorama files: NAME_range.tiff (32-bit float metres, 0 where unknown; read by OpenCV,
// GDAL, ImageJ, numpy via tifffile) and NAME_range.png (a coloured preview for people).

#include <filesystem>

#include <opencv2/core.hpp>

namespace omnirig::dense {

// Writes `range_m` (CV_32F) as a single-channel 32-bit float TIFF. Throws std::runtime_error
// when the file cannot be written, InvalidArgument for another image type.
void WriteRangeTiff(const std::filesystem::path& path, const cv::Mat& range_m);

// A colour preview of `range_m` (CV_32F, BGR): 255 levels of the turbo colour map over log range
// between the 2nd and 98th percentiles of the known ranges (near red, far blue), black where
// unknown.
cv::Mat RangePreview(const cv::Mat& range_m);

// Writes RangePreview(range_m) as an 8-bit palette PNG (a third of an RGB one's pixels to
// compress). Throws std::runtime_error when it cannot be written.
void WriteRangePng(const std::filesystem::path& path, const cv::Mat& range_m);

}  // namespace omnirig::dense
