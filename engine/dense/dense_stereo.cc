#include "engine/dense/dense_stereo.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <optional>
#include <tuple>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/features/image.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"
#include "engine/util/timer.h"

namespace omnirig::dense {
namespace {

// The columns [first, last] where either mask holds a cell; empty (first > last) when none.
std::pair<int, int> UsedColumns(const cv::Mat& mask0, const cv::Mat& mask1) {
  cv::Mat any;
  cv::bitwise_or(mask0, mask1, any);
  cv::Mat column_max;
  cv::reduce(any, column_max, 0, cv::REDUCE_MAX);
  int first = column_max.cols, last = -1;
  for (int c = 0; c < column_max.cols; ++c) {
    if (column_max.at<uint8_t>(0, c)) {
      first = std::min(first, c);
      last = c;
    }
  }
  return {first, last};
}

// Semi-global matching of the grid rows: cam0 is the left image (see spherical_rectification.h).
// The images are padded with wrapped rows above and below (the azimuth is periodic, so the
// matcher's vertical paths see across the 0/360 degree seam) and with num_disparities blank
// columns on the left (the matcher leaves its left border undecided). Returns SGBM's disparity
// (CV_16S in 1/16 cells, negative where none) over the input's size.
cv::Mat MatchRows(const cv::Mat& left, const cv::Mat& right, int num_disparities,
                  const DenseStereoOptions& o) {
  const int wrap = std::min(32, left.rows / 2);
  cv::Mat l, r;
  cv::copyMakeBorder(left, l, wrap, wrap, 0, 0, cv::BORDER_WRAP);
  cv::copyMakeBorder(right, r, wrap, wrap, 0, 0, cv::BORDER_WRAP);
  cv::copyMakeBorder(l, l, 0, 0, num_disparities, 0, cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::copyMakeBorder(r, r, 0, 0, num_disparities, 0, cv::BORDER_CONSTANT, cv::Scalar(0));
  const int w2 = o.block_size * o.block_size;
  cv::Ptr<cv::StereoSGBM> sgbm = cv::StereoSGBM::create(
      0, num_disparities, o.block_size, o.smoothness_p1 * w2, o.smoothness_p2 * w2,
      o.left_right_max_diff_cells, 63,
      o.uniqueness_ratio, o.speckle_window_cells, o.speckle_range_cells,
      cv::StereoSGBM::MODE_SGBM_3WAY);
  cv::Mat disparity16;
  sgbm->compute(l, r, disparity16);
  return disparity16(cv::Rect(num_disparities, wrap, left.cols, left.rows));
}

// cam1's grey level at each cell's match (linear between the two cells around it, as SGBM's
// sub-pixel disparity has 1/16 cells; 0 where there is none), for the correlation of the
// matched windows. `right` is CV_8U, disparity16 MatchRows' output of the same size.
cv::Mat MatchedGrey(const cv::Mat& right, const cv::Mat& disparity16) {
  cv::Mat matched(disparity16.size(), CV_32F);
  cv::parallel_for_(cv::Range(0, matched.rows), [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r) {
      const int16_t* d = disparity16.ptr<int16_t>(r);
      const uint8_t* grey = right.ptr<uint8_t>(r);
      float* out = matched.ptr<float>(r);
      for (int c = 0; c < matched.cols; ++c) {
        const int x16 = 16 * c - d[c];  // the match's column, 1/16 cells
        if (d[c] < 0 || x16 < 0) {
          out[c] = 0.f;
          continue;
        }
        const int x = x16 >> 4;
        const float t = static_cast<float>(x16 & 15) * (1.f / 16.f);
        const float next = x + 1 < matched.cols ? grey[x + 1] : 0.f;
        out[c] = (1.f - t) * grey[x] + t * next;
      }
    }
  });
  return matched;
}

// How far (cells) the window's mean disparity may lie from a cell's own for the refinement's
// step to be added to it (RefineDisparity). Chosen on the development renders (bench_dense
// --development-only, 2 pairs, 2026-12-08): 0.25, 0.5, 1 and 2 cells gave medians of 0.219,
// 0.218, 0.219 and 0.219 % of range on the room and 0.283, 0.280, 0.281 and 0.283 % on the
// noisy room, within 1 % 91.5, 91.4, 91.0 and 90.6 % and 88.4, 88.6, 88.2 and 87.8 %; the step
// added to the cell's own disparity, 0.311 % / 89.2 % and 0.388 % / 84.4 %.
constexpr float kMaxWindowDisparityShiftCells = 0.5f;

// Sub-cell refinement of SGBM's disparity on the rectified images themselves. SGBM's sub-pixel
// step (a parabola through its aggregated costs) draws disparities towards whole cells (pixel
// locking: bench_dense measures it). Each matched cell's disparity d takes one Gauss-Newton
// step of a 1-D Lucas-Kanade fit along its row: the window of cam0 around the cell against
// cam1's window at columns c - d (bicubic), with both windows' mean removed and cam1's scaled
// to cam0's contrast (the two cameras see a point at other image radii, hence other
// vignetting). The windows are box sums over the images, each cell warping its own sample by
// its own disparity (the disparity is taken as constant over a window, as SGBM does). The step
// so found is the window's mean misalignment (each sample weighted by its gradient energy), so
// it is added to the window's mean disparity (the plain mean of its matched cells' SGBM
// disparities: on a slanted surface a symmetric window's mean is the centre's disparity, where
// a mean weighted by the gradients is not), not to the cell's own: SGBM's cell-to-cell scatter
// is averaged away. Where that mean is more than kMaxWindowDisparityShiftCells from the cell's
// disparity (a depth edge in the window) the step is added to the cell's own. One step: from
// the cell's own disparity further steps made the median error grow again (bench_dense: 0.344 %
// of range after one step, 0.40-0.54 % after two to four, 0.530 % without); from the window's
// mean they lower the median but not the share within 1 %, for the refinement's time again
// each (docs/dense.md). Returns the disparity in cells (CV_32F, -1 where none) and each cell's
// least-squares std (cells): the fit's residual variance over its gradient energy (0 without
// the refinement).
struct RefinedDisparity {
  cv::Mat disparity, std_cells;
};

// Runs fn(0) .. fn(num - 1) on OpenCV's threads: independent image-wide filters, each serial in
// OpenCV (box filters and remaps nested in a parallel region run on their calling thread).
void ParallelTasks(int num, const std::function<void(int)>& fn) {
  cv::parallel_for_(cv::Range(0, num), [&](const cv::Range& tasks) {
    for (int i = tasks.start; i < tasks.end; ++i) fn(i);
  }, num);
}

RefinedDisparity RefineDisparity(const cv::Mat& left, const cv::Mat& right,
                                 const cv::Mat& disparity16, const DenseStereoOptions& o) {
  const cv::Size size = left.size();
  const cv::Size window(o.refine_window_cells, o.refine_window_cells);
  const float n = static_cast<float>(window.area());
  cv::Mat sgbm(size, CV_32F), map_x(size, CV_32F), map_y(size, CV_32F);
  // 1 where SGBM matched, and its disparity (1/16 cells) there, else 0: their window sums
  // (integer, exact) give the window's mean disparity over its matched cells.
  cv::Mat matched(size, CV_8U), matched_disparity16(size, CV_16S);
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r) {
      const int16_t* d = disparity16.ptr<int16_t>(r);
      float* sg = sgbm.ptr<float>(r);
      float* mx = map_x.ptr<float>(r);
      float* my = map_y.ptr<float>(r);
      uint8_t* m = matched.ptr<uint8_t>(r);
      int16_t* md = matched_disparity16.ptr<int16_t>(r);
      for (int c = 0; c < size.width; ++c) {
        sg[c] = d[c] > 0 ? d[c] / 16.f : -1.f;
        mx[c] = d[c] > 0 ? c - sg[c] : static_cast<float>(c);
        my[c] = static_cast<float>(r);
        m[c] = d[c] > 0 ? 1 : 0;
        md[c] = d[c] > 0 ? d[c] : 0;
      }
    }
  });
  RefinedDisparity out{sgbm.clone(), cv::Mat::zeros(size, CV_32F)};
  if (!o.refine_subcell) return out;
  // cam1 warped by each cell's disparity (bicubic) and its gradient along the row, then the
  // windows' sums of the products the fit needs: each filter on a thread of its own.
  cv::Mat w, g;
  ParallelTasks(2, [&](int i) {
    if (i == 0) {
      cv::remap(right, w, map_x, map_y, cv::INTER_CUBIC, cv::BORDER_REPLICATE);
    } else {
      cv::Mat right_dx;
      cv::Sobel(right, right_dx, CV_32F, 1, 0, 1, 0.5);  // central difference
      cv::remap(right_dx, g, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    }
  });
  cv::Mat mean_l, mean_ll, mw, mg, mww, mgg, mgw, mgl, mwl, num_matched, sum_matched_d16;
  const std::array<std::tuple<cv::Mat*, const cv::Mat*, const cv::Mat*>, 9> sums = {{
      {&mean_l, &left, nullptr}, {&mean_ll, &left, &left}, {&mw, &w, nullptr},
      {&mg, &g, nullptr}, {&mww, &w, &w}, {&mgg, &g, &g}, {&mgw, &g, &w}, {&mgl, &g, &left},
      {&mwl, &w, &left}}};
  ParallelTasks(static_cast<int>(sums.size()) + 2, [&](int i) {
    if (i == static_cast<int>(sums.size())) {
      cv::boxFilter(matched, num_matched, CV_32S, window, cv::Point(-1, -1), false);
    } else if (i > static_cast<int>(sums.size())) {
      cv::boxFilter(matched_disparity16, sum_matched_d16, CV_32S, window, cv::Point(-1, -1),
                    false);
    } else {
      const auto [sum, a, b] = sums[i];
      cv::boxFilter(b ? a->mul(*b) : *a, *sum, CV_32F, window);
    }
  });
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r) {
      const float* sg = sgbm.ptr<float>(r);
      float* d = out.disparity.ptr<float>(r);
      for (int c = 0; c < size.width; ++c) {
        if (!(sg[c] > 0.f)) continue;
        const float ml = mean_l.at<float>(r, c), m_w = mw.at<float>(r, c);
        const float m_g = mg.at<float>(r, c);
        const float var_l = std::max(0.f, mean_ll.at<float>(r, c) - ml * ml);
        const float var_w = std::max(0.f, mww.at<float>(r, c) - m_w * m_w);
        const float var_g = mgg.at<float>(r, c) - m_g * m_g;
        if (!(var_g > 1e-3f) || !(var_w > 1e-3f)) continue;
        const float a = std::sqrt((var_l + 1e-3f) / (var_w + 1e-3f));
        const float cov_gw = mgw.at<float>(r, c) - m_g * m_w;
        const float cov_gl = mgl.at<float>(r, c) - m_g * ml;
        const float step = std::clamp((a * cov_gw - cov_gl) / (a * var_g), -0.5f, 0.5f);
        // The step is the window's mean misalignment: it corrects the window's mean disparity,
        // which SGBM's cell-to-cell scatter does not move as it moves the cell's own.
        // (Cell c is matched itself, so the count is at least 1.)
        const float window_disparity = static_cast<float>(sum_matched_d16.at<int32_t>(r, c)) /
                                       (16.f * static_cast<float>(num_matched.at<int32_t>(r, c)));
        if (std::abs(window_disparity - d[c]) <= kMaxWindowDisparityShiftCells) {
          d[c] = window_disparity;
        }
        d[c] += step;
        // Residual per sample of the fit at SGBM's disparity, less what the step explains.
        const float cov_wl = mwl.at<float>(r, c) - m_w * ml;
        const float energy = a * a * var_g;
        const float residual =
            std::max(0.f, a * a * var_w + var_l - 2.f * a * cov_wl - step * step * energy);
        out.std_cells.at<float>(r, c) = std::sqrt(residual / (n * energy));
      }
    }
  });
  return out;
}

void CheckPairImages(const StereoRig& rig, const cv::Mat& image0, const cv::Mat& image1) {
  CheckPairSizes(rig, image0.cols, image0.rows, image1.cols, image1.rows);
  CheckGreyOrBgr8(image0);
  CheckGreyOrBgr8(image1);
}

}  // namespace

void DenseStereoOptions::Check() const {
  grid.Check();
  OMNIRIG_CHECK_IN(max_parallax_deg, '(', 0, 45, ']');
  OMNIRIG_CHECK(block_size >= 1 && block_size <= 11 && block_size % 2 == 1,
                "block_size must be odd and in [1, 11], got " << block_size);
  OMNIRIG_CHECK(smoothness_p1 >= 1 && smoothness_p2 > smoothness_p1,
                "smoothness_p1 must be at least 1 and smoothness_p2 above it, got "
                    << smoothness_p1 << " and " << smoothness_p2);
  OMNIRIG_CHECK_IN(uniqueness_ratio, '[', 0, 100, ']');
  OMNIRIG_CHECK_NON_NEGATIVE(speckle_window_cells);
  OMNIRIG_CHECK(refine_window_cells >= 3 && refine_window_cells <= 31 &&
                    refine_window_cells % 2 == 1,
                "refine_window_cells must be odd and in [3, 31], got " << refine_window_cells);
  OMNIRIG_CHECK_IN(speckle_range_cells, '[', 1, 16, ']');
  OMNIRIG_CHECK_IN(left_right_max_diff_cells, '[', 0, 16, ']');
  OMNIRIG_CHECK(
      confidence_window_cells >= 3 && confidence_window_cells <= 31 &&
          confidence_window_cells % 2 == 1,
      "confidence_window_cells must be odd and in [3, 31], got " << confidence_window_cells);
  OMNIRIG_CHECK_IN(image_noise_grey, '[', 0, 50, ']');
  OMNIRIG_CHECK_IN(min_confidence, '[', 0, 1, ')');
  OMNIRIG_CHECK_POSITIVE(disparity_std_cells);
  OMNIRIG_CHECK_NON_NEGATIVE(disparity_std_scale);
  OMNIRIG_CHECK_POSITIVE(max_relative_range_std);
  OMNIRIG_CHECK_IN(dark_level, '[', 0, 255, ')');
  OMNIRIG_CHECK_IN(mask_margin_cells, '[', 0, 100, ']');
  OMNIRIG_CHECK_NON_NEGATIVE(epipolar_samples);
  OMNIRIG_CHECK_IN(epipolar_search_rows, '[', 1, 16, ']');
  OMNIRIG_CHECK_POSITIVE(max_epipolar_offset_cells);
}

MirrorMaskOptions DenseStereoOptions::MaskOptions() const {
  MirrorMaskOptions mask;
  mask.shape = MirrorMaskOptions::Shape::kDarkRowEnds;
  mask.dark_level = dark_level;
  mask.margin_px = mask_margin_cells;
  return mask;
}

namespace {
constexpr int kEpipolarHalfWindow = 5;  // 11 x 11 windows

// EpipolarOffset's sample at cam0's cell (r, c), inside the images by the search's margin: the
// distance (cells) of its best match in cam1, over the disparity range and `search` rows either
// side, from row r; none when the window is textureless or the best match is not clear.
std::optional<double> RowOffset(const cv::Mat& grey0, const cv::Mat& grey1, int r, int c,
                                int num_disparities, int search) {
  constexpr int kHalf = kEpipolarHalfWindow;
  constexpr double kMinCorrelation = 0.8;  // a clear match
  constexpr double kMinTextureGrey = 8.0;  // window standard deviation
  const cv::Rect window(c - kHalf, r - kHalf, 2 * kHalf + 1, 2 * kHalf + 1);
  cv::Scalar mean, deviation;
  cv::meanStdDev(grey0(window), mean, deviation);
  if (deviation[0] < kMinTextureGrey) return std::nullopt;
  // cam1's match of column c lies at c - d, d in [0, num_disparities).
  const int left = std::max(0, c - num_disparities - kHalf);
  const cv::Rect area(left, r - search - kHalf, c + kHalf + 1 - left, 2 * (search + kHalf) + 1);
  cv::Mat scores;
  cv::matchTemplate(grey1(area), grey0(window), scores, cv::TM_CCOEFF_NORMED);
  double best = 0.0;
  cv::Point at;
  cv::minMaxLoc(scores, nullptr, &best, nullptr, &at);
  if (!(best >= kMinCorrelation)) return std::nullopt;
  double offset = at.y - search;
  if (at.y > 0 && at.y + 1 < scores.rows) {  // parabola through the best and its neighbours
    const double a = scores.at<float>(at.y - 1, at.x), b = scores.at<float>(at.y + 1, at.x);
    const double curvature = a + b - 2.0 * best;
    if (curvature < 0.0) offset += 0.5 * (a - b) / curvature;
  }
  return std::abs(offset);
}
}  // namespace

std::pair<double, int> EpipolarOffset(const cv::Mat& grey0, const cv::Mat& grey1,
                                      const cv::Mat& mask0, int num_disparities,
                                      const DenseStereoOptions& options) {
  constexpr int kHalf = kEpipolarHalfWindow;
  const int search = options.epipolar_search_rows;
  const int margin = kHalf + search + 1;
  const int lattice_rows = std::max(1, static_cast<int>(std::sqrt(options.epipolar_samples * 5.0)));
  const int lattice_cols = std::max(1, options.epipolar_samples / lattice_rows);
  // Lattice rows in parallel, each into its own list (the order of the matches does not matter
  // to the median).
  std::vector<std::vector<double>> row_offsets(lattice_rows);
  cv::parallel_for_(cv::Range(0, lattice_rows), [&](const cv::Range& lattice_range) {
    for (int i = lattice_range.start; i < lattice_range.end; ++i) {
      const int r = margin + (grey0.rows - 2 * margin) * (2 * i + 1) / (2 * lattice_rows);
      for (int j = 0; j < lattice_cols; ++j) {
        const int c = kHalf + 1 + (grey0.cols - 2 * kHalf - 2) * (2 * j + 1) / (2 * lattice_cols);
        if (r < margin || r >= grey0.rows - margin || !mask0.at<uint8_t>(r, c)) continue;
        const std::optional<double> offset = RowOffset(grey0, grey1, r, c, num_disparities, search);
        if (offset) row_offsets[i].push_back(*offset);
      }
    }
  });
  std::vector<double> offsets;
  for (const std::vector<double>& row : row_offsets) {
    offsets.insert(offsets.end(), row.begin(), row.end());
  }
  const int num = static_cast<int>(offsets.size());
  if (num < 30) return {-1.0, num};
  std::nth_element(offsets.begin(), offsets.begin() + num / 2, offsets.end());
  return {offsets[num / 2], num};
}

cv::Mat WindowCorrelation(const cv::Mat& a, const cv::Mat& b, int window, double noise_grey) {
  const cv::Size size(window, window);
  cv::Mat mean_a, mean_b, mean_aa, mean_bb, mean_ab;
  const std::array<std::tuple<cv::Mat*, const cv::Mat*, const cv::Mat*>, 5> sums = {{
      {&mean_a, &a, nullptr}, {&mean_b, &b, nullptr}, {&mean_aa, &a, &a}, {&mean_bb, &b, &b},
      {&mean_ab, &a, &b}}};
  ParallelTasks(static_cast<int>(sums.size()), [&](int i) {
    const auto [sum, x, y] = sums[i];
    cv::boxFilter(y ? x->mul(*y) : *x, *sum, CV_32F, size);
  });
  const float noise2 = static_cast<float>(noise_grey * noise_grey);
  cv::Mat out(a.size(), CV_32F);
  cv::parallel_for_(cv::Range(0, a.rows), [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r) {
      const float* ma = mean_a.ptr<float>(r);
      const float* mb = mean_b.ptr<float>(r);
      const float* maa = mean_aa.ptr<float>(r);
      const float* mbb = mean_bb.ptr<float>(r);
      const float* mab = mean_ab.ptr<float>(r);
      float* o = out.ptr<float>(r);
      for (int c = 0; c < a.cols; ++c) {
        const float var_a = std::max(0.f, maa[c] - ma[c] * ma[c]) + noise2;
        const float var_b = std::max(0.f, mbb[c] - mb[c] * mb[c]) + noise2;
        const float cov = mab[c] - ma[c] * mb[c];
        o[c] = var_a > 0.f && var_b > 0.f ? cov / std::sqrt(var_a * var_b) : 0.f;
      }
    }
  });
  return out;
}

namespace {
// The rig, once the options are checked (so that the rectifier is built from valid options).
const StereoRig& CheckedRig(const StereoRig& rig, const DenseStereoOptions& options) {
  options.Check();
  return rig;
}
}  // namespace

DenseStereo::DenseStereo(const StereoRig& rig, const DenseStereoOptions& options,
                         const std::filesystem::path& tables_dir)
    : rig_(rig),
      options_(options),
      rectifier_(SharedRectifier(CheckedRig(rig, options), options.grid, tables_dir)) {
  const double step = rectifier_->theta_step_rad(), baseline = rectifier_->baseline_m();
  const double max_parallax_rad = options_.max_parallax_deg * M_PI / 180.0;
  const int cells = static_cast<int>(std::ceil(max_parallax_rad / step));
  num_disparities_ = std::max(16, (cells + 15) / 16 * 16);
  cot_parallax_.assign(kDisparitySteps * num_disparities_, 0.0);
  range_std_per_sin_theta_.assign(kDisparitySteps * num_disparities_, 0.0);
  for (int k = 1; k < kDisparitySteps * num_disparities_; ++k) {
    const double parallax = k / static_cast<double>(kDisparitySteps) * step;
    const double sin_p = std::sin(parallax);
    cot_parallax_[k] = std::cos(parallax) / sin_p;
    range_std_per_sin_theta_[k] = baseline / (sin_p * sin_p) * step;
  }
  for (int c = 0; c < rectifier_->cols(); ++c) {
    sin_theta_.push_back(std::sin(rectifier_->Theta(c)));
    cos_theta_.push_back(std::cos(rectifier_->Theta(c)));
  }
}

DenseStereo::RectifiedPair DenseStereo::RectifyPair(const cv::Mat& image0,
                                                    const cv::Mat& image1) const {
  RectifiedPair pair;
  const MirrorMaskOptions mask = options_.MaskOptions();
  // The cameras are independent: one on each thread (OpenCV runs the remaps, blurs and
  // erosions nested in this loop serially; the masks' row scans are serial anyway).
  cv::parallel_for_(
      cv::Range(0, 2),
      [&](const cv::Range& cameras) {
        for (int camera = cameras.start; camera < cameras.end; ++camera) {
          if (camera == 0) {
            pair.colour0 = rectifier_->Rectify(image0, 0);
            pair.grey0 = ToGreyscale8(pair.colour0);
            pair.mask0 =
                MirrorMask(pair.grey0, Eigen::Vector2d::Zero(), mask, rectifier_->ValidMask(0));
          } else {
            pair.grey1 = rectifier_->Rectify(ToGreyscale8(image1), 1);
            pair.mask1 =
                MirrorMask(pair.grey1, Eigen::Vector2d::Zero(), mask, rectifier_->ValidMask(1));
          }
        }
      },
      2);
  return pair;
}

void DenseStereo::TriangulateCells(const cv::Mat& disparity, const cv::Mat& disparity_std,
                                   const cv::Mat& correlation, int first, const RectifiedPair& pair,
                                   GridCells* cells, DensePairResult* result) const {
  const int rows = disparity.rows, width = disparity.cols;
  const int num_values = static_cast<int>(cot_parallax_.size());
  const double baseline = rectifier_->baseline_m();
  const float scale = static_cast<float>(result->confidence_scale);
  const double floor2 = options_.disparity_std_cells * options_.disparity_std_cells;
  const double fit_scale2 = options_.disparity_std_scale * options_.disparity_std_scale;
  std::vector<int> row_mirror(rows, 0), row_matched(rows, 0);
  std::vector<double> row_confidence(rows, 0.0);
  cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range_of_rows) {
    for (int r = range_of_rows.start; r < range_of_rows.end; ++r) {
      const float* d = disparity.ptr<float>(r);
      const float* d_std = disparity_std.ptr<float>(r);
      const uint8_t* m0 = pair.mask0.ptr<uint8_t>(r) + first;
      const uint8_t* m1 = pair.mask1.ptr<uint8_t>(r) + first;
      const float* corr = correlation.ptr<float>(r);
      float* range_row = cells->range.ptr<float>(r) + first;
      float* std_row = cells->range_std.ptr<float>(r) + first;
      float* conf_row = cells->confidence.ptr<float>(r) + first;
      for (int c = 0; c < width; ++c) {
        if (!m0[c]) continue;
        ++row_mirror[r];
        if (!(d[c] > 0.f)) continue;
        const int k = static_cast<int>(std::lround(d[c] * kDisparitySteps));
        if (k <= 0 || k >= num_values) continue;
        const int c1 = static_cast<int>(std::lround(c - d[c]));
        if (c1 < 0 || !m1[c1]) continue;
        ++row_matched[r];
        const float conf = std::clamp(corr[c], 0.f, 1.f) * scale;
        row_confidence[r] += conf;
        conf_row[c] = conf;
        const double sin_theta = sin_theta_[first + c];
        const double range_m = baseline * (sin_theta * cot_parallax_[k] + cos_theta_[first + c]);
        const double std_cells = std::sqrt(floor2 + fit_scale2 * d_std[c] * d_std[c]);
        const double std_m = sin_theta * range_std_per_sin_theta_[k] * std_cells;
        if (conf < options_.min_confidence || !(range_m > 0.0) ||
            std_m > options_.max_relative_range_std * range_m) {
          continue;
        }
        range_row[c] = static_cast<float>(range_m);
        std_row[c] = static_cast<float>(std_m);
      }
    }
  });
  double confidence_sum = 0.0;
  for (int r = 0; r < rows; ++r) {
    result->num_mirror_cells += row_mirror[r];
    result->num_matched_cells += row_matched[r];
    confidence_sum += row_confidence[r];
  }
  if (result->num_matched_cells > 0) {
    result->mean_confidence = confidence_sum / result->num_matched_cells;
  }
}

void DenseStereo::CollectPoints(const GridCells& cells, const cv::Mat& colour0,
                                DensePairResult* result) const {
  const int rows = cells.range.rows, cols = cells.range.cols;
  std::vector<size_t> row_start(rows + 1, 0);
  for (int r = 0; r < rows; ++r) {
    row_start[r + 1] = row_start[r] + cv::countNonZero(cells.range.row(r));
  }
  result->points.resize(row_start[rows]);
  const Eigen::Matrix3d& cam0_from_grid = rectifier_->cam0_from_grid();
  cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range_of_rows) {
    for (int r = range_of_rows.start; r < range_of_rows.end; ++r) {
      // A cell's direction is sin(theta) (cos phi, sin phi, 0) + cos(theta) (0, 0, 1) in the
      // grid's frame.
      const double phi = rectifier_->Phi(r);
      const Eigen::Vector3d across =
          cam0_from_grid * Eigen::Vector3d(std::cos(phi), std::sin(phi), 0.0);
      const Eigen::Vector3d along = cam0_from_grid.col(2);
      const float* range_row = cells.range.ptr<float>(r);
      const float* std_row = cells.range_std.ptr<float>(r);
      const float* conf_row = cells.confidence.ptr<float>(r);
      DensePoint* point = result->points.data() + row_start[r];
      for (int c = 0; c < cols; ++c) {
        if (!(range_row[c] > 0.f)) continue;
        point->point_in_cam0 =
            (range_row[c] * (sin_theta_[c] * across + cos_theta_[c] * along)).cast<float>();
        if (colour0.channels() == 3) {
          const cv::Vec3b bgr = colour0.at<cv::Vec3b>(r, c);
          point->rgb = {bgr[2], bgr[1], bgr[0]};
        } else {
          const uint8_t g = colour0.at<uint8_t>(r, c);
          point->rgb = {g, g, g};
        }
        point->confidence = conf_row[c];
        point->range_std_m = std_row[c];
        ++point;
      }
    }
  });
}

PlyCloud ToPlyCloud(const std::vector<DensePoint>& points, const std::string& comment) {
  PlyCloud cloud;
  cloud.comment = comment;
  cloud.has_confidence = true;
  cloud.has_range_std = true;
  cloud.positions.reserve(points.size());
  cloud.colours.reserve(points.size());
  cloud.confidence.reserve(points.size());
  cloud.range_std_m.reserve(points.size());
  for (const DensePoint& p : points) {
    cloud.positions.push_back(p.point_in_cam0);
    cloud.colours.push_back(p.rgb);
    cloud.confidence.push_back(p.confidence);
    cloud.range_std_m.push_back(p.range_std_m);
  }
  return cloud;
}

DensePairResult DenseStereo::Reconstruct(const cv::Mat& image0, const cv::Mat& image1,
                                         const ProgressSink& progress) const {
  CheckPairImages(rig_, image0, image1);
  progress.Report(0.0, "rectify");
  Timer timer;
  const RectifiedPair pair = RectifyPair(image0, image1);
  progress.ThrowIfCancelled();
  DensePairResult result;
  result.seconds.rectify = timer.ElapsedSeconds();
  const int rows = rectifier_->rows(), cols = rectifier_->cols();
  GridCells cells{cv::Mat::zeros(rows, cols, CV_32F), cv::Mat::zeros(rows, cols, CV_32F),
                  cv::Mat::zeros(rows, cols, CV_32F)};
  const auto [first, last] = UsedColumns(pair.mask0, pair.mask1);
  if (first <= last) {
    progress.Report(0.1, "match");
    timer.Restart();
    const cv::Rect roi(first, 0, last - first + 1, rows);
    const cv::Mat disparity16 =
        MatchRows(pair.grey0(roi), pair.grey1(roi), num_disparities_, options_);
    progress.ThrowIfCancelled();
    progress.Report(0.8, "confidence");
    result.seconds.match = timer.ElapsedSeconds();
    timer.Restart();
    cv::Mat left, right_float;
    pair.grey0(roi).convertTo(left, CV_32F);
    pair.grey1(roi).convertTo(right_float, CV_32F);
    const cv::Mat correlation =
        WindowCorrelation(left, MatchedGrey(pair.grey1(roi), disparity16),
                          options_.confidence_window_cells, options_.image_noise_grey);
    result.seconds.confidence = timer.ElapsedSeconds();
    progress.Report(0.85, "epipolar");
    timer.Restart();
    std::tie(result.epipolar_offset_cells, result.num_epipolar_samples) =
        EpipolarOffset(pair.grey0, pair.grey1, pair.mask0, num_disparities_, options_);
    if (result.epipolar_offset_cells > options_.max_epipolar_offset_cells) {
      result.confidence_scale = options_.max_epipolar_offset_cells / result.epipolar_offset_cells;
    }
    result.seconds.epipolar = timer.ElapsedSeconds();
    progress.Report(0.88, "refine");
    timer.Restart();
    const RefinedDisparity refined = RefineDisparity(left, right_float, disparity16, options_);
    result.seconds.refine = timer.ElapsedSeconds();
    progress.ThrowIfCancelled();
    progress.Report(0.93, "triangulate");
    timer.Restart();
    TriangulateCells(refined.disparity, refined.std_cells, correlation, first, pair, &cells,
                     &result);
  }
  CollectPoints(cells, pair.colour0, &result);
  result.num_points = static_cast<int>(result.points.size());
  const std::array<std::pair<const cv::Mat*, cv::Mat*>, 3> panoramas = {
      {{&cells.range, &result.range_m},
       {&cells.range_std, &result.range_std_m},
       {&cells.confidence, &result.confidence}}};
  ParallelTasks(3, [&](int i) { cv::transpose(*panoramas[i].first, *panoramas[i].second); });
  result.seconds.triangulate = timer.ElapsedSeconds();
  progress.Report(1.0, "triangulate");
  return result;
}

}  // namespace omnirig::dense
