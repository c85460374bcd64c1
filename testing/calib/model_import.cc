#include "testing/calib/model_import.h"

#include <cmath>
#include <sstream>

#include <opencv2/core.hpp>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// Reads a numeric node that OpenCV may store as a number or as a 1x1 matrix.
double ReadScalar(const cv::FileNode& node, const std::string& name) {
  OMNIRIG_CHECK(!node.empty(), "opencv omnidir: missing node '" << name << "'");
  if (node.isReal() || node.isInt()) return static_cast<double>(node);
  cv::Mat m;
  node >> m;
  OMNIRIG_CHECK(m.total() == 1, "opencv omnidir: node '" << name << "' must be a scalar");
  m.convertTo(m, CV_64F);
  return m.at<double>(0);
}

cv::Mat ReadMatrix(const cv::FileStorage& fs, const std::vector<std::string>& names, int total) {
  for (const std::string& name : names) {
    const cv::FileNode node = fs[name];
    if (node.empty()) continue;
    cv::Mat m;
    node >> m;
    OMNIRIG_CHECK(static_cast<int>(m.total()) == total,
                  "opencv omnidir: node '" << name << "' must have " << total << " elements");
    m.convertTo(m, CV_64F);
    return m.reshape(1, 1);
  }
  OMNIRIG_CHECK(false, "opencv omnidir: missing node '" << names.front() << "'");
}

}  // namespace

CameraModel FromOpenCvOmnidir(const std::string& text) {
  cv::FileStorage fs;
  try {
    fs.open(text, cv::FileStorage::READ | cv::FileStorage::MEMORY);
  } catch (const cv::Exception& e) {
    OMNIRIG_CHECK(false, "opencv omnidir: cannot parse the document: " << e.what());
  }
  OMNIRIG_CHECK(fs.isOpened(), "opencv omnidir: cannot parse the document");
  const cv::Mat k = ReadMatrix(fs, {"camera_matrix", "K"}, 9);
  const cv::Mat d = ReadMatrix(fs, {"distortion_coefficients", "D"}, 4);
  CameraModel camera;
  UnifiedIntrinsics& in = camera.intrinsics;
  in.xi() = ReadScalar(fs["xi"], "xi");
  in.gamma_u() = k.at<double>(0);
  in.alpha() = k.at<double>(1) / k.at<double>(0);
  in.u0() = k.at<double>(2);
  in.gamma_v() = k.at<double>(4);
  in.v0() = k.at<double>(5);
  for (int i = 0; i < 4; ++i) in.k(i + 1) = d.at<double>(i);
  in.k(5) = 0.0;
  if (!fs["image_width"].empty()) camera.width = static_cast<int>(fs["image_width"]);
  if (!fs["image_height"].empty()) camera.height = static_cast<int>(fs["image_height"]);
  in.Check();
  return camera;
}

std::vector<CalibrationView> ReadOpenCvCornerViews(const std::string& path, const BoardSpec& board,
                                                   double object_points_to_m) {
  board.Check();
  OMNIRIG_CHECK(object_points_to_m > 0.0, "corner file: object_points_to_m must be positive");
  cv::FileStorage fs;
  try {
    fs.open(path, cv::FileStorage::READ);
  } catch (const cv::Exception& e) {
    OMNIRIG_CHECK(false,
                  "corner file '" << path << "' is not a FileStorage document: " << e.what());
  }
  OMNIRIG_CHECK(fs.isOpened(), "cannot read the corner file '" << path << "'");
  std::vector<cv::Mat> object_points, image_points;
  try {
    fs["objectPoints"] >> object_points;
    fs["imagePoints"] >> image_points;
  } catch (const cv::Exception& e) {
    OMNIRIG_CHECK(false, "corner file '" << path << "': malformed points: " << e.what());
  }
  OMNIRIG_CHECK(!object_points.empty() && object_points.size() == image_points.size(),
                "corner file '" << path << "' needs as many objectPoints as imagePoints views ("
                                << object_points.size() << " vs " << image_points.size() << ")");
  std::vector<CalibrationView> views;
  for (size_t v = 0; v < object_points.size(); ++v) {
    OMNIRIG_CHECK(object_points[v].channels() == 3 && image_points[v].channels() == 2 &&
                      object_points[v].total() == image_points[v].total(),
                  "corner file '" << path << "', view " << v
                                  << ": expected matching 3-channel object and 2-channel image "
                                     "points");
    cv::Mat object, image;
    object_points[v].convertTo(object, CV_64F);  // stored as 3d or 3f
    image_points[v].convertTo(image, CV_64F);    // stored as 2d or 2f
    CalibrationView view;
    view.name = "view" + std::to_string(v);
    view.detection.found = true;
    view.detection.method = "file";
    for (int i = 0; i < static_cast<int>(object.total()); ++i) {
      const cv::Vec3d p = object.at<cv::Vec3d>(i) * object_points_to_m;
      const cv::Vec2d q = image.at<cv::Vec2d>(i);
      const double col = p[0] / board.square_size_m, row = p[1] / board.square_size_m;
      const int c = static_cast<int>(std::lround(col)), r = static_cast<int>(std::lround(row));
      OMNIRIG_CHECK(std::abs(col - c) < 0.01 && std::abs(row - r) < 0.01 &&
                        std::abs(p[2]) < 0.01 * board.square_size_m && c >= 0 && c < board.cols &&
                        r >= 0 && r < board.rows,
                    "corner file '" << path << "', view " << v << ", point " << i
                                    << " is not on the " << board.Describe() << "'s grid");
      view.detection.corner_ids.push_back(r * board.cols + c);
      view.detection.corners_px.emplace_back(q[0], q[1]);
    }
    views.push_back(std::move(view));
  }
  return views;
}

}  // namespace omnirig
