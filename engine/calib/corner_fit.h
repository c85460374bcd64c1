#pragma once
// Sub-pixel position of a checkerboard corner by fitting a model of the blurred X-junction to the
// pixels around it.
//
// Why: cv::cornerSubPix finds the point to which the intensity gradients in its window are
// orthogonal. On straight edges that point is the corner; where a mirror bends the board's edges
// (the image of a board line is a conic), the tangent at an edge pixel a distance a from the
// corner passes the corner at kappa a^2 / 2 on the convex side, and the estimate is pulled to the
// convex side of both edges: on a catadioptric image, radially outward, by about half the edges'
// sag over the window (+0.02 px on average over the synthetic 1024x768 renders, up to 0.09 px
// where the edges bend most; bench_detect_bias). The model here bends its edges, so the
// curvature no longer moves the corner (-0.0002 px radially on the same renders).
//
// Model (pixel centres at integer coordinates, as everywhere in omnirig): around the corner p,
// each edge k is a parabola through p with direction angle theta_k and curvature kappa_k; with
// a_k, b_k the coordinates of x - p along and across the edge, its signed distance is
// d_k = b_k - kappa_k a_k^2 / 2 and the intensity is
//   I(x) = m + g . (x - p) + h E(d_1) E(d_2),   E(d) = erf(d / s) averaged over the pixel,
// a checkerboard X-junction blurred to the width s, with a linear shading term g. The 11
// parameters are fitted by Levenberg-Marquardt (ceres::TinySolver; analytic Jacobian, tested
// against Jets) to the pixels in a disc. What remains is a zero-mean dependence on the corner's
// sub-pixel phase where the real blur is not a Gaussian: 0.021 px RMS on the noise-free renders
// with 0.5 px blur, against 0.048 px for cornerSubPix. Without any blur (box-filtered pixels
// only) a small radial bias of +0.003-0.005 px remains, a fifth of cornerSubPix's.

#include <array>
#include <optional>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace omnirig {

struct CornerFitOptions {
  // Radius of the disc of pixels fitted, at most (the caller's window may be smaller).
  double max_radius_px = 8.0;
  // Levenberg-Marquardt iterations (ceres::TinySolver's, rejected steps included); the hardest
  // corners of the synthetic renders take about 50.
  int max_iterations = 100;
  // A fit that moves the corner further than this from the start is rejected.
  double max_shift_px = 1.0;

  void Check() const;
};

// The fitted corner near `start_px` in the 8-bit grey `image`, using the pixels within
// min(radius_px, max_radius_px) of the start; nullopt when that radius is below 3 px, the
// neighbourhood does not look like an X-junction (not four light/dark transitions around it),
// the fit does not converge, or it moves the corner by more than max_shift_px (the caller keeps
// its own estimate then).
std::optional<Eigen::Vector2d> FitCheckerCorner(
    const cv::Mat& image, const Eigen::Vector2d& start_px, double radius_px,
    const CornerFitOptions& options = CornerFitOptions());

namespace internal {

// The fitted model's intensity at (x, y) (relative to the start) for parameters (p_x, p_y,
// theta_1, theta_2, kappa_1, kappa_2, log s, m, h, g_x, g_y), with its gradient from the analytic
// derivatives the fit uses or, with use_jets, from Ceres Jets: for the test of the former.
double CornerModelForTest(const std::array<double, 11>& params, double x, double y, bool use_jets,
                          std::array<double, 11>* gradient);

}  // namespace internal
}  // namespace omnirig
