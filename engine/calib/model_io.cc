#include "engine/calib/model_io.h"

#include <cmath>
#include <iomanip>
#include <map>
#include <sstream>

#include <opencv2/core.hpp>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// The camera block of ToKalibrOmniRadtan's text without its comment lines (the warnings are
// collected by the caller).
std::string KalibrBlockWithoutComments(const std::string& text) {
  std::istringstream is(text);
  std::ostringstream os;
  std::string line;
  while (std::getline(is, line)) {
    if (!line.empty() && line[0] != '#') os << line << "\n";
  }
  return os.str();
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
// A key whose value is written in block style on the lines after it, as Kalibr writes its 4x4
// matrices ("  T_cn_cnm1:" then "  - [r00, r01, r02, t0]" per row), gets those rows.
std::map<std::string, std::string> KalibrCameraBlock(const std::string& text,
                                                     const std::string& camera_name) {
  std::istringstream is(text);
  std::string line;
  bool inside = false;
  std::map<std::string, std::string> block;
  std::string* last = nullptr;
  while (std::getline(is, line)) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line = line.substr(0, hash);
    const size_t start = line.find_first_not_of(" \t\r");
    if (start == std::string::npos) continue;
    if (start == 0) {
      inside = line.substr(0, line.find(':')) == camera_name;
      last = nullptr;
      continue;
    }
    if (!inside) continue;
    if (line[start] == '-') {
      if (last) *last += " " + line.substr(start + 1);
      continue;
    }
    const size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    last = &block[line.substr(start, colon - start)];
    *last = line.substr(colon + 1);
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

std::vector<std::string> ExportWarnings(const CameraModel& camera, bool format_has_skew) {
  std::vector<std::string> warnings;
  std::ostringstream os;
  os << std::setprecision(6);
  if (camera.intrinsics.k(5) != 0.0) {
    os << "k5 = " << camera.intrinsics.k(5)
       << " is not representable and was dropped; calibrate with k5 fixed at 0 for an exact "
          "export";
    warnings.push_back(os.str());
    os.str("");
  }
  if (!format_has_skew && camera.intrinsics.alpha() != 0.0) {
    os << "skew alpha = " << camera.intrinsics.alpha()
       << " is not representable and was dropped; calibrate with skew fixed at 0 for an exact "
          "export";
    warnings.push_back(os.str());
  }
  return warnings;
}

std::string ToOpenCvOmnidir(const CameraModel& camera, std::vector<std::string>* warnings) {
  const UnifiedIntrinsics& in = camera.intrinsics;
  const std::vector<std::string> dropped = ExportWarnings(camera, /*format_has_skew=*/true);
  if (warnings) *warnings = dropped;
  cv::FileStorage fs(".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
  fs.writeComment("Mei unified model exported by omnirig for cv::omnidir");
  for (const std::string& warning : dropped) fs.writeComment("WARNING: " + warning);
  fs << "image_width" << camera.width << "image_height" << camera.height;
  const cv::Matx33d k(in.gamma_u(), in.gamma_u() * in.alpha(), in.u0(), 0.0, in.gamma_v(), in.v0(),
                      0.0, 0.0, 1.0);
  fs << "camera_matrix" << cv::Mat(k);
  fs << "distortion_coefficients" << cv::Mat(cv::Matx14d(in.k(1), in.k(2), in.k(3), in.k(4)));
  fs << "xi" << in.xi();
  return fs.releaseAndGetString();
}

std::string ToKalibrOmniRadtan(const CameraModel& camera, std::vector<std::string>* warnings,
                               const std::string& camera_name, const std::string& rostopic) {
  const UnifiedIntrinsics& in = camera.intrinsics;
  const std::vector<std::string> dropped = ExportWarnings(camera, /*format_has_skew=*/false);
  if (warnings) *warnings = dropped;
  std::ostringstream os;
  os << std::setprecision(17);
  os << "# Mei unified model exported by omnirig for Kalibr (omni-radtan)\n";
  for (const std::string& warning : dropped) os << "# WARNING: " << warning << "\n";
  os << camera_name << ":\n"
     << "  camera_model: omni\n"
     << "  intrinsics: [" << in.xi() << ", " << in.gamma_u() << ", " << in.gamma_v() << ", "
     << in.u0() << ", " << in.v0() << "]\n"
     << "  distortion_model: radtan\n"
     << "  distortion_coeffs: [" << in.k(1) << ", " << in.k(2) << ", " << in.k(3) << ", " << in.k(4)
     << "]\n"
     << "  resolution: [" << camera.width << ", " << camera.height << "]\n";
  if (!rostopic.empty()) os << "  rostopic: " << rostopic << "\n";
  return os.str();
}

std::string ToKalibrCamchain(const StereoRig& rig, std::vector<std::string>* warnings,
                             const std::array<std::string, 2>& rostopics) {
  std::vector<std::string> dropped[2];
  const std::string cam0 = ToKalibrOmniRadtan(rig.cam0, &dropped[0], "cam0", rostopics[0]);
  const std::string cam1 = ToKalibrOmniRadtan(rig.cam1, &dropped[1], "cam1", rostopics[1]);
  std::vector<std::string> all;
  for (int c = 0; c < 2; ++c) {
    for (const std::string& warning : dropped[c]) {
      all.push_back("cam" + std::to_string(c) + ": " + warning);
    }
  }
  if (warnings) *warnings = all;
  const Eigen::Matrix<double, 3, 4> cam1_from_cam0 = rig.cam0_from_cam1.Inverse().ToMatrix3x4();
  std::ostringstream os;
  os << std::setprecision(17);
  os << "# Stereo rig exported by omnirig for Kalibr (omni-radtan camchain)\n";
  for (const std::string& warning : all) os << "# WARNING: " << warning << "\n";
  // Each camera lists the cameras it shares a view with, as Kalibr writes them.
  const auto with_overlap = [](std::string block, const char* other) {
    block.insert(block.find('\n') + 1, std::string("  cam_overlaps: [") + other + "]\n");
    return block;
  };
  os << with_overlap(KalibrBlockWithoutComments(cam0), "1");
  std::string cam1_block = with_overlap(KalibrBlockWithoutComments(cam1), "0");
  std::ostringstream transform;
  transform << std::setprecision(17) << "  T_cn_cnm1: [";
  for (int r = 0; r < 4; ++r) {
    transform << (r ? ", [" : "[");
    for (int c = 0; c < 4; ++c) {
      const double value = r < 3 ? cam1_from_cam0(r, c) : (c == 3 ? 1.0 : 0.0);
      transform << (c ? ", " : "") << value;
    }
    transform << "]";
  }
  transform << "]\n";
  const size_t header_end = cam1_block.find('\n') + 1;
  cam1_block.insert(header_end, transform.str());
  os << cam1_block;
  return os.str();
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
                "kalibr: T_cn_cnm1 must be a 4x4 matrix, as [[..], ..] or four \"- [..]\" rows");
  for (const double value : values) {
    OMNIRIG_CHECK(std::isfinite(value), "kalibr: T_cn_cnm1 holds a non-finite number");
  }
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
    for (const double size : resolution) {
      OMNIRIG_CHECK(size >= 1 && size <= 100000 && size == std::floor(size),
                    "kalibr: resolution must be two whole numbers of pixels");
    }
    camera.width = static_cast<int>(resolution[0]);
    camera.height = static_cast<int>(resolution[1]);
  }
  camera.intrinsics.Check();
  return camera;
}

}  // namespace omnirig
