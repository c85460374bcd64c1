#include "engine/geometry/reprojection_cost.h"

#include "engine/geometry/ceres_problem.h"
#include "engine/util/check.h"

namespace omnirig {

ReprojectionCost::ReprojectionCost(const Eigen::Vector2d& measured_px,
                                   const std::optional<Eigen::Vector3d>& point, Rig rig,
                                   const Rigid3d& cam_from_x,
                                   const std::optional<UnifiedIntrinsics>& intrinsics)
    : measured_px_(measured_px),
      point_(point),
      rig_(rig),
      cam_from_x_rotation_(cam_from_x.RotationMatrix()),
      cam_from_x_translation_(cam_from_x.translation) {
  if (intrinsics) intrinsics_ = intrinsics->params;
  set_num_residuals(2);
  std::vector<int32_t>& sizes = *mutable_parameter_block_sizes();
  sizes.push_back(7);
  const auto add = [&sizes](int size) {
    sizes.push_back(size);
    return static_cast<int>(sizes.size()) - 1;
  };
  if (!point_) point_block_ = add(3);
  if (rig_ == Rig::kBlock) rotation_block_ = translation_block_ = add(7);
  if (rig_ == Rig::kRotationTranslationBlocks) {
    rotation_block_ = add(4);
    translation_block_ = add(3);
  }
  if (!intrinsics_) intrinsics_block_ = add(UnifiedIntrinsics::kNumParams);
}

ReprojectionCost* ReprojectionCost::BoardCorner(const Eigen::Vector3d& point_in_board,
                                                const Eigen::Vector2d& measured_px) {
  return new ReprojectionCost(measured_px, point_in_board, Rig::kNone, Rigid3d(), std::nullopt);
}

ReprojectionCost* ReprojectionCost::BoardCornerThroughRig(const Eigen::Vector3d& point_in_board,
                                                          const Eigen::Vector2d& measured_px) {
  return new ReprojectionCost(measured_px, point_in_board, Rig::kBlock, Rigid3d(), std::nullopt);
}

ReprojectionCost* ReprojectionCost::BoardCornerFixedCamera(const Eigen::Vector3d& point_in_board,
                                                           const Eigen::Vector2d& measured_px,
                                                           const Rigid3d& cam_from_cam0,
                                                           const UnifiedIntrinsics& intrinsics) {
  return new ReprojectionCost(measured_px, point_in_board, Rig::kConstant, cam_from_cam0,
                              intrinsics);
}

ReprojectionCost* ReprojectionCost::Landmark(const Eigen::Vector2d& measured_px,
                                             const Rigid3d& cam_from_rig,
                                             const UnifiedIntrinsics& intrinsics) {
  return new ReprojectionCost(measured_px, std::nullopt, Rig::kConstant, cam_from_rig,
                              intrinsics);
}

ReprojectionCost* ReprojectionCost::LandmarkWithCalibration(int camera,
                                                            const Eigen::Vector2d& measured_px) {
  OMNIRIG_CHECK(camera == 0 || camera == 1, "a stereo rig has cameras 0 and 1, not " << camera);
  return new ReprojectionCost(measured_px, std::nullopt,
                              camera == 0 ? Rig::kNone : Rig::kRotationTranslationBlocks,
                              Rigid3d(), std::nullopt);
}

ReprojectionCost::ThroughRig ReprojectionCost::CarryThroughRig(double const* const* parameters,
                                                               const Eigen::Vector3d& posed) const {
  ThroughRig rig;
  rig.point_in_cam = posed;
  if (rig_ == Rig::kConstant) {
    rig.point_in_cam = cam_from_x_rotation_ * posed + cam_from_x_translation_;
    rig.d_cam_d_posed = cam_from_x_rotation_;
  } else if (rig_ != Rig::kNone) {
    // cam1 = cam0_from_cam1^-1 * (point_in_cam0 - translation), linear in point_in_cam0.
    rig.cam1_from_cam0 =
        Eigen::Map<const Eigen::Quaterniond>(parameters[rotation_block_]).conjugate();
    rig.offset = posed - Eigen::Map<const Eigen::Vector3d>(parameters[translation_block_] +
                                                           (rig_ == Rig::kBlock ? 4 : 0));
    rig.point_in_cam = rig.cam1_from_cam0 * rig.offset;
    rig.d_cam_d_posed = rig.cam1_from_cam0.toRotationMatrix();
  }
  return rig;
}

void ReprojectionCost::RigJacobians(const Eigen::Matrix<double, 2, 3>& d_pixel_d_cam,
                                    const Eigen::Matrix<double, 2, 3>& d_pixel_d_posed,
                                    const ThroughRig& rig, double** jacobians) const {
  // The conjugate negates the vector part: d/du = -(d/du' at u' = -u).
  Eigen::Matrix<double, 3, 4> d_cam_d_rotation =
      RotatedPointJacobian(rig.cam1_from_cam0, rig.offset);
  d_cam_d_rotation.leftCols<3>() *= -1.0;
  const Eigen::Matrix<double, 2, 4> d_pixel_d_rotation = d_pixel_d_cam * d_cam_d_rotation;
  if (rig_ == Rig::kBlock) {
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> jacobian(jacobians[rotation_block_]);
    jacobian.leftCols<4>() = d_pixel_d_rotation;
    jacobian.rightCols<3>() = -d_pixel_d_posed;
    return;
  }
  if (jacobians[rotation_block_] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>> jacobian(jacobians[rotation_block_]);
    jacobian = d_pixel_d_rotation;
  }
  if (jacobians[translation_block_] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> jacobian(
        jacobians[translation_block_]);
    jacobian = -d_pixel_d_posed;
  }
}

bool ReprojectionCost::Evaluate(double const* const* parameters, double* residuals,
                                double** jacobians) const {
  const auto wanted = [&](int block) {
    return jacobians != nullptr && block >= 0 && jacobians[block] != nullptr;
  };
  const double* intrinsics = intrinsics_ ? intrinsics_->data() : parameters[intrinsics_block_];
  // The pose, then the rig.
  const Eigen::Map<const Eigen::Quaterniond> rotation(parameters[0]);
  const Eigen::Map<const Eigen::Vector3d> translation(parameters[0] + 4);
  const Eigen::Map<const Eigen::Vector3d> point(point_ ? point_->data() : parameters[point_block_]);
  const ThroughRig rig = CarryThroughRig(parameters, rotation * point + translation);

  // Then the projection.
  const bool want_geometry =
      wanted(0) || wanted(point_block_) || wanted(rotation_block_) || wanted(translation_block_);
  Eigen::Vector2d pixel;
  Eigen::Matrix<double, 2, 3> d_pixel_d_cam;
  IntrinsicsJacobianOf<double> d_pixel_d_intrinsics;
  if (!Project(intrinsics, rig.point_in_cam, &pixel, want_geometry ? &d_pixel_d_cam : nullptr,
               wanted(intrinsics_block_) ? &d_pixel_d_intrinsics : nullptr)) {
    return false;
  }
  residuals[0] = pixel.x() - measured_px_.x();
  residuals[1] = pixel.y() - measured_px_.y();

  if (wanted(intrinsics_block_)) {
    Eigen::Map<Eigen::Matrix<double, 2, UnifiedIntrinsics::kNumParams, Eigen::RowMajor>> jacobian(
        jacobians[intrinsics_block_]);
    jacobian = d_pixel_d_intrinsics;
  }
  if (!want_geometry) return true;
  const Eigen::Matrix<double, 2, 3> d_pixel_d_posed =
      rig_ == Rig::kNone ? d_pixel_d_cam
                         : Eigen::Matrix<double, 2, 3>(d_pixel_d_cam * rig.d_cam_d_posed);
  if (wanted(0)) {
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> jacobian(jacobians[0]);
    jacobian.leftCols<4>() = d_pixel_d_posed * RotatedPointJacobian(rotation, point);
    jacobian.rightCols<3>() = d_pixel_d_posed;
  }
  if (wanted(point_block_)) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> jacobian(jacobians[point_block_]);
    jacobian = d_pixel_d_posed * rotation.toRotationMatrix();
  }
  if (wanted(rotation_block_) || wanted(translation_block_)) {
    RigJacobians(d_pixel_d_cam, d_pixel_d_posed, rig, jacobians);
  }
  return true;
}

}  // namespace omnirig
