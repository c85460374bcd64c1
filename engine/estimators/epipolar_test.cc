#include "engine/estimators/epipolar.h"

#include <random>

#include <gtest/gtest.h>

#include "engine/estimators/essential.h"
#include "engine/util/check.h"

namespace omnirig {
namespace {

CameraModel Camera(double u0, double v0) {
  CameraModel camera;
  camera.intrinsics.params = {0.95,  300.0, 305.0,  u0,      v0,   0.001,
                              -0.12, 0.03,  0.0008, -0.0005, 0.004};
  camera.width = 1024;
  camera.height = 768;
  return camera;
}

// Two downward-looking catadioptric cameras one above the other, 0.1 m apart, slightly turned.
StereoRig VerticalRig() {
  StereoRig rig;
  rig.cam0 = Camera(512.3, 383.7);
  rig.cam1 = Camera(509.0, 386.2);
  rig.cam0_from_cam1 = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.03, Eigen::Vector3d(0.2, 0.1, 1).normalized())),
      Eigen::Vector3d(0.003, -0.002, 0.1));
  return rig;
}

double DistanceToPolyline(const Polyline2d& line, const Eigen::Vector2d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i + 1 < line.size(); ++i) {
    const Eigen::Vector2d d = line[i + 1] - line[i];
    const double s = std::clamp((p - line[i]).dot(d) / std::max(d.squaredNorm(), 1e-300), 0.0, 1.0);
    best = std::min(best, (line[i] + s * d - p).norm());
  }
  return best;
}

bool Inside(const CameraModel& camera, const Eigen::Vector2d& p) {
  return p.x() >= -0.5 && p.y() >= -0.5 && p.x() < camera.width - 0.5 &&
         p.y() < camera.height - 0.5;
}

TEST(EpipolarCurve, SamplesLieOnTheEpipolarPlaneAndTheTrueMatchOnTheCurve) {
  const StereoRig rig = VerticalRig();
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_real_distribution<double> range(0.5, 5.0);
  int checked = 0;
  for (int trial = 0; trial < 300 && checked < 60; ++trial) {
    const Eigen::Vector3d point_in_cam0 =
        range(rng) * Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
    const Eigen::Vector3d point_in_cam1 = rig.cam0_from_cam1.Inverse() * point_in_cam0;
    const auto p0 = Project(rig.cam0.intrinsics, point_in_cam0);
    const auto p1 = Project(rig.cam1.intrinsics, point_in_cam1);
    if (!p0 || !p1 || !Inside(rig.cam0, *p0) || !Inside(rig.cam1, *p1)) continue;
    for (int from = 0; from < 2; ++from) {
      const Eigen::Vector2d pixel = from == 0 ? *p0 : *p1;
      const Eigen::Vector2d match = from == 0 ? *p1 : *p0;
      const CameraModel& from_camera = from == 0 ? rig.cam0 : rig.cam1;
      const CameraModel& to_camera = from == 0 ? rig.cam1 : rig.cam0;
      const Rigid3d to_from_from = from == 0 ? rig.cam0_from_cam1.Inverse() : rig.cam0_from_cam1;
      const Eigen::Matrix3d e = EssentialFromPose(to_from_from);
      const Eigen::Vector3d bearing = *Lift(from_camera.intrinsics, pixel);

      const std::vector<Polyline2d> curves = EpipolarCurve(rig, from, pixel, 400);
      ASSERT_FALSE(curves.empty());
      double distance = std::numeric_limits<double>::infinity();
      for (const Polyline2d& curve : curves) {
        ASSERT_GE(curve.size(), 2u);
        for (const Eigen::Vector2d& sample : curve) {
          EXPECT_TRUE(Inside(to_camera, sample));
          const auto lifted = Lift(to_camera.intrinsics, sample);
          ASSERT_TRUE(lifted.has_value());
          EXPECT_LT(EpipolarAngularError(e, bearing, *lifted), 1e-9);
        }
        distance = std::min(distance, DistanceToPolyline(curve, match));
      }
      // Chords of 400 samples over the arc stay well under half a pixel from the curve.
      EXPECT_LT(distance, 0.5) << "from cam" << from << " pixel " << pixel.transpose();
    }
    ++checked;
  }
  EXPECT_EQ(checked, 60);
}

TEST(EpipolarCurve, SplitsWhereTheCurveLeavesTheImage) {
  // A sideways baseline makes the curves wide conics around the image centre; a band of the
  // image's top rows cuts them into pieces. Every kept sample is inside.
  StereoRig rig = VerticalRig();
  rig.cam0_from_cam1.translation = Eigen::Vector3d(0.1, 0.0, 0.0);
  rig.cam1.height = 300;
  int split = 0;
  for (double u = 100; u < 1000; u += 50) {
    for (double v = 100; v < 700; v += 50) {
      for (const Polyline2d& curve : EpipolarCurve(rig, 0, Eigen::Vector2d(u, v))) {
        EXPECT_GE(curve.size(), 2u);
        for (const Eigen::Vector2d& p : curve) EXPECT_TRUE(Inside(rig.cam1, p));
      }
      split += EpipolarCurve(rig, 0, Eigen::Vector2d(u, v)).size() > 1;
    }
  }
  EXPECT_GT(split, 0);
}

TEST(EpipolarCurve, BadInputs) {
  const StereoRig rig = VerticalRig();
  EXPECT_THROW(EpipolarCurve(rig, 2, Eigen::Vector2d(500, 400)), InvalidArgument);
  EXPECT_THROW(EpipolarCurve(rig, 0, Eigen::Vector2d(500, 400), 1), InvalidArgument);
  // A pixel that does not lift has no curve.
  EXPECT_TRUE(EpipolarCurve(rig, 0, Eigen::Vector2d(NAN, 400)).empty());
  // No baseline: no curve (every depth maps to one direction).
  StereoRig no_baseline = rig;
  no_baseline.cam0_from_cam1.translation.setZero();
  EXPECT_TRUE(EpipolarCurve(no_baseline, 1, Eigen::Vector2d(500, 400)).empty());
}

}  // namespace
}  // namespace omnirig
