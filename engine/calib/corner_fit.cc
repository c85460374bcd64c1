#include "engine/calib/corner_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include <ceres/jet.h>
#include <ceres/tiny_solver.h>
#include <Eigen/Dense>

#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

using std::cos;
using std::erf;
using std::exp;
using std::sin;

// Parameter layout of the junction model (see the header).
enum Param { kPx, kPy, kTheta1, kTheta2, kKappa1, kKappa2, kLogS, kMean, kAmp, kGx, kGy, kNum };
using Params = Eigen::Matrix<double, kNum, 1>;
using Jet = ceres::Jet<double, kNum>;

struct Pixel {
  double x, y;  // relative to the start
  double value;
};

// The model's intensity at (x, y), relative to the start, for T = double or Jet.
template <typename T>
struct JunctionModel {
  T px, py, c1, s1, c2, s2, k1, k2, inv_s, mean, amp, gx, gy;

  explicit JunctionModel(const T* q)
      : px(q[kPx]),
        py(q[kPy]),
        c1(cos(q[kTheta1])),
        s1(sin(q[kTheta1])),
        c2(cos(q[kTheta2])),
        s2(sin(q[kTheta2])),
        k1(q[kKappa1]),
        k2(q[kKappa2]),
        inv_s(exp(-q[kLogS])),
        mean(q[kMean]),
        amp(q[kAmp]),
        gx(q[kGx]),
        gy(q[kGy]) {}

  T operator()(double x, double y) const {
    const T dx = x - px, dy = y - py;
    const T a1 = dx * c1 + dy * s1, b1 = dy * c1 - dx * s1;
    const T a2 = dx * c2 + dy * s2, b2 = dy * c2 - dx * s2;
    const T d1 = b1 - 0.5 * k1 * a1 * a1, d2 = b2 - 0.5 * k2 * a2 * a2;
    return mean + gx * dx + gy * dy + amp * PixelErf(d1) * PixelErf(d2);
  }

  // erf(d / s) averaged over a pixel across the edge, (G((d + 1/2) / s) - G((d - 1/2) / s)) s
  // with G' = erf: a pixel integrates the image, and on edges a few tenths of a pixel wide a
  // point sample would make the fit depend on the corner's sub-pixel phase. (A unit square's
  // footprint on any direction has the variance 1/12 of a unit box, which stands in for it.)
  T PixelErf(const T& d) const {
    return (Antiderivative((d + 0.5) * inv_s) - Antiderivative((d - 0.5) * inv_s)) / inv_s;
  }
  static T Antiderivative(const T& z) { return z * erf(z) + exp(-z * z) / std::sqrt(M_PI); }
};

// The model's value and analytic gradient for T = double (the Jet instantiation costs several
// times more per pixel; the test checks the two against each other). With
// E(d) = s (G((d + 1/2) / s) - G((d - 1/2) / s)): dE/dd = erf(z+) - erf(z-) and
// dE/dlog s = s dE/ds = (exp(-z+^2) - exp(-z-^2)) s / sqrt(pi), z+- = (d +- 1/2) / s.
double ValueAndGradient(const JunctionModel<double>& m, double x, double y, Params* gradient) {
  const double dx = x - m.px, dy = y - m.py;
  const double s = 1.0 / m.inv_s;
  const double a1 = dx * m.c1 + dy * m.s1, b1 = dy * m.c1 - dx * m.s1;
  const double a2 = dx * m.c2 + dy * m.s2, b2 = dy * m.c2 - dx * m.s2;
  const double d1 = b1 - 0.5 * m.k1 * a1 * a1, d2 = b2 - 0.5 * m.k2 * a2 * a2;
  // E, dE/dd and dE/dlog s of one edge.
  auto edge = [&](double d, double* e, double* de_dd, double* de_dlogs) {
    const double zp = (d + 0.5) * m.inv_s, zm = (d - 0.5) * m.inv_s;
    const double erf_p = std::erf(zp), erf_m = std::erf(zm);
    const double exp_p = std::exp(-zp * zp), exp_m = std::exp(-zm * zm);
    constexpr double kInvSqrtPi = 0.5641895835477563;
    *e = s * ((zp * erf_p + exp_p * kInvSqrtPi) - (zm * erf_m + exp_m * kInvSqrtPi));
    *de_dd = erf_p - erf_m;
    *de_dlogs = s * (exp_p - exp_m) * kInvSqrtPi;
  };
  double e1, e1_d, e1_s, e2, e2_d, e2_s;
  edge(d1, &e1, &e1_d, &e1_s);
  edge(d2, &e2, &e2_d, &e2_s);
  const double g1 = m.amp * e1_d * e2, g2 = m.amp * e1 * e2_d;  // dM/dd1, dM/dd2
  Params& g = *gradient;
  // d d_k / d px = s_k + kappa_k a_k c_k, d d_k / d py = -c_k + kappa_k a_k s_k,
  // d d_k / d theta_k = -a_k - kappa_k a_k b_k, d d_k / d kappa_k = -a_k^2 / 2.
  g[kPx] = -m.gx + g1 * (m.s1 + m.k1 * a1 * m.c1) + g2 * (m.s2 + m.k2 * a2 * m.c2);
  g[kPy] = -m.gy + g1 * (-m.c1 + m.k1 * a1 * m.s1) + g2 * (-m.c2 + m.k2 * a2 * m.s2);
  g[kTheta1] = g1 * (-a1 - m.k1 * a1 * b1);
  g[kTheta2] = g2 * (-a2 - m.k2 * a2 * b2);
  g[kKappa1] = g1 * (-0.5 * a1 * a1);
  g[kKappa2] = g2 * (-0.5 * a2 * a2);
  g[kLogS] = m.amp * (e1_s * e2 + e1 * e2_s);
  g[kMean] = 1.0;
  g[kAmp] = e1 * e2;
  g[kGx] = dx;
  g[kGy] = dy;
  return m.mean + m.gx * dx + m.gy * dy + m.amp * e1 * e2;
}

double Bilinear(const cv::Mat& image, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  auto at = [&](int u, int v) { return static_cast<double>(image.at<uint8_t>(v, u)); };
  return (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) +
         fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
}

// The two edges' direction angles from the four light/dark transitions on a circle of radius
// `rho` around `center`: edge 1 passes the first and third transition, edge 2 the others.
std::optional<std::array<double, 2>> EdgeAngles(const cv::Mat& image, const Eigen::Vector2d& center,
                                                double rho) {
  constexpr int kSamples = 72;
  std::array<double, kSamples> values;
  for (int i = 0; i < kSamples; ++i) {
    const double angle = 2.0 * M_PI * i / kSamples;
    values[i] =
        Bilinear(image, center.x() + rho * std::cos(angle), center.y() + rho * std::sin(angle));
  }
  const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  if (*hi - *lo < 20.0) return std::nullopt;
  const double threshold = 0.5 * (*hi + *lo);
  std::vector<double> crossings;
  for (int i = 0; i < kSamples; ++i) {
    const double v0 = values[i] - threshold, v1 = values[(i + 1) % kSamples] - threshold;
    if ((v0 > 0) == (v1 > 0)) continue;
    const double t = v0 / (v0 - v1);
    crossings.push_back(2.0 * M_PI * (i + t) / kSamples);
  }
  if (crossings.size() != 4) return std::nullopt;
  return std::array<double, 2>{0.5 * (crossings[0] + crossings[2] - M_PI),
                               0.5 * (crossings[1] + crossings[3] - M_PI)};
}

// The residuals model - value over the disc's pixels and their analytic Jacobian, as
// ceres::TinySolver takes them.
struct JunctionResiduals {
  using Scalar = double;
  enum { NUM_RESIDUALS = Eigen::Dynamic, NUM_PARAMETERS = kNum };

  const std::vector<Pixel>* pixels;

  int NumResiduals() const { return static_cast<int>(pixels->size()); }

  // `jacobian` is column-major (residual, parameter), or null.
  bool operator()(const double* q, double* residuals, double* jacobian) const {
    const JunctionModel<double> model(q);
    const int n = NumResiduals();
    Params gradient;
    for (int i = 0; i < n; ++i) {
      const Pixel& pixel = (*pixels)[i];
      residuals[i] = ValueAndGradient(model, pixel.x, pixel.y, &gradient) - pixel.value;
      if (jacobian == nullptr) continue;
      for (int j = 0; j < kNum; ++j) jacobian[i + j * n] = gradient[j];
    }
    return true;
  }
};

// Mean and amplitude by linear least squares with the geometry of q fixed.
void FitLevels(const std::vector<Pixel>& pixels, Params* q) {
  (*q)[kMean] = 0.0;
  (*q)[kAmp] = 1.0;
  (*q)[kGx] = (*q)[kGy] = 0.0;
  const JunctionModel<double> shape(q->data());
  Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
  Eigen::Vector2d atb = Eigen::Vector2d::Zero();
  for (const Pixel& pixel : pixels) {
    const Eigen::Vector2d a(1.0, shape(pixel.x, pixel.y));
    ata += a * a.transpose();
    atb += a * pixel.value;
  }
  const Eigen::Vector2d levels = ata.ldlt().solve(atb);
  (*q)[kMean] = levels[0];
  (*q)[kAmp] = levels[1];
}

// Levenberg-Marquardt on the model; false when it does not settle.
bool Solve(const std::vector<Pixel>& pixels, int max_iterations, Params* q) {
  ceres::TinySolver<JunctionResiduals> solver;
  solver.options.max_num_iterations = max_iterations;
  const auto& summary = solver.Solve(JunctionResiduals{&pixels}, q);
  return summary.status != ceres::TinySolver<JunctionResiduals>::HIT_MAX_ITERATIONS;
}

}  // namespace

namespace internal {

double CornerModelForTest(const std::array<double, 11>& params, double x, double y, bool use_jets,
                          std::array<double, 11>* gradient) {
  static_assert(kNum == 11, "the test hook's parameter count");
  if (use_jets) {
    std::array<Jet, kNum> jets;
    for (int i = 0; i < kNum; ++i) jets[i] = Jet(params[i], i);
    const Jet value = JunctionModel<Jet>(jets.data())(x, y);
    for (int i = 0; i < kNum; ++i) (*gradient)[i] = value.v[i];
    return value.a;
  }
  Params q, g;
  for (int i = 0; i < kNum; ++i) q[i] = params[i];
  const double value = ValueAndGradient(JunctionModel<double>(q.data()), x, y, &g);
  for (int i = 0; i < kNum; ++i) (*gradient)[i] = g[i];
  return value;
}

}  // namespace internal

void CornerFitOptions::Check() const {
  OMNIRIG_CHECK_AT_LEAST(max_radius_px, 3);
  OMNIRIG_CHECK_AT_LEAST(max_iterations, 1);
  OMNIRIG_CHECK_POSITIVE(max_shift_px);
}

std::optional<Eigen::Vector2d> FitCheckerCorner(const cv::Mat& image,
                                                const Eigen::Vector2d& start_px, double radius_px,
                                                const CornerFitOptions& options) {
  options.Check();
  OMNIRIG_CHECK(image.type() == CV_8UC1, "corner fit: needs an 8-bit grey image");
  const double radius = std::min(radius_px, options.max_radius_px);
  // Below a radius of 3 px the disc holds fewer than 30 pixels for 11 parameters (and the edges'
  // sag over cornerSubPix's equally small window is negligible).
  if (!(radius >= 3.0) || !start_px.allFinite()) return std::nullopt;
  if (start_px.x() - radius < 1 || start_px.y() - radius < 1 ||
      start_px.x() + radius > image.cols - 2 || start_px.y() + radius > image.rows - 2) {
    return std::nullopt;
  }
  const auto angles = EdgeAngles(image, start_px, 0.65 * radius);
  if (!angles) return std::nullopt;
  std::vector<Pixel> pixels;
  const int u0 = static_cast<int>(std::ceil(start_px.x() - radius));
  const int v0 = static_cast<int>(std::ceil(start_px.y() - radius));
  for (int v = v0; v <= start_px.y() + radius; ++v) {
    for (int u = u0; u <= start_px.x() + radius; ++u) {
      const double x = u - start_px.x(), y = v - start_px.y();
      if (x * x + y * y > radius * radius) continue;
      pixels.push_back({x, y, static_cast<double>(image.at<uint8_t>(v, u))});
    }
  }
  Params q = Params::Zero();
  q[kTheta1] = (*angles)[0];
  q[kTheta2] = (*angles)[1];
  q[kLogS] = 0.0;  // a blur width of 1 px
  FitLevels(pixels, &q);
  // The curvatures are fitted at every radius: even where the sag over a small disc is a few
  // hundredths of a pixel, straight model edges would pull the corner to the concave side by
  // about that much (bench_detect_bias, sag < 0.02 px: -0.004 px radially), at the price of a
  // somewhat larger random error there.
  if (!Solve(pixels, options.max_iterations, &q)) return std::nullopt;
  const Eigen::Vector2d shift(q[kPx], q[kPy]);
  const double blur = std::exp(q[kLogS]);
  if (!q.allFinite() || shift.norm() > options.max_shift_px || !(blur > 0.05 && blur < radius) ||
      !(std::abs(q[kAmp]) > 5.0)) {
    return std::nullopt;
  }
  return start_px + shift;
}

}  // namespace omnirig
