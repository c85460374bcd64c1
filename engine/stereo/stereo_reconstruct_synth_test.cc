// Integration: "instant 3D" on rendered images of the synthetic textured room
// (engine/synth/presets.h, MakeStereoSequence), checked against the room's true geometry: each
// point's range is compared with the range at which cam0's ray through its keypoint hits the
// scene (a ray cast against the scene's primitives).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <gtest/gtest.h>

#include "engine/geometry/unified_camera.h"
#include "engine/stereo/stereo_reconstruct.h"
#include "engine/synth/presets.h"

namespace omnirig {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kEps = 1e-9;

// First hit (ray parameter, > 0) of the ray o + t d with one primitive, in its local frame.
double HitPlane(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& size) {
  if (std::abs(d.z()) < kEps) return kInf;
  const double t = -o.z() / d.z();
  const Eigen::Vector3d p = o + t * d;
  return t > kEps && std::abs(p.x()) <= 0.5 * size.x() && std::abs(p.y()) <= 0.5 * size.y() ? t
                                                                                            : kInf;
}

double HitBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& size) {
  double t_near = -kInf, t_far = kInf;
  for (int k = 0; k < 3; ++k) {
    const double h = 0.5 * size[k];
    if (std::abs(d[k]) < kEps) {
      if (std::abs(o[k]) > h) return kInf;
      continue;
    }
    const double t1 = (-h - o[k]) / d[k], t2 = (h - o[k]) / d[k];
    t_near = std::max(t_near, std::min(t1, t2));
    t_far = std::min(t_far, std::max(t1, t2));
  }
  if (t_near > t_far) return kInf;
  if (t_near > kEps) return t_near;    // from outside
  return t_far > kEps ? t_far : kInf;  // from inside (the room's walls)
}

double HitCylinder(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double radius,
                   double height) {
  double best = kInf;
  const double a = d.x() * d.x() + d.y() * d.y();
  const double b = 2.0 * (o.x() * d.x() + o.y() * d.y());
  const double c = o.x() * o.x() + o.y() * o.y() - radius * radius;
  const double disc = b * b - 4 * a * c;
  if (a > kEps && disc >= 0.0) {
    for (double t : {(-b - std::sqrt(disc)) / (2 * a), (-b + std::sqrt(disc)) / (2 * a)}) {
      const double z = o.z() + t * d.z();
      if (t > kEps && z >= 0.0 && z <= height) best = std::min(best, t);
    }
  }
  if (std::abs(d.z()) > kEps) {
    for (double zc : {0.0, height}) {
      const double t = (zc - o.z()) / d.z();
      const Eigen::Vector3d p = o + t * d;
      if (t > kEps && p.x() * p.x() + p.y() * p.y() <= radius * radius) best = std::min(best, t);
    }
  }
  return best;
}

// Range along a unit ray from `origin` (world frame) to the first surface of the scene.
double CastRay(const synth::Scene& scene, const Eigen::Vector3d& origin,
               const Eigen::Vector3d& direction) {
  double best = kInf;
  for (const synth::PrimitiveInfo& primitive : scene.primitives()) {
    const Rigid3d local_from_world = primitive.world_from_local.Inverse();
    const Eigen::Vector3d o = local_from_world * origin;
    const Eigen::Vector3d d = local_from_world.rotation * direction;
    double t = kInf;
    switch (primitive.kind) {
      case synth::PrimitiveInfo::Kind::kPlane:
        t = HitPlane(o, d, primitive.size_m);
        break;
      case synth::PrimitiveInfo::Kind::kBox:
        t = HitBox(o, d, primitive.size_m);
        break;
      case synth::PrimitiveInfo::Kind::kCylinder:
        t = HitCylinder(o, d, primitive.size_m.x(), primitive.size_m.z());
        break;
      case synth::PrimitiveInfo::Kind::kCheckerboard:
        break;
    }
    best = std::min(best, t);
  }
  return best;
}

TEST(StereoReconstructSynth, RangesMatchTheRoomWithinTheirUncertainty) {
  synth::StereoSequenceOptions sequence_options;
  sequence_options.num_frames = 1;
  sequence_options.render.noise_sigma = 1.0;
  sequence_options.seed = 3;
  const synth::StereoSequence sequence = synth::MakeStereoSequence(sequence_options);
  ASSERT_EQ(sequence.images[0].size(), 1u);

  const StereoReconstructOptions options;
  const StereoPairReport report =
      ReconstructStereoPair(sequence.rig, sequence.images[0][0], sequence.images[1][0], options);
  const Rigid3d& world_from_cam0 = sequence.world_from_rig[0];
  std::vector<double> relative_errors;
  int within_3_sigma = 0, gross = 0;
  for (const StereoPoint& point : report.points) {
    const Eigen::Vector3d bearing = *Lift(sequence.rig.cam0.intrinsics, point.pixel0);
    const double true_range =
        CastRay(sequence.scene, world_from_cam0.translation, world_from_cam0.rotation * bearing);
    ASSERT_TRUE(std::isfinite(true_range));
    const double error = std::abs(point.point_in_cam0.norm() - true_range);
    relative_errors.push_back(error / true_range);
    within_3_sigma += error <= 3.0 * point.range_std_m;
    gross += error > 0.2 * true_range;  // a wrong match, or a keypoint on an occlusion edge
  }
  ASSERT_FALSE(relative_errors.empty());
  std::sort(relative_errors.begin(), relative_errors.end());
  const double median = relative_errors[relative_errors.size() / 2];
  const double n = static_cast<double>(report.points.size());
  std::printf(
      "keypoints %d/%d, candidates %d, matches %d, points %zu (rejected: parallax %d, "
      "reprojection %d, uncertain %d); range error / range: median %.4f, 90%% %.4f; "
      "within 3 sigma %.1f%%, gross %.1f%%\n",
      report.num_keypoints0, report.num_keypoints1, report.num_candidates, report.num_matches,
      report.points.size(), report.num_rejected_parallax, report.num_rejected_reprojection,
      report.num_rejected_uncertain, median, relative_errors[relative_errors.size() * 9 / 10],
      100 * within_3_sigma / n, 100 * gross / n);
  // A 0.1 m vertical baseline in a 10 m x 7 m room: ranges of 1-6 m at 1-6 degrees of parallax.
  EXPECT_GT(report.points.size(), 1000u);
  EXPECT_LT(median, 0.02);
  EXPECT_GT(within_3_sigma, 0.9 * n);
  EXPECT_LT(gross, 0.03 * n);
}

}  // namespace
}  // namespace omnirig
