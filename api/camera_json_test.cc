#include "api/camera_json.h"

#include <gtest/gtest.h>

namespace omnirig::api {
namespace {

TEST(CameraJson, RigRoundTrip) {
  StereoRig rig;
  rig.cam0.intrinsics.params = {0.9, 300, 301, 512, 384, 0.001, -0.1, 0.02, 0.001, -0.002, 0.003};
  rig.cam0.width = 1024;
  rig.cam0.height = 768;
  rig.cam1 = rig.cam0;
  rig.cam1.intrinsics.xi() = 1.1;
  rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond(0.99, 0.01, 0.02, 0.03), Eigen::Vector3d(0, 0, 0.1));
  const nlohmann::json json = RigToJson(rig);
  EXPECT_NEAR(json["baseline_m"].get<double>(), 0.1, 1e-12);
  EXPECT_EQ(json["cameras"]["cam0"]["intrinsics"]["gamma_v"].get<double>(), 301);
  const StereoRig back = RigFromJson(json);
  EXPECT_EQ(back.cam1.intrinsics.params, rig.cam1.intrinsics.params);
  EXPECT_EQ(back.cam0.width, 1024);
  EXPECT_LT(RotationDistanceRad(back.cam0_from_cam1.rotation, rig.cam0_from_cam1.rotation), 1e-12);
}

TEST(CameraJson, ErrorsNameTheField) {
  nlohmann::json camera = CameraToJson(CameraModel{UnifiedIntrinsics{}, 640, 480});
  camera["intrinsics"].erase("gamma_u");
  try {
    CameraFromJson(camera);
    FAIL() << "expected InvalidArgument";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("gamma_u"), std::string::npos);
  }
  camera = CameraToJson(CameraModel{UnifiedIntrinsics{}, 640, 480});
  camera["image_size"] = {640, "x"};
  EXPECT_THROW(CameraFromJson(camera), InvalidArgument);
  camera = CameraToJson(CameraModel{UnifiedIntrinsics{}, 640, 480});
  camera["intrinsics"]["xi"] = -1;
  EXPECT_THROW(CameraFromJson(camera), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::api
