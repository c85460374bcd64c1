#pragma once
// Export of the unified model in other tools' formats:
//   OpenCV omnidir FileStorage (YAML or XML): K (camera_matrix), D = (k1, k2, p1, p2)
//     (distortion_coefficients) and xi, as cv::omnidir::calibrate's sample writes them.
//     K(0, 1) = s = gamma_u * alpha; (p1, p2) = the paper's (k3, k4).
//   Kalibr camchain YAML, camera_model "omni" with distortion_model "radtan":
//     intrinsics [xi, fu, fv, pu, pv], distortion_coeffs [k1, k2, r1, r2], resolution [w, h].
// Neither format has k5; Kalibr has no skew. Exports return a warning for each parameter they
// drop (and write it into the file as a comment); CalibrationOptions fixes k5 and skew at zero
// by default so that exports are exact. Kalibr camchains are also read (a rig's cameras given as
// the camchain a user calibrated with Kalibr); the OpenCV reader, for round-trip tests, is
// testing/calib/model_import.h.

#include <array>
#include <string>
#include <vector>

#include "engine/geometry/camera_model.h"

namespace omnirig {

// Warnings for the parameters a format cannot hold ("k5 = 0.01 is not representable ...").
std::vector<std::string> ExportWarnings(const CameraModel& camera, bool format_has_skew);

// The FileStorage document as text (YAML). `warnings` receives what the format drops.
std::string ToOpenCvOmnidir(const CameraModel& camera, std::vector<std::string>* warnings);

// `rostopic`: the image topic the camera's frames came from, written as Kalibr writes it (Kalibr
// reads it to find the camera's images in a bag); none when empty.
std::string ToKalibrOmniRadtan(const CameraModel& camera, std::vector<std::string>* warnings,
                               const std::string& camera_name = "cam0",
                               const std::string& rostopic = "");

// A Kalibr camchain YAML of a stereo rig: cam0 and cam1 as ToKalibrOmniRadtan writes them,
// cam1 with T_cn_cnm1 = cam1_from_cam0 (maps points in cam0's frame into cam1's; translation in
// metres) as a 4x4 matrix. `warnings` receives what the format drops, per camera.
// `rostopics`: each camera's image topic (see ToKalibrOmniRadtan).
std::string ToKalibrCamchain(const StereoRig& rig, std::vector<std::string>* warnings,
                             const std::array<std::string, 2>& rostopics = {});

// Parses the camera `camera_name` of a Kalibr camchain YAML. Throws InvalidArgument for another
// camera or distortion model or missing keys.
CameraModel FromKalibrOmniRadtan(const std::string& text, const std::string& camera_name = "cam0");

// Parses a two-camera Kalibr camchain (cam0, cam1 with T_cn_cnm1; omni-radtan). Throws
// InvalidArgument for missing keys or a T_cn_cnm1 that is not a rigid transform.
StereoRig FromKalibrCamchain(const std::string& text);

}  // namespace omnirig
