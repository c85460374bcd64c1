#pragma once
// Image conversions every front end shares.

#include <string_view>

#include <opencv2/core.hpp>

namespace omnirig {

// An 8-bit single-channel view of `image`: BGR and BGRA are converted, deeper images (16-bit,
// float) are stretched to 0..255. Shared by the board detector, the SVP rim search and the
// feature detectors.
cv::Mat ToGreyscale8(const cv::Mat& image);

// An encoded image (PNG, JPEG, BMP, PGM/PPM bytes) decoded to 8-bit BGR; empty when the bytes
// are no image OpenCV decodes.
cv::Mat DecodeImageBgr(std::string_view bytes);

// Throws InvalidArgument unless `image` is 8-bit grey or BGR: what SLAM and dense stereo take
// (they read colours as BGR bytes).
void CheckGreyOrBgr8(const cv::Mat& image);

}  // namespace omnirig
