#include "engine/calib/detect.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <set>

#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/calib/calibrate.h"
#include "engine/calib/corner_fit.h"
#include "engine/calib/grid_check.h"
#include "engine/calib/initialize.h"
#include "engine/estimators/board_pose.h"
#include "engine/features/image.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

// Distance from corner `id` to its nearest grid neighbour (the local square size in pixels).
double LocalSquarePx(const std::vector<Eigen::Vector2d>& grid, const BoardSpec& board, int id) {
  const int row = id / board.cols, col = id % board.cols;
  double best = std::numeric_limits<double>::infinity();
  const int offsets[4][2] = {{0, 1}, {0, -1}, {1, 0}, {-1, 0}};
  for (const auto& offset : offsets) {
    const int r = row + offset[0], c = col + offset[1];
    if (r < 0 || c < 0 || r >= board.rows || c >= board.cols) continue;
    best = std::min(best, (grid[r * board.cols + c] - grid[id]).norm());
  }
  return best;
}

// True when the intensities on a circle around `center` alternate dark/light four times, as
// around an inner checkerboard corner (an outer board corner or an edge alternates twice).
bool LooksLikeXCorner(const cv::Mat& grey, const Eigen::Vector2d& center, double radius) {
  constexpr int kSamples = 32;
  std::vector<double> values;
  for (int i = 0; i < kSamples; ++i) {
    const double angle = 2.0 * M_PI * i / kSamples;
    const int u = static_cast<int>(std::lround(center.x() + radius * std::cos(angle)));
    const int v = static_cast<int>(std::lround(center.y() + radius * std::sin(angle)));
    if (u < 0 || v < 0 || u >= grey.cols || v >= grey.rows) return false;
    values.push_back(grey.at<uint8_t>(v, u));
  }
  const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  if (*hi - *lo < 30.0) return false;
  const double threshold = 0.5 * (*hi + *lo);
  int changes = 0;
  for (int i = 0; i < kSamples; ++i) {
    changes += (values[i] > threshold) != (values[(i + 1) % kSamples] > threshold);
  }
  return changes == 4;
}

// Mean grey level in a disc of `radius` pixels around `center`; nullopt when the disc leaves the
// image.
std::optional<double> MeanInDisc(const cv::Mat& grey, const Eigen::Vector2d& center,
                                 double radius) {
  const int r = std::max(1, static_cast<int>(std::floor(radius)));
  const int u0 = static_cast<int>(std::lround(center.x()));
  const int v0 = static_cast<int>(std::lround(center.y()));
  if (!center.allFinite() || u0 - r < 0 || v0 - r < 0 || u0 + r >= grey.cols ||
      v0 + r >= grey.rows) {
    return std::nullopt;
  }
  double sum = 0.0;
  int n = 0;
  for (int dv = -r; dv <= r; ++dv) {
    for (int du = -r; du <= r; ++du) {
      if (du * du + dv * dv > r * r) continue;
      sum += grey.at<uint8_t>(v0 + dv, u0 + du);
      ++n;
    }
  }
  return sum / n;
}

// How one edge of a full grid continues. A board of cols x rows inner corners has one more
// row of squares beyond each edge line of corners (its outer squares), then its margin. The
// cells one square further out (between one and two square pitches beyond the edge line, along
// the grid's predicted continuation) are checker squares only on a larger board: there each has
// the colour of the square two rows inwards, the inside square next to the edge line, distinctly
// dark or light, so the row alternates in the board's own pitch and phase. A white margin of any
// width, a frame or holder of another grey, a hand, glare or the background is uniform along
// the edge (or random), so at most about half of its cells match.
//
// edge[i], inner[i], inner2[i]: the corners of the edge line, the next line inwards and the one
// after (inner2 empty when the board has only two lines across).
bool EdgeContinues(const cv::Mat& grey, const std::vector<Eigen::Vector2d>& edge,
                   const std::vector<Eigen::Vector2d>& inner,
                   const std::vector<Eigen::Vector2d>& inner2) {
  const size_t n = edge.size();
  std::vector<Eigen::Vector2d> beyond1(n), beyond2(n);
  for (size_t i = 0; i < n; ++i) {
    // Lagrange extrapolation of the quadratic through the lines at grid offsets 0, -1, -2 to +1
    // and +2: it follows the curvature of a mirror's image of the board.
    if (inner2.empty()) {
      beyond1[i] = 2.0 * edge[i] - inner[i];
      beyond2[i] = 3.0 * edge[i] - 2.0 * inner[i];
    } else {
      beyond1[i] = 3.0 * edge[i] - 3.0 * inner[i] + inner2[i];
      beyond2[i] = 6.0 * edge[i] - 8.0 * inner[i] + 3.0 * inner2[i];
    }
  }
  std::vector<double> inside, outside;
  for (size_t i = 0; i + 1 < n; ++i) {
    const double side = std::min((edge[i + 1] - edge[i]).norm(), (edge[i] - inner[i]).norm());
    const double radius = 0.2 * side;
    std::optional<double> in, out;
    if (radius >= 1.0) {
      in = MeanInDisc(grey, 0.25 * (edge[i] + edge[i + 1] + inner[i] + inner[i + 1]), radius);
      out = MeanInDisc(grey, 0.25 * (beyond1[i] + beyond1[i + 1] + beyond2[i] + beyond2[i + 1]),
                       radius);
    }
    // Cells too small or off the image are left out, keeping the alternation's index.
    if (!in || !out) {
      inside.push_back(std::numeric_limits<double>::quiet_NaN());
      outside.push_back(0.0);
      continue;
    }
    inside.push_back(*in);
    outside.push_back(*out);
  }
  // The board's own dark and light levels: the squares inside alternate along the edge.
  double sum[2] = {0.0, 0.0};
  int count[2] = {0, 0};
  for (size_t i = 0; i < inside.size(); ++i) {
    if (std::isnan(inside[i])) continue;
    sum[i % 2] += inside[i];
    ++count[i % 2];
  }
  if (count[0] == 0 || count[1] == 0) return false;
  const double level0 = sum[0] / count[0], level1 = sum[1] / count[1];
  const double contrast = std::abs(level0 - level1);
  if (contrast < 20.0) return false;
  const double mid = 0.5 * (level0 + level1);
  int valid = 0, matches = 0;
  for (size_t i = 0; i < inside.size(); ++i) {
    if (std::isnan(inside[i])) continue;
    ++valid;
    const bool inside_light = (i % 2 == 0 ? level0 : level1) > mid;
    const bool outside_light = outside[i] > mid;
    matches += inside_light == outside_light && std::abs(outside[i] - mid) > 0.25 * contrast;
  }
  return valid >= 2 && 5 * matches >= 4 * valid;
}

// The edges along which a full grid continues as a checkerboard (a sub-board of a larger
// board): extra columns (left, right) and rows (top, bottom) seen beyond it.
struct GridExtension {
  int extra_cols = 0;
  int extra_rows = 0;
};

GridExtension FindGridExtension(const cv::Mat& grey, const std::vector<Eigen::Vector2d>& grid,
                                const BoardSpec& board) {
  const int R = board.rows, C = board.cols;
  auto row = [&](int r) {
    std::vector<Eigen::Vector2d> line;
    if (r < 0 || r >= R) return line;
    for (int c = 0; c < C; ++c) line.push_back(grid[r * C + c]);
    return line;
  };
  auto col = [&](int c) {
    std::vector<Eigen::Vector2d> line;
    if (c < 0 || c >= C) return line;
    for (int r = 0; r < R; ++r) line.push_back(grid[r * C + c]);
    return line;
  };
  GridExtension extension;
  extension.extra_rows += EdgeContinues(grey, row(0), row(1), R > 2 ? row(2) : row(-1));
  extension.extra_rows += EdgeContinues(grey, row(R - 1), row(R - 2), R > 2 ? row(R - 3) : row(-1));
  extension.extra_cols += EdgeContinues(grey, col(0), col(1), C > 2 ? col(2) : col(-1));
  extension.extra_cols += EdgeContinues(grey, col(C - 1), col(C - 2), C > 2 ? col(C - 3) : col(-1));
  return extension;
}

// Refinement window half-size (pixels) for a corner whose local square is square_px.
int WindowHalfPx(double square_px) {
  return std::clamp(static_cast<int>(std::lround(0.4 * square_px)), 2, 15);
}

// Refines each corner with cornerSubPix in a window scaled to its local square size, then (with
// `fit`) by fitting the blurred X-junction with curved edges (corner_fit.h): cornerSubPix alone
// is pulled to the convex side of edges a mirror bends. Returns the largest shift.
double RefineCorners(const cv::Mat& grey, std::vector<Eigen::Vector2d>* corners,
                     const std::vector<double>& square_px, bool fit) {
  double max_shift = 0.0;
  for (size_t i = 0; i < corners->size(); ++i) {
    const int half = WindowHalfPx(square_px[i]);
    std::vector<cv::Point2f> point = {
        cv::Point2f(static_cast<float>((*corners)[i].x()), static_cast<float>((*corners)[i].y()))};
    const cv::Point2f before = point[0];
    if (before.x < half + 1 || before.y < half + 1 || before.x > grey.cols - half - 2 ||
        before.y > grey.rows - half - 2) {
      continue;
    }
    cv::cornerSubPix(grey, point, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 1e-3));
    (*corners)[i] = Eigen::Vector2d(point[0].x, point[0].y);
    if (fit) {
      if (const auto fitted = FitCheckerCorner(grey, (*corners)[i], half)) (*corners)[i] = *fitted;
    }
    max_shift = std::max(max_shift, ((*corners)[i] - Eigen::Vector2d(before.x, before.y)).norm());
  }

  return max_shift;
}

// Refines the whole grid; returns the local square size each corner's window was sized from.
std::vector<double> RefineGrid(const cv::Mat& grey, const BoardSpec& board, bool fit,
                               BoardDetection* detection) {
  std::vector<double> square_px;
  for (int id : detection->corner_ids) {
    square_px.push_back(LocalSquarePx(detection->corners_px, board, id));
  }
  RefineCorners(grey, &detection->corners_px, square_px, fit);
  return square_px;
}

// Refines the corners `flagged` by the grid check again from their clean neighbours'
// prediction, in a window sized from the square those neighbours span (the first window may have
// been sized from the wrong corner itself), then their clean 4-neighbours whose window changed.
// A corner whose refinement measures nothing (too near the border, or cornerSubPix returning its
// start because it diverged) keeps its old position, so that the second check drops it.
void RefineFlaggedCorners(const cv::Mat& grey, const BoardSpec& board, const DetectOptions& options,
                          const std::vector<int>& flagged,
                          const std::vector<double>& first_square_px, BoardDetection* detection) {
  std::vector<Eigen::Vector2d>& grid = detection->corners_px;
  std::vector<bool> usable(grid.size(), true);
  for (int id : flagged) usable[id] = false;
  const std::vector<GridCornerPrediction> predictions = PredictFromGridNeighbours(
      grid, board.cols, board.rows, usable, options.grid_check.num_neighbours);
  for (int id : flagged) {
    const GridCornerPrediction& prediction = predictions[id];
    if (!prediction.valid || !std::isfinite(prediction.square_px)) continue;
    std::vector<Eigen::Vector2d> corner = {prediction.predicted_px};
    if (RefineCorners(grey, &corner, {prediction.square_px}, options.fit_corner_model) > 0.0) {
      grid[id] = corner[0];
      ++detection->num_rerefined_corners;
    }
  }
  const int offsets[4][2] = {{0, 1}, {0, -1}, {1, 0}, {-1, 0}};
  for (int id : flagged) {
    for (const auto& offset : offsets) {
      const int r = id / board.cols + offset[0], c = id % board.cols + offset[1];
      if (r < 0 || c < 0 || r >= board.rows || c >= board.cols || !usable[r * board.cols + c]) {
        continue;
      }
      const int neighbour = r * board.cols + c;
      const double square_px = LocalSquarePx(grid, board, neighbour);
      if (WindowHalfPx(square_px) == WindowHalfPx(first_square_px[neighbour])) continue;
      std::vector<Eigen::Vector2d> corner = {grid[neighbour]};
      RefineCorners(grey, &corner, {square_px}, options.fit_corner_model);
      grid[neighbour] = corner[0];
    }
  }
}

// Leaves the corners `ids` out of a full-grid detection.
void DropCorners(std::vector<int> ids, BoardDetection* detection) {
  std::sort(ids.begin(), ids.end());
  BoardDetection kept = *detection;
  kept.corners_px.clear();
  kept.corner_ids.clear();
  for (size_t i = 0; i < detection->corners_px.size(); ++i) {
    if (std::binary_search(ids.begin(), ids.end(), detection->corner_ids[i])) continue;
    kept.corners_px.push_back(detection->corners_px[i]);
    kept.corner_ids.push_back(detection->corner_ids[i]);
  }
  kept.dropped_corner_ids = std::move(ids);
  *detection = std::move(kept);
}

// The grid check (grid_check.h) after the refinement of a full grid (corner id i at index i):
// inconsistent corners are refined again; those still inconsistent are dropped, or the view is
// rejected when that would drop more than max_dropped_fraction of the corners.
void CheckGrid(const cv::Mat& grey, const BoardSpec& board, const DetectOptions& options,
               const std::vector<double>& first_square_px, BoardDetection* detection) {
  const std::vector<int> flagged =
      FindInconsistentCorners(detection->corners_px, board.cols, board.rows, options.grid_check);
  if (flagged.empty()) return;
  RefineFlaggedCorners(grey, board, options, flagged, first_square_px, detection);
  const std::vector<int> still =
      FindInconsistentCorners(detection->corners_px, board.cols, board.rows, options.grid_check);
  if (still.empty()) return;
  if (static_cast<double>(still.size()) > options.max_dropped_fraction * board.NumCorners()) {
    detection->found = false;
    detection->reason = std::to_string(still.size()) + " of " + std::to_string(board.NumCorners()) +
                        " corners disagree with their neighbours in the grid even after a new "
                        "refinement (an inconsistent grid)";
    return;
  }
  DropCorners(still, detection);
}

std::string ValidateGridImpl(const cv::Mat& grey, const BoardSpec& board,
                             const std::vector<Eigen::Vector2d>& grid) {
  if (static_cast<int>(grid.size()) != board.NumCorners()) return "wrong corner count";
  for (int id = 0; id < board.NumCorners(); ++id) {
    const Eigen::Vector2d& p = grid[id];
    if (!(p.x() >= 0 && p.y() >= 0 && p.x() <= grey.cols - 1 && p.y() <= grey.rows - 1)) {
      return "corner outside the image";
    }
    if (!(LocalSquarePx(grid, board, id) > 1.5)) return "collapsed squares";
  }
  const GridExtension extension = FindGridExtension(grey, grid, board);
  if (extension.extra_cols > 0 || extension.extra_rows > 0) {
    return "the board size looks wrong: the checker squares continue beyond " +
           std::to_string(board.cols) + "x" + std::to_string(board.rows) +
           " inner corners, the board has at least " +
           std::to_string(board.cols + extension.extra_cols) + "x" +
           std::to_string(board.rows + extension.extra_rows) +
           " (a sub-board of a larger board: check cols and rows, counted as inner corners)";
  }
  return "";
}

// One attempt of an OpenCV detector on a (possibly upsampled) image; corners are mapped back to
// the original's pixel convention (centre of the top-left pixel at (0, 0)).
bool RunOpenCvDetector(const cv::Mat& image, double scale, const BoardSpec& board, bool sb,
                       int flags, std::vector<Eigen::Vector2d>* grid) {
  std::vector<cv::Point2f> corners;
  const cv::Size pattern(board.cols, board.rows);
  const bool found = sb ? cv::findChessboardCornersSB(image, pattern, corners, flags)
                        : cv::findChessboardCorners(image, pattern, corners, flags);
  if (!found || static_cast<int>(corners.size()) != board.NumCorners()) return false;
  grid->clear();
  for (const auto& c : corners) {
    grid->emplace_back((c.x + 0.5) / scale - 0.5, (c.y + 0.5) / scale - 0.5);
  }
  return true;
}

// An image OpenCV's detectors search, its scale relative to the original and the suffix it
// gives the method's name.
struct DetectorImage {
  cv::Mat image;
  double scale;
  std::string suffix;
};

// The image itself, after a half-size copy on large images (a half-size search is several times
// faster; the corners are refined at full resolution afterwards).
std::vector<DetectorImage> PlainImages(const cv::Mat& grey) {
  std::vector<DetectorImage> images;
  if (std::max(grey.cols, grey.rows) > 1000) {
    cv::Mat half;
    cv::resize(grey, half, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
    images.push_back({half, 0.5, "-half"});
  }
  images.push_back({grey, 1.0, ""});
  return images;
}

// A contrast-equalised copy (CLAHE): boards in the dim or washed-out parts of a mirror.
DetectorImage EqualisedImage(const cv::Mat& grey) {
  cv::Mat equalised;
  cv::createCLAHE(3.0, cv::Size(8, 8))->apply(grey, equalised);
  return {equalised, 1.0, "-equalised"};
}

constexpr int kClassicFlags =
    cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK;
constexpr int kSectorFlags = cv::CALIB_CB_NORMALIZE_IMAGE;
// The sector-based detector's ACCURACY flag (an internal upsampling) finds more boards of small
// squares, at about four times the cost.
constexpr int kSectorFineFlags = cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_ACCURACY;

// The attempts that take most of a second each on a 640x480 image (bench_calib profile), for
// views the cheap ones miss: on small images (squares of a few pixels) the sector-based detector
// with ACCURACY on the plain and equalised images, the classic one on the equalised image, and
// both on a 2x upsampled copy (on large images upsampling costs seconds; there, the sector-based
// detector on the full-size equalised image when the cheap ones used the half-size one).
// `try_one(image, sb, flags)` runs and validates one.
template <typename TryOne>
std::optional<BoardDetection> TryCostlyVariants(const cv::Mat& grey,
                                                const DetectorImage& equalised, bool small,
                                                bool halved, TryOne& try_one) {
  const DetectorImage plain = {grey, 1.0, ""};
  if (small) {
    if (auto detection = try_one(plain, true, kSectorFineFlags)) return detection;
  }
  if (auto detection = try_one(equalised, false, kClassicFlags)) return detection;
  if (!small) {
    // The cheap attempts searched only the half-size equalised image.
    return halved ? try_one(equalised, true, kSectorFlags) : std::nullopt;
  }
  if (auto detection = try_one(equalised, true, kSectorFineFlags)) return detection;
  DetectorImage upsampled{cv::Mat(), 2.0, "-upsampled"};
  cv::resize(grey, upsampled.image, cv::Size(), 2.0, 2.0, cv::INTER_CUBIC);
  // The fast check misses boards that only the upsampled image resolves.
  if (auto detection = try_one(upsampled, false, kClassicFlags & ~cv::CALIB_CB_FAST_CHECK)) {
    return detection;
  }
  return try_one(upsampled, true, kSectorFlags);
}

// No checkerboard found: why, in words a user can act on (what a detectable view needs, or
// why the last candidate was rejected).
BoardDetection NotFound(const BoardSpec& board, const std::string& last_reason) {
  BoardDetection detection;
  detection.reason = last_reason.empty()
                         ? "no " + board.Describe() +
                               " found: the whole board must be in view (every inner corner, "
                               "clear of the mirror's rim, the camera's reflection and hands), "
                               "sharp, and not washed out by glare; cols and rows count inner "
                               "corners"
                         : "rejected candidate: " + last_reason;
  return detection;
}

BoardDetection DetectCheckerboard(const cv::Mat& grey, const BoardSpec& board,
                                  const DetectOptions& options) {
  const bool small = std::max(grey.cols, grey.rows) <= 800;
  std::string last_reason;
  auto try_one = [&](const DetectorImage& variant, bool sb,
                     int flags) -> std::optional<BoardDetection> {
    std::vector<Eigen::Vector2d> grid;
    if (!RunOpenCvDetector(variant.image, variant.scale, board, sb, flags, &grid)) {
      return std::nullopt;
    }
    last_reason = ValidateGridImpl(grey, board, grid);
    if (!last_reason.empty()) return std::nullopt;
    BoardDetection detection;
    detection.found = true;
    detection.corners_px = grid;
    for (int id = 0; id < board.NumCorners(); ++id) detection.corner_ids.push_back(id);
    detection.method = (sb ? "sb" : "classic");
    if (flags & cv::CALIB_CB_ACCURACY) detection.method += "-fine";
    detection.method += variant.suffix;
    return detection;
  };
  // Cheapest first (CPU per 640x480 image, bench_calib profile): the classic detector with its
  // fast check (~0.01 s) on the full-size image, then the sector-based one (~0.1 s) on the
  // equalised image (on KaidanOmni it finds every view the plain image gives and five more),
  // then on the plain images. The classic detector does not search the half-size image: on
  // VMR (1024x768) it found there only views the full-size image gives, and where it failed
  // there it cost up to 0.15 s before the full-size search found the board in 0.005 s.
  const std::vector<DetectorImage> plain = PlainImages(grey);
  if (auto detection = try_one(plain.back(), false, kClassicFlags)) return *detection;
  // The first plain image is the half-size one on large images.
  if (options.try_enhanced) {
    DetectorImage equalised = EqualisedImage(plain.front().image);
    equalised.scale = plain.front().scale;
    equalised.suffix = plain.front().suffix + equalised.suffix;
    if (auto detection = try_one(equalised, true, kSectorFlags)) return *detection;
  }
  // With the equalised image tried, the plain ones join the costly variants: on the real sets
  // the plain image never gave a board the equalised one did not.
  if (!options.try_enhanced || options.try_costly_variants) {
    for (const DetectorImage& variant : plain) {
      if (auto detection = try_one(variant, true, kSectorFlags)) return *detection;
    }
  }
  if (options.try_enhanced && options.try_costly_variants) {
    if (auto detection =
            TryCostlyVariants(grey, EqualisedImage(grey), small, plain.size() > 1, try_one)) {
      return *detection;
    }
  }
  if (options.allow_exhaustive) {
    if (auto detection =
            try_one(plain.front(), true, cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_EXHAUSTIVE)) {
      detection->method = "sb-exhaustive";
      return *detection;
    }
  }
  return NotFound(board, last_reason);
}

BoardDetection DetectCharuco(const cv::Mat& grey, const BoardSpec& board,
                             const DetectOptions& options) {
  const cv::Ptr<cv::aruco::Dictionary> dictionary = cv::aruco::getPredefinedDictionary(
      static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(board.aruco_dictionary));
  const cv::Ptr<cv::aruco::CharucoBoard> charuco = cv::aruco::CharucoBoard::create(
      board.cols + 1, board.rows + 1, static_cast<float>(board.square_size_m),
      static_cast<float>(board.marker_size_m), dictionary);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(grey, dictionary, marker_corners, marker_ids);
  BoardDetection detection;
  detection.method = "charuco";
  if (marker_ids.empty()) {
    detection.reason = "no aruco markers found";
    return detection;
  }
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, grey, charuco, corners, ids);
  if (static_cast<int>(ids.size()) < options.min_charuco_corners) {
    detection.reason = "only " + std::to_string(ids.size()) + " charuco corners found";
    return detection;
  }
  for (size_t i = 0; i < ids.size(); ++i) {
    detection.corners_px.emplace_back(corners[i].x, corners[i].y);
    detection.corner_ids.push_back(ids[i]);
  }
  detection.found = true;
  return detection;
}

// The board slots (row offset, column offset within the tag's 2 x 2 corners) of OpenCV's marker
// corners, which come clockwise from the marker's own top-left: top-left, top-right,
// bottom-right, bottom-left, with the AprilGrid's y pointing up the tag.
constexpr int kTagSlots[4][2] = {{1, 0}, {1, 1}, {0, 1}, {0, 0}};

// Which of OpenCV's four corners fills each slot of kTagSlots under one of the eight symmetries
// of a square: rotations by `turn` quarter turns, mirrored or not. AprilTag implementations and
// OpenCV disagree on the bit order of 36h11's codes (a rotation or a transposition of the tag),
// so the labelling of a tag's corners is not taken on trust: the symmetry under which the
// corners that face each other across the gap between neighbouring tags lie closest wins.
int CornerForSlot(int slot, int turn, bool mirrored) {
  return mirrored ? (turn - slot + 8) % 4 : (slot + turn) % 4;
}

struct DetectedTag {
  int row = 0, col = 0;
  std::array<Eigen::Vector2d, 4> corners_px;
};

// Sum over neighbouring tags of the distance between the corners facing each other across
// their gap, relative to the tags' size, under one symmetry; -1 without neighbouring tags.
double FacingCornerScore(const std::vector<DetectedTag>& tags, int turn, bool mirrored) {
  std::map<std::pair<int, int>, const DetectedTag*> at;
  for (const DetectedTag& tag : tags) at[{tag.row, tag.col}] = &tag;
  const auto slot_px = [&](const DetectedTag& tag, int dr, int dc) {
    for (int slot = 0; slot < 4; ++slot) {
      if (kTagSlots[slot][0] == dr && kTagSlots[slot][1] == dc) {
        return tag.corners_px[CornerForSlot(slot, turn, mirrored)];
      }
    }
    return Eigen::Vector2d(Eigen::Vector2d::Zero());
  };
  double score = 0.0;
  int pairs = 0;
  for (const DetectedTag& tag : tags) {
    const double side = (tag.corners_px[0] - tag.corners_px[2]).norm() / std::sqrt(2.0);
    if (const auto right = at.find({tag.row, tag.col + 1}); right != at.end()) {
      for (int dr = 0; dr < 2; ++dr) {
        score += (slot_px(tag, dr, 1) - slot_px(*right->second, dr, 0)).norm() / side;
      }
      ++pairs;
    }
    if (const auto above = at.find({tag.row + 1, tag.col}); above != at.end()) {
      for (int dc = 0; dc < 2; ++dc) {
        score += (slot_px(tag, 1, dc) - slot_px(*above->second, 0, dc)).norm() / side;
      }
      ++pairs;
    }
  }
  return pairs > 0 ? score : -1.0;
}

// The board's tags OpenCV aruco finds in `image` (family 36h11, a border of two bits), by id.
std::map<int, DetectedTag> FindTags(const cv::Mat& image, const BoardSpec& board) {
  const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_APRILTAG_36h11);
  const cv::Ptr<cv::aruco::DetectorParameters> parameters = cv::aruco::DetectorParameters::create();
  parameters->markerBorderBits = 2;
  // A mirror bends a tag's sides, so that a homography of its four corners reads its cells a
  // little off: they are read from 8 x 8 pixels each and only at their centres (on four renders
  // of 35-pixel tags through the synthetic mirror, 75 of 80 tags are read, against 66 with
  // OpenCV's defaults of 4 pixels and a margin of 0.13).
  parameters->perspectiveRemovePixelPerCell = 8;
  parameters->perspectiveRemoveIgnoredMarginPerCell = 0.3;
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(image, dictionary, marker_corners, marker_ids, parameters);
  const int tag_cols = board.cols / 2, tag_rows = board.rows / 2;
  std::map<int, DetectedTag> tags;
  std::set<int> repeated;
  for (size_t i = 0; i < marker_ids.size(); ++i) {
    const int id = marker_ids[i];
    if (id < 0 || id >= tag_cols * tag_rows) continue;  // a tag of another grid
    DetectedTag tag;
    tag.row = id / tag_cols;
    tag.col = id % tag_cols;
    for (int k = 0; k < 4; ++k) {
      const cv::Point2f& corner = marker_corners[i][k];
      tag.corners_px[k] = {corner.x, corner.y};
    }
    if (!tags.emplace(id, tag).second) repeated.insert(id);
  }
  for (const int id : repeated) tags.erase(id);  // one id seen twice (a reflection): neither
  return tags;
}

// Kalibr's AprilGrid: tags of family 36h11 with a border of two bits, found by OpenCV aruco,
// each tag's four corners refined to sub-pixel (they touch the grid's small black squares, so
// each is an X-junction) and numbered as Kalibr numbers them. Partial views count.
BoardDetection DetectAprilgrid(const cv::Mat& grey, const BoardSpec& board,
                               const DetectOptions& options) {
  std::vector<DetectedTag> tags;
  for (const auto& [id, tag] : FindTags(grey, board)) tags.push_back(tag);
  if (options.refine_subpixel && !tags.empty()) {
    std::vector<cv::Point2f> corners;
    double side_px = 0.0;
    for (const DetectedTag& tag : tags) {
      side_px += (tag.corners_px[0] - tag.corners_px[2]).norm() / std::sqrt(2.0) / tags.size();
      for (const Eigen::Vector2d& corner : tag.corners_px) {
        corners.emplace_back(corner.x(), corner.y());
      }
    }
    // The window stays within the black square beside the corner (0.3 of a tag in Kalibr's
    // default target).
    const int half = std::clamp(static_cast<int>(std::lround(0.12 * side_px)), 2, 8);
    cv::cornerSubPix(grey, corners, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 0.01));
    for (size_t t = 0; t < tags.size(); ++t) {
      for (int k = 0; k < 4; ++k) {
        tags[t].corners_px[k] = {corners[4 * t + k].x, corners[4 * t + k].y};
      }
    }
  }
  BoardDetection detection;
  detection.method = "aprilgrid";
  if (static_cast<int>(tags.size()) < options.min_aprilgrid_tags) {
    detection.reason = "found " + std::to_string(tags.size()) + " of the " +
                       std::to_string(board.NumCorners() / 4) + " tags of the " + board.Describe() +
                       " (at least " + std::to_string(options.min_aprilgrid_tags) + " needed)";
    return detection;
  }
  int best_turn = 0;
  bool best_mirrored = false;
  double best_score = std::numeric_limits<double>::infinity();
  for (const bool mirrored : {false, true}) {
    for (int turn = 0; turn < 4; ++turn) {
      const double score = FacingCornerScore(tags, turn, mirrored);
      if (score >= 0.0 && score < best_score) {
        best_score = score;
        best_turn = turn;
        best_mirrored = mirrored;
      }
    }
  }
  std::vector<std::pair<int, Eigen::Vector2d>> corners;
  for (const DetectedTag& tag : tags) {
    for (int slot = 0; slot < 4; ++slot) {
      const int id = (2 * tag.row + kTagSlots[slot][0]) * board.cols + 2 * tag.col +
                     kTagSlots[slot][1];
      corners.emplace_back(id, tag.corners_px[CornerForSlot(slot, best_turn, best_mirrored)]);
    }
  }
  std::sort(corners.begin(), corners.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [id, pixel] : corners) {
    detection.corner_ids.push_back(id);
    detection.corners_px.push_back(pixel);
  }
  detection.found = true;
  return detection;
}

// A rough model for the hint path: xi = 1, principal point at the image centre, and the gamma
// under which a board pose explains the four hinted corners best.
std::optional<std::pair<CameraModel, Rigid3d>> ModelFromHint(
    const cv::Mat& grey, const BoardSpec& board, const std::array<Eigen::Vector2d, 4>& hint) {
  const std::vector<Eigen::Vector3d> all = board.ObjectPoints();
  const std::vector<Eigen::Vector3d> outer = {all[0], all[board.cols - 1], all.back(),
                                              all[(board.rows - 1) * board.cols]};
  const std::vector<Eigen::Vector2d> pixels(hint.begin(), hint.end());
  std::optional<std::pair<CameraModel, Rigid3d>> best;
  double best_rms = std::numeric_limits<double>::infinity();
  const double size = std::max(grey.cols, grey.rows);
  for (double factor = 0.05; factor < 3.0; factor *= 1.1) {
    CameraModel camera;
    camera.width = grey.cols;
    camera.height = grey.rows;
    camera.intrinsics.params = {1.0,
                                factor * size,
                                factor * size,
                                (grey.cols - 1) / 2.0,
                                (grey.rows - 1) / 2.0,
                                0,
                                0,
                                0,
                                0,
                                0,
                                0};
    double rms = 0.0;
    const auto cam_from_board = EstimateBoardPose(camera, outer, pixels, &rms);
    if (cam_from_board && rms < best_rms) {
      best_rms = rms;
      best = std::make_pair(camera, *cam_from_board);
    }
  }
  return best;
}

// Gamma and the board pose fitted to a single view's corners with everything else fixed at the
// rough model (xi = 1, principal point at the image centre, no distortion).
std::optional<std::pair<CameraModel, Rigid3d>> RefitRoughModel(const cv::Mat& grey,
                                                               const BoardSpec& board,
                                                               const BoardDetection& detection) {
  CalibrationOptions options;
  options.min_views = 1;
  options.min_corners_per_view = 8;
  options.max_rejection_rounds = 1;
  options.fixed.fill(true);
  options.fixed[UnifiedIntrinsics::kGammaU] = options.fixed[UnifiedIntrinsics::kGammaV] = false;
  BoardDetection partial = detection;
  partial.found = true;  // a partial grid is all this fit needs
  try {
    const CalibrationReport report =
        Calibrate({{"hint", partial}}, grey.cols, grey.rows, board, options, ProgressSink());
    if (!report.images[0].used) return std::nullopt;
    return std::make_pair(report.camera, report.images[0].cam_from_board);
  } catch (const InvalidArgument&) {
    return std::nullopt;
  }
}

BoardDetection DetectFromHint(const cv::Mat& grey, const BoardSpec& board,
                              const DetectOptions& options) {
  const std::array<Eigen::Vector2d, 4>& hint = *options.outer_corners_hint_px;
  const std::vector<Eigen::Vector3d> all = board.ObjectPoints();
  const std::vector<Eigen::Vector3d> outer = {all[0], all[board.cols - 1], all.back(),
                                              all[(board.rows - 1) * board.cols]};
  const std::vector<Eigen::Vector2d> pixels(hint.begin(), hint.end());
  BoardDetection detection;
  detection.method = "hint";
  std::optional<std::pair<CameraModel, Rigid3d>> guess;
  if (options.model) {
    const auto cam_from_board = EstimateBoardPose(*options.model, outer, pixels);
    if (cam_from_board) guess = std::make_pair(*options.model, *cam_from_board);
  } else {
    guess = ModelFromHint(grey, board, hint);
  }
  if (!guess) {
    detection.reason = "the four hinted corners fit no board pose";
    return detection;
  }
  detection = DetectBoardFromPose(grey, board, guess->first, guess->second, options);
  // Without a model the first prediction bends wrongly between the hinted corners. Each further
  // pass fits gamma and the pose (xi = 1, no distortion) to every corner found so far and
  // predicts again, while that finds more corners.
  for (int pass = 0; pass < 4 && !options.model && detection.corners_px.size() >= 8 &&
                     static_cast<int>(detection.corners_px.size()) < board.NumCorners();
       ++pass) {
    const auto refit = RefitRoughModel(grey, board, detection);
    if (!refit) break;
    BoardDetection again = DetectBoardFromPose(grey, board, refit->first, refit->second, options);
    if (again.corners_px.size() <= detection.corners_px.size()) break;
    detection = std::move(again);
  }
  detection.method = "hint";
  return detection;
}

// A corner of the board as a model predicts it at a pose: where it projects with a local square
// of more than 4 px and the image shows an X-junction there.
struct PredictedCorner {
  int id;
  Eigen::Vector2d px;
  double square_px;
};

std::vector<PredictedCorner> PredictXCorners(const cv::Mat& grey, const BoardSpec& board,
                                             const CameraModel& model,
                                             const Rigid3d& cam_from_board) {
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  std::vector<Eigen::Vector2d> predicted(object_points.size(), Eigen::Vector2d::Constant(-1e9));
  for (size_t i = 0; i < object_points.size(); ++i) {
    const auto pixel = Project(model.intrinsics, cam_from_board * object_points[i]);
    if (pixel) predicted[i] = *pixel;
  }
  std::vector<PredictedCorner> corners;
  for (int id = 0; id < board.NumCorners(); ++id) {
    const double square_px = LocalSquarePx(predicted, board, id);
    if (!(square_px > 4.0) || !std::isfinite(square_px)) continue;
    if (!LooksLikeXCorner(grey, predicted[id], 0.3 * square_px)) continue;
    corners.push_back({id, predicted[id], square_px});
  }
  return corners;
}

// Refines each predicted corner; found requires at least half of the board's corners.
BoardDetection RefinePredictedCorners(const cv::Mat& grey, const BoardSpec& board,
                                      const std::vector<PredictedCorner>& predicted,
                                      const DetectOptions& options) {
  BoardDetection detection;
  detection.method = "model";
  for (const PredictedCorner& corner : predicted) {
    std::vector<Eigen::Vector2d> refined = {corner.px};
    RefineCorners(grey, &refined, {corner.square_px}, options.fit_corner_model);
    // A refinement that wanders off by more than a third of a square found something else.
    if ((refined[0] - corner.px).norm() > corner.square_px / 3.0) continue;
    detection.corners_px.push_back(refined[0]);
    detection.corner_ids.push_back(corner.id);
  }
  detection.found = 2 * static_cast<int>(detection.corner_ids.size()) >= board.NumCorners();
  if (!detection.found) {
    detection.reason = "only " + std::to_string(detection.corner_ids.size()) + " of " +
                       std::to_string(board.NumCorners()) + " predicted corners confirmed";
  }
  return detection;
}

// The eight symmetries of a sub-grid of sub_cols x sub_rows placed on the board at (dc, dr):
// the board id of sub-grid corner (c, r), or -1 when it falls off the board.
int PlacedId(const BoardSpec& board, int sub_cols, int sub_rows, int symmetry, int dc, int dr,
             int c, int r) {
  if (symmetry & 1) c = sub_cols - 1 - c;
  if (symmetry & 2) r = sub_rows - 1 - r;
  int col = c, row = r;
  if (symmetry & 4) std::swap(col, row);
  col += dc;
  row += dr;
  if (col < 0 || row < 0 || col >= board.cols || row >= board.rows) return -1;
  return row * board.cols + col;
}

// A partial grid of a view the detectors missed: its corners row by row, cols x rows.
struct PartialGrid {
  std::vector<Eigen::Vector2d> corners;
  int cols = 0;
  int rows = 0;
};

// A grid that OpenCV's sector-based detector links around a seed of seed x seed corners with
// CALIB_CB_LARGER: e.g. 6 x 7 of KaidanOmni8's 7 x 11 corners, where the camera's reflection and
// a hand hide the rest. The grid must fit on the board and hold at least 40 % of its corners.
// One call replaces one per partial size (bench_calib profile: KaidanOmni8 took 33 calls, ~8 s
// CPU). Which grid it links depends on the seed and the image, so callers try a few.
std::optional<PartialGrid> FindLinkedGrid(const cv::Mat& image, int seed, const BoardSpec& board) {
  std::vector<cv::Point2f> corners;
  cv::Mat meta;
  if (!cv::findChessboardCornersSB(image, cv::Size(seed, seed), corners,
                                   kSectorFlags | cv::CALIB_CB_LARGER, meta)) {
    return std::nullopt;
  }
  PartialGrid grid;
  grid.cols = meta.cols;
  grid.rows = meta.rows;
  if (static_cast<int>(corners.size()) != grid.cols * grid.rows ||
      std::min(grid.cols, grid.rows) > std::min(board.cols, board.rows) ||
      std::max(grid.cols, grid.rows) > std::max(board.cols, board.rows) ||
      5 * grid.cols * grid.rows < 2 * board.NumCorners()) {
    return std::nullopt;
  }
  for (const auto& c : corners) grid.corners.emplace_back(c.x, c.y);
  return grid;
}

// Every placement of a partial grid on the board (its eight symmetries, every offset), scored by
// the corners the model confirms. A placement's pose fits its grid equally well at every offset
// of a planar board, so only the corners beyond the grid tell them apart: each placement's
// X-junction candidates are counted first (cheap), and placements are refined in decreasing
// order of that count until no remaining one can confirm more corners than the best (a
// refinement keeps a subset of its candidates), instead of refining all of them.
BoardDetection BestPlacement(const cv::Mat& grey, const BoardSpec& board, const CameraModel& model,
                             const PartialGrid& grid, const DetectOptions& options) {
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  std::vector<std::vector<PredictedCorner>> placements;
  const int span = std::max(board.cols, board.rows);
  for (int symmetry = 0; symmetry < 8; ++symmetry) {
    for (int dr = 0; dr < span; ++dr) {
      for (int dc = 0; dc < span; ++dc) {
        std::vector<Eigen::Vector3d> points;
        bool fits = true;
        for (int i = 0; i < grid.cols * grid.rows && fits; ++i) {
          const int id =
              PlacedId(board, grid.cols, grid.rows, symmetry, dc, dr, i % grid.cols, i / grid.cols);
          fits = id >= 0;
          if (fits) points.push_back(object_points[id]);
        }
        if (!fits) continue;
        double rms = 0.0;
        const auto cam_from_board = EstimateBoardPose(model, points, grid.corners, &rms);
        if (!cam_from_board || rms > 3.0) continue;
        placements.push_back(PredictXCorners(grey, board, model, *cam_from_board));
      }
    }
  }
  std::stable_sort(placements.begin(), placements.end(),
                   [](const auto& a, const auto& b) { return a.size() > b.size(); });
  BoardDetection best;
  for (const std::vector<PredictedCorner>& candidates : placements) {
    if (candidates.size() <= best.corners_px.size()) break;
    BoardDetection detection = RefinePredictedCorners(grey, board, candidates, options);
    if (detection.corners_px.size() > best.corners_px.size()) best = std::move(detection);
  }
  return best;
}

}  // namespace

std::string ValidateBoardGrid(const cv::Mat& image, const BoardSpec& board,
                              const std::vector<Eigen::Vector2d>& grid) {
  board.Check();
  OMNIRIG_CHECK(!image.empty(), "detect: empty image");
  return ValidateGridImpl(ToGreyscale8(image), board, grid);
}

void DetectOptions::Check() const {
  OMNIRIG_CHECK_AT_LEAST(min_charuco_corners, 4);
  OMNIRIG_CHECK_AT_LEAST(min_aprilgrid_tags, 1);
  if (outer_corners_hint_px) {
    for (const auto& corner : *outer_corners_hint_px) {
      OMNIRIG_CHECK(corner.allFinite(), "detect: hint corners must be finite");
    }
  }
  if (model) model->intrinsics.Check();
  grid_check.Check();
  OMNIRIG_CHECK_IN(max_dropped_fraction, '[', 0, 1, ']');
}

BoardDetection DetectBoard(const cv::Mat& image, const BoardSpec& board,
                           const DetectOptions& options) {
  board.Check();
  options.Check();
  OMNIRIG_CHECK(!image.empty(), "detect: empty image");
  const cv::Mat grey = ToGreyscale8(image);
  BoardDetection detection;
  if (board.type == BoardSpec::Type::kCharuco) {
    detection = DetectCharuco(grey, board, options);
  } else if (board.type == BoardSpec::Type::kAprilgrid) {
    detection = DetectAprilgrid(grey, board, options);
  } else if (options.outer_corners_hint_px) {
    detection = DetectFromHint(grey, board, options);
  } else {
    detection = DetectCheckerboard(grey, board, options);
  }
  if (detection.found && options.refine_subpixel && detection.method != "hint" &&
      detection.method != "charuco" && detection.method != "aprilgrid") {
    const std::vector<double> square_px =
        RefineGrid(grey, board, options.fit_corner_model, &detection);
    if (options.check_grid) CheckGrid(grey, board, options, square_px, &detection);
  }
  return detection;
}

BoardDetection DetectBoardFromPose(const cv::Mat& image, const BoardSpec& board,
                                   const CameraModel& model, const Rigid3d& cam_from_board,
                                   const DetectOptions& options) {
  board.Check();
  options.Check();
  OMNIRIG_CHECK(!image.empty(), "detect: empty image");
  const cv::Mat grey = ToGreyscale8(image);
  return RefinePredictedCorners(grey, board, PredictXCorners(grey, board, model, cam_from_board),
                                options);
}

}  // namespace omnirig

namespace omnirig {

BoardDetection RedetectWithModel(const cv::Mat& image, const BoardSpec& board,
                                 const CameraModel& model, const DetectOptions& options) {
  board.Check();
  options.Check();
  OMNIRIG_CHECK(!image.empty(), "detect: empty image");
  const cv::Mat grey = ToGreyscale8(image);
  // Seeds of 4 x 4 and 3 x 3 corners on the plain and the equalised image link different
  // grids (bench_calib profile: one of the four grows each view of KaidanOmni the cheap
  // detector attempts miss), at about 0.1 s CPU each on 640x480.
  for (const DetectorImage& variant : {DetectorImage{grey, 1.0, ""}, EqualisedImage(grey)}) {
    std::pair<int, int> tried = {0, 0};
    for (const int seed : {4, 3}) {
      const auto grid = FindLinkedGrid(variant.image, seed, board);
      if (!grid || std::make_pair(grid->cols, grid->rows) == tried) continue;
      tried = {grid->cols, grid->rows};
      BoardDetection detection = BestPlacement(grey, board, model, *grid, options);
      if (detection.found) {
        detection.method = "model-grown";
        return detection;
      }
    }
  }
  BoardDetection detection;
  detection.reason = "no " + board.Describe() +
                     " found, also not by growing a partial grid "
                     "with the model of the other views";
  return detection;
}

}  // namespace omnirig
