#include "testing/calib/model_import.h"

#include <cmath>
#include <map>
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

// The bracketed numbers after "key:" in a YAML flow sequence, e.g. "intrinsics: [1, 2, 3]".
std::vector<double> ParseFlowSequence(const std::string& value, const std::string& key) {
  const size_t open = value.find('['), close = value.find(']');
  OMNIRIG_CHECK(open != std::string::npos && close != std::string::npos && open < close,
                "kalibr: '" << key << "' must be a [..] list");
  std::string inner = value.substr(open + 1, close - open - 1);
  for (char& c : inner) {
    if (c == ',') c = ' ';
  }
  std::istringstream is(inner);
  std::vector<double> numbers;
  double x;
  while (is >> x) numbers.push_back(x);
  OMNIRIG_CHECK(is.eof(), "kalibr: '" << key << "' holds a non-number");
  return numbers;
}

// key -> value text of the camera block `camera_name` (indented lines after "camera_name:").
std::map<std::string, std::string> KalibrCameraBlock(const std::string& text,
                                                     const std::string& camera_name) {
  std::istringstream is(text);
  std::string line;
  bool inside = false;
  std::map<std::string, std::string> block;
  while (std::getline(is, line)) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line = line.substr(0, hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const bool indented = line[0] == ' ' || line[0] == '\t';
    if (!indented) {
      inside = line.substr(0, line.find(':')) == camera_name;
      continue;
    }
    const size_t colon = line.find(':');
    if (!inside || colon == std::string::npos) continue;
    const size_t start = line.find_first_not_of(" \t");
    block[line.substr(start, colon - start)] = line.substr(colon + 1);
  }
  OMNIRIG_CHECK(!block.empty(), "kalibr: no camera '" << camera_name << "'");
  return block;
}

std::string Trimmed(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r\"'");
  const size_t b = s.find_last_not_of(" \t\r\"'");
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
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

StereoRig FromKalibrCamchain(const std::string& text) {
  StereoRig rig;
  rig.cam0 = FromKalibrOmniRadtan(text, "cam0");
  rig.cam1 = FromKalibrOmniRadtan(text, "cam1");
  const std::map<std::string, std::string> block = KalibrCameraBlock(text, "cam1");
  const auto it = block.find("T_cn_cnm1");
  OMNIRIG_CHECK(it != block.end(), "kalibr: camera 'cam1' has no 'T_cn_cnm1'");
  std::string numbers = it->second;
  for (char& c : numbers) {
    if (c == '[' || c == ']' || c == ',') c = ' ';
  }
  std::istringstream is(numbers);
  std::vector<double> values;
  double x;
  while (is >> x) values.push_back(x);
  OMNIRIG_CHECK(is.eof() && values.size() == 16,
                "kalibr: T_cn_cnm1 must be a 4x4 matrix in one [[..], ..] list");
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rotation(r, c) = values[4 * r + c];
    translation[r] = values[4 * r + 3];
  }
  OMNIRIG_CHECK((rotation * rotation.transpose() - Eigen::Matrix3d::Identity()).norm() < 1e-6 &&
                    rotation.determinant() > 0.0,
                "kalibr: T_cn_cnm1's rotation is not a rotation");
  rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond(rotation), translation).Inverse();
  return rig;
}

CameraModel FromKalibrOmniRadtan(const std::string& text, const std::string& camera_name) {
  const std::map<std::string, std::string> block = KalibrCameraBlock(text, camera_name);
  auto get = [&](const std::string& key) -> const std::string& {
    const auto it = block.find(key);
    OMNIRIG_CHECK(it != block.end(),
                  "kalibr: camera '" << camera_name << "' has no '" << key << "'");
    return it->second;
  };
  OMNIRIG_CHECK(Trimmed(get("camera_model")) == "omni",
                "kalibr: camera_model must be omni, got '" << Trimmed(get("camera_model")) << "'");
  OMNIRIG_CHECK(
      Trimmed(get("distortion_model")) == "radtan",
      "kalibr: distortion_model must be radtan, got '" << Trimmed(get("distortion_model")) << "'");
  const std::vector<double> intrinsics = ParseFlowSequence(get("intrinsics"), "intrinsics");
  const std::vector<double> distortion =
      ParseFlowSequence(get("distortion_coeffs"), "distortion_coeffs");
  OMNIRIG_CHECK(intrinsics.size() == 5, "kalibr: intrinsics must hold 5 numbers");
  OMNIRIG_CHECK(distortion.size() == 4, "kalibr: distortion_coeffs must hold 4 numbers");
  CameraModel camera;
  camera.intrinsics.params = {intrinsics[0],
                              intrinsics[1],
                              intrinsics[2],
                              intrinsics[3],
                              intrinsics[4],
                              0.0,
                              distortion[0],
                              distortion[1],
                              distortion[2],
                              distortion[3],
                              0.0};
  if (block.count("resolution")) {
    const std::vector<double> resolution = ParseFlowSequence(get("resolution"), "resolution");
    OMNIRIG_CHECK(resolution.size() == 2, "kalibr: resolution must hold 2 numbers");
    camera.width = static_cast<int>(resolution[0]);
    camera.height = static_cast<int>(resolution[1]);
  }
  camera.intrinsics.Check();
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
