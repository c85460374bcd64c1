#include "engine/features/image.h"

#include <opencv2/imgproc.hpp>

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

}  // namespace omnirig
