#include "engine/geometry/unified_camera.h"

#include <random>

#include <ceres/jet.h>
#include <gtest/gtest.h>
#include <opencv2/ccalib/omnidir.hpp>

namespace omnirig {
namespace {

// Points whose projection falls inside a 1024x768 image: the model's distortion polynomial is
// only meant to be invertible over the image.
bool InImage(const std::optional<Eigen::Vector2d>& pixel) {
  return pixel && pixel->x() >= 0 && pixel->x() < 1024 && pixel->y() >= 0 && pixel->y() < 768;
}

UnifiedIntrinsics HyperbolicCamera() {
  UnifiedIntrinsics c;
  c.params = {0.95, 300.0, 305.0, 512.3, 383.7, 0.001, -0.12, 0.03, 0.0008, -0.0005, 0.004};
  return c;
}

TEST(UnifiedCamera, LiftOfProjectionIsParallel) {
  const UnifiedIntrinsics camera = HyperbolicCamera();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int tested = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d point(u(rng) * 5, u(rng) * 5, u(rng) * 2);
    const auto pixel = Project(camera, point);
    if (!InImage(pixel)) continue;
    const auto bearing = Lift(camera, *pixel);
    ASSERT_TRUE(bearing.has_value()) << point.transpose();
    EXPECT_NEAR((*bearing - point.normalized()).norm(), 0.0, 1e-9);
    ++tested;
  }
  EXPECT_GT(tested, 1000);
}

TEST(UnifiedCamera, ProjectionOfLiftIsIdentityOverPixelGrid) {
  const UnifiedIntrinsics camera = HyperbolicCamera();
  int tested = 0;
  for (double v = 84; v < 684; v += 10) {
    for (double u = 212; u < 812; u += 10) {
      const Eigen::Vector2d pixel(u, v);
      const auto bearing = Lift(camera, pixel);
      if (!bearing) continue;
      const auto back = Project(camera, *bearing);
      ASSERT_TRUE(back.has_value());
      EXPECT_LT((*back - pixel).norm(), 1e-6) << pixel.transpose();
      ++tested;
    }
  }
  EXPECT_GT(tested, 3000);
}

TEST(UnifiedCamera, RejectsInvalidInputs) {
  UnifiedIntrinsics camera = HyperbolicCamera();
  EXPECT_FALSE(Project(camera, Eigen::Vector3d::Zero()).has_value());
  // Straight behind the mirror: X_s.z = -1 < -xi.
  EXPECT_FALSE(Project(camera, Eigen::Vector3d(0, 0, -1)).has_value());
  camera.xi() = 1.5;  // beyond the horizon X_s.z = -1/xi the projection folds over
  EXPECT_FALSE(Project(camera, Eigen::Vector3d(0.3, 0, -0.95)).has_value());
  EXPECT_TRUE(Project(camera, Eigen::Vector3d(1, 0, -0.5)).has_value());
  // A pixel far outside the image of the horizon has no bearing for xi > 1.
  UnifiedIntrinsics no_distortion;
  no_distortion.params = {1.5, 300, 300, 500, 400, 0, 0, 0, 0, 0, 0};
  EXPECT_FALSE(Lift(no_distortion, Eigen::Vector2d(500 + 1e4, 400)).has_value());
  EXPECT_FALSE(Lift(no_distortion, Eigen::Vector2d(NAN, 400)).has_value());
  UnifiedIntrinsics bad = camera;
  bad.gamma_u() = -1;
  EXPECT_THROW(bad.Check(), InvalidArgument);
  bad = camera;
  bad.xi() = -0.1;
  EXPECT_THROW(bad.Check(), InvalidArgument);
  EXPECT_NO_THROW(camera.Check());
}

TEST(UnifiedCamera, JacobianMatchesJetsAndCentralDifferences) {
  const UnifiedIntrinsics camera = HyperbolicCamera();
  using Jet = ceres::Jet<double, 3>;
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d point(u(rng) * 3, u(rng) * 3, u(rng) * 1.5);
    Eigen::Matrix<double, 2, 3> analytic;
    Eigen::Vector2d projected;
    const std::optional<Eigen::Vector2d> pixel =
        Project(camera.params.data(), point, &projected, &analytic)
            ? std::optional<Eigen::Vector2d>(projected)
            : std::nullopt;
    if (!InImage(pixel)) continue;
    // Jets.
    Jet params[UnifiedIntrinsics::kNumParams];
    for (int k = 0; k < UnifiedIntrinsics::kNumParams; ++k) params[k] = Jet(camera.params[k]);
    Jet point_jet[3] = {Jet(point.x(), 0), Jet(point.y(), 1), Jet(point.z(), 2)};
    Jet pixel_jet[2];
    ASSERT_TRUE(ProjectToPixel(params, point_jet, pixel_jet));
    for (int r = 0; r < 2; ++r) {
      EXPECT_NEAR(pixel_jet[r].a, (*pixel)[r], 1e-9);
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(pixel_jet[r].v[c], analytic(r, c), 1e-7 * (1 + std::abs(analytic(r, c))));
      }
    }
    // Central differences.
    const double h = 1e-6;
    for (int c = 0; c < 3; ++c) {
      Eigen::Vector3d plus = point, minus = point;
      plus[c] += h;
      minus[c] -= h;
      const auto pp = Project(camera, plus), pm = Project(camera, minus);
      ASSERT_TRUE(pp && pm);
      const Eigen::Vector2d numeric = (*pp - *pm) / (2 * h);
      for (int r = 0; r < 2; ++r) {
        EXPECT_NEAR(numeric[r], analytic(r, c), 1e-4 * (1 + std::abs(analytic(r, c))));
      }
    }
  }
}

// The templated projection's Jacobians (point and parameters) against central differences of
// the projection itself, in double and in float.
template <typename T>
void CheckProjectionJacobians(T step, T tolerance) {
  using I = UnifiedIntrinsics;
  const UnifiedIntrinsics camera = HyperbolicCamera();
  std::array<T, I::kNumParams> params;
  for (int k = 0; k < I::kNumParams; ++k) params[k] = static_cast<T>(camera.params[k]);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int tested = 0;
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector3d point_d(u(rng) * 3, u(rng) * 3, u(rng) * 1.5);
    if (!InImage(Project(camera, point_d))) continue;
    const Vector3<T> point = point_d.cast<T>();
    Vector2<T> pixel;
    Eigen::Matrix<T, 2, 3> d_point;
    IntrinsicsJacobianOf<T> d_params;
    ASSERT_TRUE(Project(params.data(), point, &pixel, &d_point, &d_params));
    EXPECT_LT((pixel.template cast<double>() - *Project(camera, point_d)).norm(),
              1e4 * Eigen::NumTraits<T>::epsilon());
    // Scale invariance: the derivative along the ray is zero.
    EXPECT_LT((d_point * point).norm(), tolerance * 100);
    for (int c = 0; c < 3; ++c) {
      Vector3<T> plus = point, minus = point;
      plus[c] += step;
      minus[c] -= step;
      Vector2<T> pp, pm;
      ASSERT_TRUE(Project(params.data(), plus, &pp) && Project(params.data(), minus, &pm));
      const Vector2<T> numeric = (pp - pm) / (T(2) * step);
      for (int r = 0; r < 2; ++r) {
        EXPECT_NEAR(numeric[r], d_point(r, c), tolerance * (1 + std::abs(d_point(r, c))));
      }
    }
    for (int k = 0; k < I::kNumParams; ++k) {
      std::array<T, I::kNumParams> plus = params, minus = params;
      plus[k] += step;
      minus[k] -= step;
      Vector2<T> pp, pm;
      ASSERT_TRUE(Project(plus.data(), point, &pp) && Project(minus.data(), point, &pm));
      const Vector2<T> numeric = (pp - pm) / (T(2) * step);
      for (int r = 0; r < 2; ++r) {
        EXPECT_NEAR(numeric[r], d_params(r, k), tolerance * (1 + std::abs(d_params(r, k))))
            << I::kNames[k];
      }
    }
    ++tested;
  }
  EXPECT_GT(tested, 50);
}

TEST(UnifiedCamera, ProjectionJacobiansMatchCentralDifferencesInDouble) {
  CheckProjectionJacobians<double>(1e-6, 1e-4);
}

TEST(UnifiedCamera, ProjectionJacobiansMatchCentralDifferencesInFloat) {
  CheckProjectionJacobians<float>(1e-2f, 2e-2f);
}

TEST(UnifiedCamera, IntrinsicsJacobianMatchesJets) {
  using I = UnifiedIntrinsics;
  using Jet = ceres::Jet<double, I::kNumParams>;
  const UnifiedIntrinsics camera = HyperbolicCamera();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d point(u(rng) * 3, u(rng) * 3, u(rng) * 1.5);
    Eigen::Vector2d pixel;
    IntrinsicsJacobianOf<double> analytic;
    if (!InImage(Project(camera, point))) continue;
    ASSERT_TRUE(Project(camera.params.data(), point, &pixel, nullptr, &analytic));
    Jet params[I::kNumParams];
    for (int k = 0; k < I::kNumParams; ++k) params[k] = Jet(camera.params[k], k);
    const Jet point_jet[3] = {Jet(point.x()), Jet(point.y()), Jet(point.z())};
    Jet pixel_jet[2];
    ASSERT_TRUE(ProjectToPixel(params, point_jet, pixel_jet));
    for (int r = 0; r < 2; ++r) {
      for (int k = 0; k < I::kNumParams; ++k) {
        EXPECT_NEAR(pixel_jet[r].v[k], analytic(r, k), 1e-9 * (1 + std::abs(analytic(r, k))))
            << I::kNames[k];
      }
    }
  }
}

// The lifting's Jacobian against central differences of Lift, in double and in float; and the
// lift of the projection in float.
template <typename T>
void CheckLiftJacobian(T step, T tolerance) {
  using I = UnifiedIntrinsics;
  const UnifiedIntrinsics camera = HyperbolicCamera();
  std::array<T, I::kNumParams> params;
  for (int k = 0; k < I::kNumParams; ++k) params[k] = static_cast<T>(camera.params[k]);
  int tested = 0;
  for (double v = 84; v < 684; v += 50) {
    for (double u = 212; u < 812; u += 50) {
      const Vector2<T> pixel(static_cast<T>(u), static_cast<T>(v));
      Vector3<T> bearing;
      Eigen::Matrix<T, 3, 2> jacobian;
      if (!Lift(params.data(), pixel, &bearing, &jacobian)) continue;
      Vector2<T> back;
      ASSERT_TRUE(Project(params.data(), bearing, &back));
      EXPECT_LT((back - pixel).norm(), tolerance * 0.1);
      EXPECT_LT((bearing.transpose() * jacobian).norm(), tolerance * 1e-2);
      for (int c = 0; c < 2; ++c) {
        Vector2<T> plus = pixel, minus = pixel;
        plus[c] += step;
        minus[c] -= step;
        Vector3<T> bp, bm;
        ASSERT_TRUE(Lift(params.data(), plus, &bp) && Lift(params.data(), minus, &bm));
        const Vector3<T> numeric = (bp - bm) / (T(2) * step);
        for (int r = 0; r < 3; ++r) {
          EXPECT_NEAR(numeric[r], jacobian(r, c), tolerance * 1e-2) << u << " " << v;
        }
      }
      ++tested;
    }
  }
  EXPECT_GT(tested, 100);
}

TEST(UnifiedCamera, LiftJacobianMatchesCentralDifferencesInDouble) {
  CheckLiftJacobian<double>(1e-4, 1e-6);
}

TEST(UnifiedCamera, LiftJacobianMatchesCentralDifferencesInFloat) {
  CheckLiftJacobian<float>(0.25f, 2e-2f);
}

TEST(UnifiedCamera, AgreesWithOpenCvOmnidirWhenK5IsZero) {
  UnifiedIntrinsics camera = HyperbolicCamera();
  camera.k(5) = 0.0;
  const cv::Matx33d K(camera.gamma_u(), camera.gamma_u() * camera.alpha(), camera.u0(), 0,
                      camera.gamma_v(), camera.v0(), 0, 0, 1);
  const cv::Vec4d D(camera.k(1), camera.k(2), camera.k(3), camera.k(4));
  std::vector<cv::Vec3d> points;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  while (points.size() < 500) {
    const cv::Vec3d p(u(rng) * 4, u(rng) * 4, u(rng) * 1.0 + 0.2);
    if (InImage(Project(camera, Eigen::Vector3d(p[0], p[1], p[2])))) points.push_back(p);
  }
  std::vector<cv::Vec2d> cv_pixels;
  cv::omnidir::projectPoints(points, cv_pixels, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K,
                             camera.xi(), D);
  for (size_t i = 0; i < points.size(); ++i) {
    const auto ours = Project(camera, Eigen::Vector3d(points[i][0], points[i][1], points[i][2]));
    EXPECT_NEAR(ours->x(), cv_pixels[i][0], 1e-6);
    EXPECT_NEAR(ours->y(), cv_pixels[i][1], 1e-6);
  }
}

}  // namespace
}  // namespace omnirig
