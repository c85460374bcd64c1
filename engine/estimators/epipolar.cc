#include "engine/estimators/epipolar.h"

#include <cmath>

#include <Eigen/Geometry>

#include "engine/geometry/unified_camera.h"
#include "engine/util/check.h"

namespace omnirig {
namespace {

bool InImage(const CameraModel& camera, const Eigen::Vector2d& pixel) {
  // Pixel centres at integers: the image covers [-0.5, size - 0.5).
  return pixel.x() >= -0.5 && pixel.y() >= -0.5 && pixel.x() < camera.width - 0.5 &&
         pixel.y() < camera.height - 0.5;
}

}  // namespace

std::vector<Polyline2d> EpipolarCurve(const StereoRig& rig, int from_camera,
                                      const Eigen::Vector2d& pixel, int num_samples) {
  OMNIRIG_CHECK(from_camera == 0 || from_camera == 1,
                "from_camera must be 0 or 1, got " << from_camera);
  OMNIRIG_CHECK(num_samples >= 2, "num_samples must be at least 2, got " << num_samples);
  const CameraModel& from = from_camera == 0 ? rig.cam0 : rig.cam1;
  const CameraModel& to = from_camera == 0 ? rig.cam1 : rig.cam0;
  const Rigid3d to_from_from = from_camera == 0 ? rig.cam0_from_cam1.Inverse() : rig.cam0_from_cam1;

  std::vector<Polyline2d> curves;
  const std::optional<Eigen::Vector3d> bearing = Lift(from.intrinsics, pixel);
  if (!bearing) return curves;

  // Seen from `to`, the point at depth d along the ray is R b d + t: its direction runs from
  // t (the epipole, d = 0) to R b (d = infinity) along the great circle through both.
  const Eigen::Vector3d far = (to_from_from.rotation * *bearing).normalized();
  const double baseline = to_from_from.translation.norm();
  if (!(baseline > 0.0)) return curves;  // no baseline: the "curve" is the single point `far`
  const Eigen::Vector3d epipole = to_from_from.translation / baseline;
  const double arc = std::atan2(epipole.cross(far).norm(), epipole.dot(far));
  if (!(arc > 0.0)) return curves;  // the pixel looks along the baseline
  // Unit vector orthogonal to the epipole in the plane of the arc (the arc is < pi long).
  const Eigen::Vector3d ortho = (far - epipole.dot(far) * epipole).normalized();

  Polyline2d current;
  for (int i = 1; i <= num_samples; ++i) {
    const double angle = arc * static_cast<double>(i) / num_samples;
    const Eigen::Vector3d direction = std::cos(angle) * epipole + std::sin(angle) * ortho;
    const std::optional<Eigen::Vector2d> p = Project(to.intrinsics, direction);
    // Lifting back guards against the distortion folding over outside its calibrated range:
    // a sample is kept only where projection and lifting agree.
    const std::optional<Eigen::Vector3d> back =
        p && InImage(to, *p) ? Lift(to.intrinsics, *p) : std::nullopt;
    if (back && back->dot(direction) > std::cos(1e-6)) {
      current.push_back(*p);
      continue;
    }
    if (current.size() >= 2) curves.push_back(std::move(current));
    current.clear();
  }
  if (current.size() >= 2) curves.push_back(std::move(current));
  return curves;
}

}  // namespace omnirig
