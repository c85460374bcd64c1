#include "engine/calib/model_io.h"

#include <iomanip>
#include <sstream>

#include <opencv2/core.hpp>

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
  os << KalibrBlockWithoutComments(cam0);
  std::string cam1_block = KalibrBlockWithoutComments(cam1);
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

}  // namespace omnirig
