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
  if (!point_) sizes.push_back(3);
  if (rig_ == Rig::kBlock) sizes.push_back(7);
  if (rig_ == Rig::kRotationTranslationBlocks) sizes.insert(sizes.end(), {4, 3});
  if (!intrinsics_) sizes.push_back(UnifiedIntrinsics::kNumParams);
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

bool ReprojectionCost::Evaluate(double const* const* parameters, double* residuals,
                                double** jacobians) const {
  // Where each block is (-1: constant, no Jacobian).
  int next = 1;
  const int point_block = point_ ? -1 : next++;
  const int rotation_block = rig_ == Rig::kBlock || rig_ == Rig::kRotationTranslationBlocks
                                 ? next++ : -1;
  const int translation_block = rig_ == Rig::kBlock ? rotation_block
                                : rig_ == Rig::kRotationTranslationBlocks ? next++
                                                                          : -1;
  const int intrinsics_block = intrinsics_ ? -1 : next++;
  const auto wanted = [&](int block) {
    return jacobians != nullptr && block >= 0 && jacobians[block] != nullptr;
  };
  const double* point_data = point_ ? point_->data() : parameters[point_block];
  const double* intrinsics = intrinsics_ ? intrinsics_->data() : parameters[intrinsics_block];

  // The pose, then the rig.
  const Eigen::Map<const Eigen::Quaterniond> rotation(parameters[0]);
  const Eigen::Map<const Eigen::Vector3d> translation(parameters[0] + 4);
  const Eigen::Map<const Eigen::Vector3d> point(point_data);
  const Eigen::Vector3d posed = rotation * point + translation;
  Eigen::Vector3d point_in_cam = posed;
  Eigen::Matrix3d d_cam_d_posed = Eigen::Matrix3d::Identity();
  Eigen::Quaterniond cam1_from_cam0 = Eigen::Quaterniond::Identity();
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  if (rig_ == Rig::kConstant) {
    point_in_cam = cam_from_x_rotation_ * posed + cam_from_x_translation_;
    d_cam_d_posed = cam_from_x_rotation_;
  } else if (rig_ != Rig::kNone) {
    // cam1 = cam0_from_cam1^-1 * (point_in_cam0 - translation), linear in point_in_cam0.
    cam1_from_cam0 = Eigen::Map<const Eigen::Quaterniond>(parameters[rotation_block]).conjugate();
    offset = posed - Eigen::Map<const Eigen::Vector3d>(parameters[translation_block] +
                                                       (rig_ == Rig::kBlock ? 4 : 0));
    point_in_cam = cam1_from_cam0 * offset;
    d_cam_d_posed = cam1_from_cam0.toRotationMatrix();
  }

  // Then the projection.
  const bool want_geometry = wanted(0) || wanted(point_block) || wanted(rotation_block) ||
                             wanted(translation_block);
  Eigen::Vector2d pixel;
  Eigen::Matrix<double, 2, 3> d_pixel_d_cam;
  IntrinsicsJacobianOf<double> d_pixel_d_intrinsics;
  if (!Project(intrinsics, point_in_cam, &pixel, want_geometry ? &d_pixel_d_cam : nullptr,
               wanted(intrinsics_block) ? &d_pixel_d_intrinsics : nullptr)) {
    return false;
  }
  residuals[0] = pixel.x() - measured_px_.x();
  residuals[1] = pixel.y() - measured_px_.y();

  if (wanted(intrinsics_block)) {
    Eigen::Map<Eigen::Matrix<double, 2, UnifiedIntrinsics::kNumParams, Eigen::RowMajor>> jacobian(
        jacobians[intrinsics_block]);
    jacobian = d_pixel_d_intrinsics;
  }
  if (!want_geometry) return true;
  using RowMajor2x7 = Eigen::Matrix<double, 2, 7, Eigen::RowMajor>;
  const Eigen::Matrix<double, 2, 3> d_pixel_d_posed =
      rig_ == Rig::kNone ? d_pixel_d_cam : Eigen::Matrix<double, 2, 3>(d_pixel_d_cam * d_cam_d_posed);
  if (wanted(0)) {
    Eigen::Map<RowMajor2x7> jacobian(jacobians[0]);
    jacobian.leftCols<4>() = d_pixel_d_posed * RotatedPointJacobian(rotation, point);
    jacobian.rightCols<3>() = d_pixel_d_posed;
  }
  if (wanted(point_block)) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> jacobian(jacobians[point_block]);
    jacobian = d_pixel_d_posed * rotation.toRotationMatrix();
  }
  if (wanted(rotation_block) || wanted(translation_block)) {
    // The conjugate negates the vector part: d/du = -(d/du' at u' = -u).
    Eigen::Matrix<double, 3, 4> d_cam_d_rotation = RotatedPointJacobian(cam1_from_cam0, offset);
    d_cam_d_rotation.leftCols<3>() *= -1.0;
    const Eigen::Matrix<double, 2, 4> d_pixel_d_rotation = d_pixel_d_cam * d_cam_d_rotation;
    if (rig_ == Rig::kBlock) {
      Eigen::Map<RowMajor2x7> jacobian(jacobians[rotation_block]);
      jacobian.leftCols<4>() = d_pixel_d_rotation;
      jacobian.rightCols<3>() = -d_pixel_d_posed;
    } else {
      if (wanted(rotation_block)) {
        Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>> jacobian(jacobians[rotation_block]);
        jacobian = d_pixel_d_rotation;
      }
      if (wanted(translation_block)) {
        Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> jacobian(
            jacobians[translation_block]);
        jacobian = -d_pixel_d_posed;
      }
    }
  }
  return true;
}

}  // namespace omnirig
