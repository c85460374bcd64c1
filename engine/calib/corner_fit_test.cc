#include "engine/calib/corner_fit.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// A checkerboard X-junction at `corner` whose two edges are circular arcs through it (direction
// angles theta, curvatures kappa; kappa = 0 gives a straight edge), at the renderer's grey
// levels and blurred like the renders (0.5 px). Pixels near an edge are the mean of 16 x 16
// samples in a rook pattern (256 distinct rows and columns, so an axis-aligned edge is placed to
// 1/256 px). Circles, not the fit's parabolas, so that the test does not draw the fitted model.
cv::Mat DrawJunction(const Eigen::Vector2d& corner, const double theta[2], const double kappa[2],
                     int size = 41) {
  // Signed distance to edge k, positive on the side of its normal (the concave side).
  auto distance = [&](int k, const Eigen::Vector2d& x) {
    const Eigen::Vector2d normal(-std::sin(theta[k]), std::cos(theta[k]));
    if (kappa[k] == 0.0) return normal.dot(x - corner);
    const Eigen::Vector2d centre = corner + normal / kappa[k];
    return (1.0 / std::abs(kappa[k]) - (x - centre).norm()) * (kappa[k] > 0 ? 1.0 : -1.0);
  };
  auto level = [&](const Eigen::Vector2d& x) {
    return (distance(0, x) > 0.0) == (distance(1, x) > 0.0) ? 235.0 : 25.0;
  };
  cv::Mat image(size, size, CV_32F);
  constexpr int kSub = 16;
  constexpr int kSamples = kSub * kSub;
  for (int v = 0; v < size; ++v) {
    for (int u = 0; u < size; ++u) {
      const Eigen::Vector2d centre(u, v);
      double value = level(centre);
      if (std::abs(distance(0, centre)) < 1.0 || std::abs(distance(1, centre)) < 1.0) {
        double sum = 0.0;
        for (int a = 0; a < kSub; ++a) {
          for (int b = 0; b < kSub; ++b) {
            const double fx = (a * kSub + b + 0.5) / kSamples, fy = (b * kSub + a + 0.5) / kSamples;
            sum += level(Eigen::Vector2d(u - 0.5 + fx, v - 0.5 + fy));
          }
        }
        value = sum / kSamples;
      }
      image.at<float>(v, u) = static_cast<float>(value);
    }
  }
  cv::GaussianBlur(image, image, cv::Size(0, 0), 0.5, 0.0, cv::BORDER_REPLICATE);
  cv::Mat grey;
  image.convertTo(grey, CV_8U);
  return grey;
}

Eigen::Vector2d CornerSubPix(const cv::Mat& image, const Eigen::Vector2d& start, int half) {
  std::vector<cv::Point2f> point = {
      cv::Point2f(static_cast<float>(start.x()), static_cast<float>(start.y()))};
  cv::cornerSubPix(image, point, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 1e-3));
  return Eigen::Vector2d(point[0].x, point[0].y);
}

// Curved edges as a mirror bends them (sag over the window 0.05-0.2 px): cornerSubPix is pulled
// to the convex side of both edges, the fit is not.
TEST(CornerFit, UnbiasedOnCurvedEdgesWhereCornerSubPixIsNot) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  constexpr int kHalf = 8;
  double subpix_convex = 0.0, fit_convex = 0.0, fit_max = 0.0;
  constexpr int kCases = 12;
  for (int i = 0; i < kCases; ++i) {
    const Eigen::Vector2d corner(20.0 + uniform(rng), 20.0 + uniform(rng));
    const double theta[2] = {uniform(rng) * M_PI, 0.0};
    const double angle = 1.1 + 0.9 * uniform(rng);  // 63 to 115 degrees between the edges
    const double theta_2[2] = {theta[0], theta[0] + angle};
    const double kappa[2] = {0.002 + 0.004 * uniform(rng), 0.002 + 0.004 * uniform(rng)};
    const cv::Mat image = DrawJunction(corner, theta_2, kappa);
    // The mean of the two edges' concave normals: both biases project onto it positively.
    Eigen::Vector2d concave = Eigen::Vector2d::Zero();
    for (int k = 0; k < 2; ++k)
      concave += Eigen::Vector2d(-std::sin(theta_2[k]), std::cos(theta_2[k]));
    concave.normalize();
    const Eigen::Vector2d start = corner + Eigen::Vector2d(0.3, -0.2);
    const Eigen::Vector2d subpix = CornerSubPix(image, start, kHalf);
    const auto fitted = FitCheckerCorner(image, subpix, kHalf);
    ASSERT_TRUE(fitted.has_value()) << "case " << i;
    subpix_convex -= (subpix - corner).dot(concave) / kCases;
    fit_convex -= (*fitted - corner).dot(concave) / kCases;
    fit_max = std::max(fit_max, (*fitted - corner).norm());
  }
  std::printf("mean error to the convex side: cornerSubPix %.4f px, fit %.4f px\n", subpix_convex,
              fit_convex);
  EXPECT_GT(subpix_convex, 0.03);  // the bias this fit exists for
  EXPECT_LT(std::abs(fit_convex), 0.005);
  EXPECT_LT(fit_max, 0.03);  // the sub-pixel phase error of StraightEdgesAtAnySubpixelPhase
}

// Straight edges at several sub-pixel phases and angles: the fit's error is what the model's
// Gaussian blur does not describe of the image's (a box-filtered pixel and a discrete 0.5 px
// blur), zero-mean over the phases and well below cornerSubPix's on the same images.
TEST(CornerFit, StraightEdgesAtAnySubpixelPhase) {
  double fit_sq = 0.0, subpix_sq = 0.0, fit_max = 0.0;
  Eigen::Vector2d fit_sum = Eigen::Vector2d::Zero();
  int n = 0;
  for (const double dx : {0.0, 0.25, 0.5, 0.8}) {
    for (const double angle : {M_PI / 2, 1.7}) {
      for (const double theta : {0.0, 0.4}) {
        const Eigen::Vector2d corner(20.0 + dx, 19.6 + 0.5 * dx);
        const double thetas[2] = {theta, theta + angle};
        const double kappa[2] = {0.0, 0.0};
        const cv::Mat image = DrawJunction(corner, thetas, kappa);
        const Eigen::Vector2d start = corner + Eigen::Vector2d(-0.4, 0.3);
        const auto fitted = FitCheckerCorner(image, start, 6.0);
        ASSERT_TRUE(fitted.has_value()) << dx << " " << angle << " " << theta;
        const Eigen::Vector2d error = *fitted - corner;
        fit_sum += error;
        fit_sq += error.squaredNorm();
        fit_max = std::max(fit_max, error.norm());
        subpix_sq += (CornerSubPix(image, start, 6) - corner).squaredNorm();
        ++n;
      }
    }
  }
  EXPECT_LT(std::sqrt(fit_sq / n), 0.02);
  EXPECT_LT(std::sqrt(fit_sq / n), 0.6 * std::sqrt(subpix_sq / n));
  EXPECT_LT(fit_max, 0.03);
  EXPECT_LT((fit_sum / n).norm(), 0.006);
}

// The fit's hand-written Jacobian against Ceres Jets, at curved edges, blur and shading, on and
// off the edges.
TEST(CornerFit, AnalyticJacobianMatchesJets) {
  const std::array<double, 11> params = {0.13,          -0.21, 0.4,   2.0, 0.01, -0.02,
                                         std::log(0.8), 128.0, -95.0, 0.3, -0.2};
  for (const auto& [x, y] :
       {std::pair{0.0, 0.0}, {0.5, -0.3}, {-2.0, 1.2}, {3.0, 2.5}, {-4.1, -0.7}, {1.7, -3.9}}) {
    std::array<double, 11> analytic{}, jets{};
    const double value = internal::CornerModelForTest(params, x, y, false, &analytic);
    EXPECT_NEAR(value, internal::CornerModelForTest(params, x, y, true, &jets), 1e-9);
    for (int i = 0; i < 11; ++i) {
      EXPECT_NEAR(analytic[i], jets[i], 1e-9 * (1.0 + std::abs(jets[i])))
          << "parameter " << i << " at " << x << ", " << y;
    }
  }
}

TEST(CornerFit, RefusesWhatIsNotAnXJunction) {
  const cv::Mat flat(41, 41, CV_8U, cv::Scalar(128));
  EXPECT_FALSE(FitCheckerCorner(flat, Eigen::Vector2d(20, 20), 8.0).has_value());
  // A single straight edge: two transitions around the start, not four.
  cv::Mat edge(41, 41, CV_8U, cv::Scalar(25));
  edge.colRange(20, 41).setTo(235);
  EXPECT_FALSE(FitCheckerCorner(edge, Eigen::Vector2d(20, 20), 8.0).has_value());
  // Too close to the image border for its disc.
  const double theta[2] = {0.0, M_PI / 2};
  const double kappa[2] = {0.0, 0.0};
  const cv::Mat junction = DrawJunction(Eigen::Vector2d(20, 20), theta, kappa);
  EXPECT_FALSE(FitCheckerCorner(junction, Eigen::Vector2d(3, 20), 8.0).has_value());
  EXPECT_THROW(FitCheckerCorner(cv::Mat(5, 5, CV_32F), Eigen::Vector2d(2, 2), 2.0),
               InvalidArgument);
}

}  // namespace
}  // namespace omnirig
