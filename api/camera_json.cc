#include "api/camera_json.h"

#include <string>

#include "api/json_fields.h"
#include "engine/util/check.h"

namespace omnirig::api {
nlohmann::json IntrinsicsToJson(const std::array<double, UnifiedIntrinsics::kNumParams>& values) {
  nlohmann::json json = nlohmann::json::object();
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    json[UnifiedIntrinsics::kNames[i]] = values[i];
  }
  return json;
}

namespace {

UnifiedIntrinsics IntrinsicsFromJson(const nlohmann::json& json) {
  UnifiedIntrinsics intrinsics;
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    const std::string name = UnifiedIntrinsics::kNames[i];
    // k5 and alpha are optional on input (formats without them mean zero).
    if ((name == "k5" || name == "alpha") && json.is_object() && !json.contains(name)) {
      intrinsics.params[i] = 0.0;
      continue;
    }
    intrinsics.params[i] = NumberField(json, "", name);
  }
  intrinsics.Check();
  return intrinsics;
}

}  // namespace

nlohmann::json CameraToJson(const CameraModel& camera) {
  return {{"model", "unified"},
          {"image_size", {camera.width, camera.height}},
          {"intrinsics", IntrinsicsToJson(camera.intrinsics.params)}};
}

CameraModel CameraFromJson(const nlohmann::json& json) {
  const nlohmann::json& model = Field(json, "", "model");
  OMNIRIG_CHECK(model.is_string() && model.get<std::string>() == "unified",
                "field 'model' must be \"unified\"");
  CameraModel camera;
  const Eigen::Vector2d size = NumberVector<2>(Field(json, "", "image_size"), "image_size");
  camera.width = static_cast<int>(size[0]);
  camera.height = static_cast<int>(size[1]);
  OMNIRIG_CHECK(camera.width > 0 && camera.height > 0 && camera.width == size[0] &&
                    camera.height == size[1],
                "field 'image_size' must hold two positive integers");
  camera.intrinsics = IntrinsicsFromJson(Field(json, "", "intrinsics"));
  return camera;
}

nlohmann::json PoseToJson(const Rigid3d& pose) {
  const auto wxyz = pose.ToWxyz();
  return {{"rotation_wxyz", {wxyz[0], wxyz[1], wxyz[2], wxyz[3]}},
          {"translation_m", {pose.translation.x(), pose.translation.y(), pose.translation.z()}}};
}

Rigid3d PoseFromJson(const nlohmann::json& json) {
  const Eigen::Vector4d wxyz = NumberVector<4>(Field(json, "", "rotation_wxyz"), "rotation_wxyz");
  const Eigen::Vector3d t = NumberVector<3>(Field(json, "", "translation_m"), "translation_m");
  OMNIRIG_CHECK(wxyz.squaredNorm() > 1e-12, "field 'rotation_wxyz' must be a non-zero quaternion");
  return Rigid3d(Rigid3d::FromWxyz({wxyz[0], wxyz[1], wxyz[2], wxyz[3]}), t);
}

StereoRig RigFromJson(const nlohmann::json& json) {
  StereoRig rig;
  rig.cam0_from_cam1 = PoseFromJson(Field(json, "", "cam0_from_cam1"));
  const nlohmann::json& cameras = Field(json, "", "cameras");
  rig.cam0 = CameraFromJson(Field(cameras, "cameras", "cam0"));
  rig.cam1 = CameraFromJson(Field(cameras, "cameras", "cam1"));
  return rig;
}

StereoRig LoadRig(const std::function<nlohmann::json(const std::string&)>& load_result,
                  const std::string& job_id) {
  OMNIRIG_CHECK(static_cast<bool>(load_result),
                "this job cannot read other jobs' results (no result loader)");
  const nlohmann::json result = load_result(job_id);
  return WithErrorPrefix("job " + job_id + " holds no stereo rig (is it a relative_pose job?): ",
                         [&] { return RigFromJson(result); });
}

std::string RigJobField(const nlohmann::json& params) {
  OMNIRIG_CHECK(params.is_object() && params.contains("rig"),
                "missing field 'params.rig': the id of a succeeded relative_pose job, which makes "
                "the stereo rig (submit one on board pairs seen by both cameras first)");
  return JobIdField(params, "params", "rig");
}

nlohmann::json RigToJson(const StereoRig& rig) {
  return {{"cam0_from_cam1", PoseToJson(rig.cam0_from_cam1)},
          {"baseline_m", rig.cam0_from_cam1.translation.norm()},
          {"cameras", {{"cam0", CameraToJson(rig.cam0)}, {"cam1", CameraToJson(rig.cam1)}}}};
}

void SetFixedFromJson(const nlohmann::json& names, const std::string& field, bool fix,
                      CalibrationOptions* options) {
  OMNIRIG_CHECK(names.is_array(), "field '" << field << "' must be an array of names");
  for (const nlohmann::json& name : names) {
    OMNIRIG_CHECK(name.is_string(), "field '" << field << "' must hold names, got " << name.dump());
    WithErrorPrefix("field '" + field + "': ",
                    [&] { options->SetFixed(name.get<std::string>(), fix); });
  }
}

std::array<bool, UnifiedIntrinsics::kNumParams> FixedIntrinsicsFromJson(const nlohmann::json& names,
                                                                        const std::string& field) {
  CalibrationOptions calibration;
  calibration.fixed.fill(false);
  SetFixedFromJson(names, field, true, &calibration);
  return calibration.fixed;
}

}  // namespace omnirig::api
