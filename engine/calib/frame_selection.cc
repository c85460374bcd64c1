#include "engine/calib/frame_selection.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include <opencv2/calib3d.hpp>

#include "engine/estimators/board_pose.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

constexpr int kNumRings = 5;
constexpr int kNumSectors = 16;
constexpr int kNumTiltBins = 4;  // 0-15, 15-30, 30-45, 45+ degrees
constexpr int kNumDistanceBins = 3;

// Corners per cell of the disk (rings x sectors around the image centre) of one view.
std::map<int, int> CellCounts(const std::vector<Eigen::Vector2d>& corners_px, int width,
                              int height) {
  const Eigen::Vector2d centre(0.5 * (width - 1), 0.5 * (height - 1));
  const double radius = 0.5 * std::min(width, height);
  std::map<int, int> counts;
  for (const Eigen::Vector2d& corner : corners_px) {
    const Eigen::Vector2d d = corner - centre;
    const int ring = std::min(kNumRings - 1, static_cast<int>(kNumRings * d.norm() / radius));
    const double angle = std::atan2(d.y(), d.x()) + M_PI;  // [0, 2 pi]
    const int sector =
        std::min(kNumSectors - 1, static_cast<int>(kNumSectors * angle / (2.0 * M_PI)));
    ++counts[ring * kNumSectors + sector];
  }
  return counts;
}

// The pose bin (tilt x distance) of each view with a board pose under `camera`; -1 without one.
std::vector<int> PoseBins(const std::vector<CalibrationView>& views, const BoardSpec& board,
                          const CameraModel& camera) {
  const std::vector<Eigen::Vector3d> object = board.ObjectPoints();
  std::vector<double> tilt_deg(views.size(), -1.0), distance_m(views.size(), -1.0);
  double min_distance = 1e300, max_distance = 0.0;
  for (size_t v = 0; v < views.size(); ++v) {
    const BoardDetection& detection = views[v].detection;
    if (!detection.found) continue;
    std::vector<Eigen::Vector3d> points;
    for (int id : detection.corner_ids) points.push_back(object[id]);
    const std::optional<Rigid3d> pose = EstimateBoardPose(camera, points, detection.corners_px);
    if (!pose) continue;
    const Eigen::Vector3d normal = pose->rotation * Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d centre = pose->translation;
    distance_m[v] = centre.norm();
    if (distance_m[v] <= 0.0) continue;
    tilt_deg[v] = std::acos(std::min(1.0, std::abs(normal.dot(centre)) / distance_m[v])) * 180.0 /
                  M_PI;
    min_distance = std::min(min_distance, distance_m[v]);
    max_distance = std::max(max_distance, distance_m[v]);
  }
  std::vector<int> bins(views.size(), -1);
  for (size_t v = 0; v < views.size(); ++v) {
    if (tilt_deg[v] < 0.0) continue;
    const int tilt = std::min(kNumTiltBins - 1, static_cast<int>(tilt_deg[v] / 15.0));
    const double span = std::max(1e-9, max_distance - min_distance);
    const int distance = std::min(
        kNumDistanceBins - 1,
        static_cast<int>(kNumDistanceBins * (distance_m[v] - min_distance) / span));
    bins[v] = tilt * kNumDistanceBins + distance;
  }
  return bins;
}

// Greedy picks until `chosen` holds `target` views: the view whose corners add most to the
// cells' square-root counts, times 1 + 1 / (1 + views chosen in its pose bin) when pose bins are
// known.
void PickGreedy(const std::vector<std::map<int, int>>& cells, const std::vector<int>& pose_bins,
                int target, std::vector<bool>* chosen) {
  std::vector<double> cell_count(kNumRings * kNumSectors, 0.0);
  std::vector<int> bin_count(kNumTiltBins * kNumDistanceBins, 0);
  int num_chosen = 0;
  for (size_t v = 0; v < cells.size(); ++v) {
    if (!(*chosen)[v]) continue;
    ++num_chosen;
    for (const auto& [cell, n] : cells[v]) cell_count[cell] += n;
    if (!pose_bins.empty() && pose_bins[v] >= 0) ++bin_count[pose_bins[v]];
  }
  while (num_chosen < target) {
    int best = -1;
    double best_gain = 0.0;
    for (size_t v = 0; v < cells.size(); ++v) {
      if ((*chosen)[v] || cells[v].empty()) continue;
      double gain = 0.0;
      for (const auto& [cell, n] : cells[v]) {
        gain += std::sqrt(cell_count[cell] + n) - std::sqrt(cell_count[cell]);
      }
      if (!pose_bins.empty() && pose_bins[v] >= 0) gain *= 1.0 + 1.0 / (1 + bin_count[pose_bins[v]]);
      if (gain > best_gain) {
        best_gain = gain;
        best = static_cast<int>(v);
      }
    }
    if (best < 0) return;
    (*chosen)[best] = true;
    ++num_chosen;
    for (const auto& [cell, n] : cells[best]) cell_count[cell] += n;
    if (!pose_bins.empty() && pose_bins[best] >= 0) ++bin_count[pose_bins[best]];
  }
}

}  // namespace

void FrameSelectionOptions::Check() const {
  OMNIRIG_CHECK(max_views == 0 || max_views >= 3,
                "max_views must be 0 (no cap) or at least 3, got " << max_views);
  OMNIRIG_CHECK_IN(near_duplicate_fraction, '[', 0.0, 0.5, ']');
  OMNIRIG_CHECK(long_input_frames >= 0,
                "long_input_frames must not be negative, got " << long_input_frames);
}

std::vector<Eigen::Vector2d> ScreenFrame(const cv::Mat& grey, const BoardSpec& board) {
  OMNIRIG_CHECK(!grey.empty() && grey.type() == CV_8UC1, "ScreenFrame takes an 8-bit grey image");
  std::vector<cv::Point2f> corners;
  const bool found =
      cv::findChessboardCorners(grey, cv::Size(board.cols, board.rows), corners,
                                cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK);
  std::vector<Eigen::Vector2d> out;
  if (!found || static_cast<int>(corners.size()) != board.NumCorners()) return out;
  for (const cv::Point2f& c : corners) out.emplace_back(c.x, c.y);
  return out;
}

double BoardShift(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b) {
  OMNIRIG_CHECK(a.size() == b.size() && !a.empty(), "BoardShift takes two full corner sets");
  const size_t n = a.size();
  double direct = 0.0, turned = 0.0;
  for (size_t i = 0; i < n; ++i) {
    direct += (a[i] - b[i]).norm();
    turned += (a[i] - b[n - 1 - i]).norm();
  }
  return std::min(direct, turned) / n;
}

std::vector<int> MarkNearDuplicates(const std::vector<std::vector<Eigen::Vector2d>>& corners,
                                    double threshold_px) {
  std::vector<int> duplicate_of(corners.size(), -1);
  std::vector<int> kept;
  for (size_t i = 0; i < corners.size(); ++i) {
    if (corners[i].empty()) continue;
    // The most recent kept frames first: a board held still matches the last one.
    for (auto k = kept.rbegin(); k != kept.rend(); ++k) {
      if (corners[*k].size() == corners[i].size() &&
          BoardShift(corners[*k], corners[i]) < threshold_px) {
        duplicate_of[i] = *k;
        break;
      }
    }
    if (duplicate_of[i] < 0) kept.push_back(static_cast<int>(i));
  }
  return duplicate_of;
}

std::vector<int> SelectViews(const std::vector<CalibrationView>& views, int width, int height,
                             const BoardSpec& board, int max_views,
                             const CalibrationOptions& options) {
  std::vector<std::map<int, int>> cells(views.size());
  int num_found = 0;
  for (size_t v = 0; v < views.size(); ++v) {
    if (!views[v].detection.found) continue;
    cells[v] = CellCounts(views[v].detection.corners_px, width, height);
    ++num_found;
  }
  std::vector<bool> chosen(views.size(), false);
  if (num_found <= max_views) {
    for (size_t v = 0; v < views.size(); ++v) chosen[v] = views[v].detection.found;
  } else {
    // First half on the disk's coverage alone, then with the board poses of a first model.
    PickGreedy(cells, {}, std::max(options.min_views, max_views / 2), &chosen);
    std::vector<int> pose_bins;
    std::vector<CalibrationView> first;
    for (size_t v = 0; v < views.size(); ++v) {
      if (chosen[v]) first.push_back(views[v]);
    }
    try {
      const CalibrationReport model = Calibrate(first, width, height, board, options, {});
      pose_bins = PoseBins(views, board, model.camera);
    } catch (const InvalidArgument&) {
      // Too few usable views for a first model: coverage of the disk alone.
    }
    PickGreedy(cells, pose_bins, max_views, &chosen);
  }
  std::vector<int> out;
  for (size_t v = 0; v < views.size(); ++v) {
    if (chosen[v]) out.push_back(static_cast<int>(v));
  }
  return out;
}

}  // namespace omnirig
