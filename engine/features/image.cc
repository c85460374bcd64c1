#include "engine/features/image.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/util/check.h"

namespace omnirig {

cv::Mat ToGreyscale8(const cv::Mat& image) {
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else if (image.channels() == 4) {
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  } else {
    grey = image;
  }
  if (grey.depth() != CV_8U) {
    cv::Mat converted;
    cv::normalize(grey, converted, 0, 255, cv::NORM_MINMAX, CV_8U);
    grey = converted;
  }
  return grey;
}

void CheckGreyOrBgr8(const cv::Mat& image) {
  OMNIRIG_CHECK(
      !image.empty() && image.depth() == CV_8U && (image.channels() == 1 || image.channels() == 3),
      "images must be 8-bit grey or BGR");
}

cv::Mat DecodeImageBgr(std::string_view bytes) {
  if (bytes.empty()) return cv::Mat();
  const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8U,
                       const_cast<char*>(bytes.data()));
  try {
    return cv::imdecode(buffer, cv::IMREAD_COLOR);
  } catch (const cv::Exception&) {
    return cv::Mat();  // bytes OpenCV's decoders refuse by throwing: no image either
  }
}

ImageReader FolderImageReader(const std::filesystem::path& dir) {
  return [dir](const std::string& name, int imread_flags) {
    return cv::imread((dir / name).string(), imread_flags);
  };
}

}  // namespace omnirig
