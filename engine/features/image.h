#pragma once
// Image conversions every front end shares.

#include <filesystem>
#include <functional>
#include <string>
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

// Where a pipeline reads its images: by name, as cv::imread reads a file with `imread_flags`
// (cv::IMREAD_COLOR: 8-bit BGR, cv::IMREAD_GRAYSCALE: 8-bit grey); an empty Mat when there is
// no such image or it cannot be decoded. The images of a folder (FolderImageReader) or frames of
// a recording (the api's recording jobs). Called from several threads at once.
using ImageReader = std::function<cv::Mat(const std::string& name, int imread_flags)>;

// The files of `dir`, by their names relative to it (cv::imread).
ImageReader FolderImageReader(const std::filesystem::path& dir);

// Throws InvalidArgument unless `image` is 8-bit grey or BGR: what SLAM and dense stereo take
// (they read colours as BGR bytes).
void CheckGreyOrBgr8(const cv::Mat& image);

}  // namespace omnirig
