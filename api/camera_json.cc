#include "api/camera_json.h"

#include <string>

#include "engine/calib/calibrate.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

const nlohmann::json& Member(const nlohmann::json& json, const std::string& key) {
  OMNIRIG_CHECK(json.is_object(), "expected a JSON object holding '" << key << "'");
  const auto it = json.find(key);
  OMNIRIG_CHECK(it != json.end(), "missing field '" << key << "'");
  return *it;
}

double Number(const nlohmann::json& json, const std::string& key) {
  const nlohmann::json& value = Member(json, key);
  OMNIRIG_CHECK(value.is_number(), "field '" << key << "' must be a number");
  return value.get<double>();
}

template <size_t N>
std::array<double, N> NumberArray(const nlohmann::json& json, const std::string& key) {
  const nlohmann::json& value = Member(json, key);
  OMNIRIG_CHECK(value.is_array() && value.size() == N,
                "field '" << key << "' must be an array of " << N << " numbers");
  std::array<double, N> out{};
  for (size_t i = 0; i < N; ++i) {
    OMNIRIG_CHECK(value[i].is_number(), "field '" << key << "' must hold numbers only");
    out[i] = value[i].get<double>();
  }
  return out;
}

}  // namespace

nlohmann::json IntrinsicsToJson(const UnifiedIntrinsics& intrinsics) {
  nlohmann::json json = nlohmann::json::object();
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    json[UnifiedIntrinsics::kNames[i]] = intrinsics.params[i];
  }
  return json;
}

UnifiedIntrinsics IntrinsicsFromJson(const nlohmann::json& json) {
  UnifiedIntrinsics intrinsics;
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    const std::string name = UnifiedIntrinsics::kNames[i];
    // k5 and alpha are optional on input (formats without them mean zero).
    if ((name == "k5" || name == "alpha") && json.is_object() && !json.contains(name)) {
      intrinsics.params[i] = 0.0;
      continue;
    }
    intrinsics.params[i] = Number(json, name);
  }
  intrinsics.Check();
  return intrinsics;
}

nlohmann::json CameraToJson(const CameraModel& camera) {
  return {{"model", "unified"},
          {"image_size", {camera.width, camera.height}},
          {"intrinsics", IntrinsicsToJson(camera.intrinsics)}};
}

CameraModel CameraFromJson(const nlohmann::json& json) {
  const nlohmann::json& model = Member(json, "model");
  OMNIRIG_CHECK(model.is_string() && model.get<std::string>() == "unified",
                "field 'model' must be \"unified\"");
  CameraModel camera;
  const auto size = NumberArray<2>(json, "image_size");
  camera.width = static_cast<int>(size[0]);
  camera.height = static_cast<int>(size[1]);
  OMNIRIG_CHECK(camera.width > 0 && camera.height > 0 && camera.width == size[0] &&
                    camera.height == size[1],
                "field 'image_size' must hold two positive integers");
  camera.intrinsics = IntrinsicsFromJson(Member(json, "intrinsics"));
  return camera;
}

nlohmann::json PoseToJson(const Rigid3d& pose) {
  const auto wxyz = pose.ToWxyz();
  return {{"rotation_wxyz", {wxyz[0], wxyz[1], wxyz[2], wxyz[3]}},
          {"translation_m", {pose.translation.x(), pose.translation.y(), pose.translation.z()}}};
}

Rigid3d PoseFromJson(const nlohmann::json& json) {
  const auto wxyz = NumberArray<4>(json, "rotation_wxyz");
  const auto t = NumberArray<3>(json, "translation_m");
  const double norm2 = wxyz[0] * wxyz[0] + wxyz[1] * wxyz[1] + wxyz[2] * wxyz[2] + wxyz[3] * wxyz[3];
  OMNIRIG_CHECK(norm2 > 1e-12, "field 'rotation_wxyz' must be a non-zero quaternion");
  return Rigid3d(Rigid3d::FromWxyz(wxyz), Eigen::Vector3d(t[0], t[1], t[2]));
}

StereoRig RigFromJson(const nlohmann::json& json) {
  StereoRig rig;
  rig.cam0_from_cam1 = PoseFromJson(Member(json, "cam0_from_cam1"));
  const nlohmann::json& cameras = Member(json, "cameras");
  rig.cam0 = CameraFromJson(Member(cameras, "cam0"));
  rig.cam1 = CameraFromJson(Member(cameras, "cam1"));
  return rig;
}

nlohmann::json RigToJson(const StereoRig& rig) {
  return {{"cam0_from_cam1", PoseToJson(rig.cam0_from_cam1)},
          {"baseline_m", rig.cam0_from_cam1.translation.norm()},
          {"cameras", {{"cam0", CameraToJson(rig.cam0)}, {"cam1", CameraToJson(rig.cam1)}}}};
}

std::array<bool, UnifiedIntrinsics::kNumParams> FixedIntrinsicsFromJson(const nlohmann::json& names,
                                                                        const std::string& field) {
  OMNIRIG_CHECK(names.is_array(), "field '" << field << "' must be an array of names");
  CalibrationOptions calibration;
  calibration.fixed.fill(false);
  for (const nlohmann::json& name : names) {
    OMNIRIG_CHECK(name.is_string(), "field '" << field << "' must hold names, got " << name.dump());
    try {
      calibration.SetFixed(name.get<std::string>(), true);
    } catch (const InvalidArgument& e) {
      throw InvalidArgument("field '" + field + "': " + e.what());
    }
  }
  return calibration.fixed;
}

}  // namespace omnirig::api
