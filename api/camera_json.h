#pragma once
// JSON forms of cameras, poses and rigs, shared by every job type's result.
//
//   camera: {"model": "unified", "image_size": [w, h],
//            "intrinsics": {"xi", "gamma_u", "gamma_v", "u0", "v0", "alpha", "k1".."k5"}}
//   pose:   {"rotation_wxyz": [w, x, y, z], "translation_m": [x, y, z]}
//   rig:    {"cam0_from_cam1": pose, "cameras": {"cam0": camera, "cam1": camera}, ...}

#include <array>
#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "engine/calib/calibrate.h"
#include "engine/geometry/camera_model.h"

namespace omnirig::api {

// {NAME: value} over UnifiedIntrinsics::kNames: the intrinsics, or their standard deviations.
nlohmann::json IntrinsicsToJson(const std::array<double, UnifiedIntrinsics::kNumParams>& values);
nlohmann::json CameraToJson(const CameraModel& camera);
// Throws InvalidArgument naming the missing or mistyped key.
CameraModel CameraFromJson(const nlohmann::json& json);

nlohmann::json PoseToJson(const Rigid3d& pose);
Rigid3d PoseFromJson(const nlohmann::json& json);

// Reads cam0_from_cam1 and cameras.cam0/cam1 of a relative_pose result.
StereoRig RigFromJson(const nlohmann::json& json);
// RigFromJson of job `job_id`'s result read by `load_result`; the error names the job.
StereoRig LoadRig(const std::function<nlohmann::json(const std::string&)>& load_result,
                  const std::string& job_id);
// params.rig of a job that needs a stereo rig: the id of a succeeded relative_pose job. A request
// without one is told which job type makes a rig.
std::string RigJobField(const nlohmann::json& params);
// Writes cam0_from_cam1, baseline_m and cameras; callers add the rest of their result.
nlohmann::json RigToJson(const StereoRig& rig);

// Fixes (fix) or frees each intrinsic a list of names gives (UnifiedIntrinsics::kNames, or the
// calibration's groups "skew", "tangential", "principal_point", "gamma"), the rest as it was.
// `field` names the JSON field in error messages (e.g. "options.fix").
void SetFixedFromJson(const nlohmann::json& names, const std::string& field, bool fix,
                      CalibrationOptions* options);
// A list of intrinsic names (UnifiedIntrinsics::kNames, or the calibration's groups "skew",
// "tangential", "principal_point", "gamma") as a fixed set, nothing else fixed. `field` names
// the JSON field in error messages (e.g. "params.fixed_intrinsics").
std::array<bool, UnifiedIntrinsics::kNumParams> FixedIntrinsicsFromJson(const nlohmann::json& names,
                                                                        const std::string& field);

}  // namespace omnirig::api
