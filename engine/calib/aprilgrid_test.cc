// Kalibr's AprilGrid: the target read from Kalibr's YAML, its corners detected in catadioptric
// renders of the grid as kalibr_create_target_pdf prints it (tags of family 36h11 with a border
// of two bits, a black square of the gap's size at every crossing of the gaps), partial views,
// and a calibration from them.

#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/synth/presets.h"
#include "engine/synth/synth_camera.h"
#include "engine/util/check.h"

namespace omnirig {
namespace {

constexpr int kTagCols = 5, kTagRows = 4;
constexpr double kTagSizeM = 0.06, kTagSpacing = 0.3;
constexpr double kPixelsPerM = 4000.0;  // of the printed target
constexpr double kMarginM = 0.02;       // white border around the grid

BoardSpec Grid() { return BoardSpec::Aprilgrid(kTagCols, kTagRows, kTagSizeM, kTagSpacing); }

double ExtentM(int tags) { return tags * kTagSizeM + (tags - 1) * kTagSpacing * kTagSizeM; }

// The printed target, row 0 at the top: board y (up as printed) is image -v.
cv::Mat PrintTarget() {
  const double width_m = ExtentM(kTagCols) + 2 * kMarginM;
  const double height_m = ExtentM(kTagRows) + 2 * kMarginM;
  cv::Mat canvas(static_cast<int>(std::lround(height_m * kPixelsPerM)),
                 static_cast<int>(std::lround(width_m * kPixelsPerM)), CV_8U, cv::Scalar(255));
  const auto to_px = [&](double x_m, double y_m) {
    return cv::Point(static_cast<int>(std::lround((x_m + kMarginM) * kPixelsPerM)),
                     static_cast<int>(std::lround((height_m - kMarginM - y_m) * kPixelsPerM)));
  };
  const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_APRILTAG_36h11);
  const int tag_px = static_cast<int>(std::lround(kTagSizeM * kPixelsPerM));
  const double step_m = (1 + kTagSpacing) * kTagSizeM;
  for (int r = 0; r < kTagRows; ++r) {
    for (int c = 0; c < kTagCols; ++c) {
      cv::Mat tag;
      cv::aruco::drawMarker(dictionary, r * kTagCols + c, tag_px, tag, /*borderBits=*/2);
      // Tag (r, c) spans [c step, c step + size] x [r step, r step + size]; its top-left as
      // printed is at the larger y.
      const cv::Point top_left = to_px(c * step_m, r * step_m + kTagSizeM);
      tag.copyTo(canvas(cv::Rect(top_left.x, top_left.y, tag_px, tag_px)));
    }
  }
  const double gap_m = kTagSpacing * kTagSizeM;
  for (int r = 0; r <= kTagRows; ++r) {
    for (int c = 0; c <= kTagCols; ++c) {
      const cv::Point a = to_px(c * step_m - gap_m, r * step_m);
      const cv::Point b = to_px(c * step_m, r * step_m - gap_m);
      cv::rectangle(canvas, cv::Rect(a, b), cv::Scalar(0), cv::FILLED);
    }
  }
  return canvas;
}

// Pose of the printed grid, y up and the camera on its +z side, from a pose the checkerboard
// sampler draws (board y down, camera on its -z side) for a board of the grid's extent.
Rigid3d CamFromGrid(const synth::SynthCamera& camera, int index, int num_views) {
  synth::CheckerboardSpec outline;
  outline.cols = kTagCols;
  outline.rows = kTagRows;
  outline.square_size_m = ExtentM(kTagCols) / (outline.cols + 1);
  outline.margin_m = kMarginM + (ExtentM(kTagRows) - (outline.rows + 1) * outline.square_size_m) / 2;
  synth::BoardPoseOptions options;
  options.min_distance_m = 0.3;
  options.max_distance_m = 0.5;
  options.max_tilt_deg = 40.0;
  const Rigid3d cam_from_board =
      synth::SampleBoardPose({camera}, {Rigid3d()}, outline, options, index, num_views, 7);
  // Grid point (x, y, z) is board point (x - square, top - y, -z), top = the grid's top edge in
  // the board frame.
  const double top_m = ExtentM(kTagRows) - outline.square_size_m -
                       (ExtentM(kTagRows) - (outline.rows + 1) * outline.square_size_m) / 2;
  const Rigid3d board_from_grid(Eigen::Quaterniond(0, 1, 0, 0),
                                Eigen::Vector3d(-outline.square_size_m, top_m, 0));
  return cam_from_board * board_from_grid;
}

// The target seen by the camera: each pixel the average of 3 x 3 rays' hits on the print, dark
// outside the mirror's annulus, mid grey where a ray misses the print.
cv::Mat RenderView(const synth::SynthCamera& camera, const cv::Mat& print,
                   const Rigid3d& cam_from_grid) {
  const CameraModel& model = camera.model;
  cv::Mat image(model.height, model.width, CV_8U, cv::Scalar(0));
  const Rigid3d grid_from_cam = cam_from_grid.Inverse();
  const double height_m = print.rows / kPixelsPerM;
  // Only the pixels around the print's image need rays.
  double u_min = model.width, u_max = 0, v_min = model.height, v_max = 0;
  for (double x = -kMarginM; x <= ExtentM(kTagCols) + kMarginM + 1e-9; x += 0.005) {
    for (double y = -kMarginM; y <= ExtentM(kTagRows) + kMarginM + 1e-9; y += 0.005) {
      const auto pixel = Project(model.intrinsics, cam_from_grid * Eigen::Vector3d(x, y, 0));
      if (!pixel) continue;
      u_min = std::min(u_min, pixel->x()), u_max = std::max(u_max, pixel->x());
      v_min = std::min(v_min, pixel->y()), v_max = std::max(v_max, pixel->y());
    }
  }
  for (int v = std::max(0, int(v_min) - 3); v < std::min(model.height, int(v_max) + 4); ++v) {
    for (int u = std::max(0, int(u_min) - 3); u < std::min(model.width, int(u_max) + 4); ++u) {
      if (!synth::InAnnulus(camera, Eigen::Vector2d(u, v))) continue;
      double sum = 0.0;
      for (int i = 0; i < 9; ++i) {
        const Eigen::Vector2d pixel(u + (i % 3 - 1) / 3.0, v + (i / 3 - 1) / 3.0);
        const auto bearing = Lift(model.intrinsics, pixel);
        double value = 128.0;
        if (bearing) {
          const Eigen::Vector3d origin = grid_from_cam.translation;
          const Eigen::Vector3d direction = grid_from_cam.rotation * *bearing;
          const double t = -origin.z() / direction.z();
          if (std::isfinite(t) && t > 0) {
            const Eigen::Vector3d hit = origin + t * direction;
            const float px = static_cast<float>((hit.x() + kMarginM) * kPixelsPerM);
            const float py = static_cast<float>((height_m - kMarginM - hit.y()) * kPixelsPerM);
            if (px >= 0 && py >= 0 && px < print.cols - 1 && py < print.rows - 1) {
              cv::Mat sample;
              cv::getRectSubPix(print, cv::Size(1, 1), cv::Point2f(px, py), sample, CV_32F);
              value = 25.0 + sample.at<float>(0) * (210.0 / 255.0);
            }
          }
        }
        sum += value;
      }
      image.at<uchar>(v, u) = cv::saturate_cast<uchar>(sum / 9.0);
    }
  }
  return image;
}

// Distances between the detected corners and their exact projections, sorted.
std::vector<double> CornerErrorsPx(const BoardDetection& detection, const CameraModel& model,
                                   const Rigid3d& cam_from_grid) {
  const std::vector<Eigen::Vector3d> points = Grid().ObjectPoints();
  std::vector<double> errors;
  for (size_t i = 0; i < detection.corner_ids.size(); ++i) {
    const auto truth = Project(model.intrinsics, cam_from_grid * points[detection.corner_ids[i]]);
    errors.push_back(truth ? (*truth - detection.corners_px[i]).norm() : 1e9);
  }
  std::sort(errors.begin(), errors.end());
  return errors;
}

// A wrong labelling would put corners a tag's size (tens of pixels) away.
void ExpectAccurateCorners(const BoardDetection& detection, const CameraModel& model,
                           const Rigid3d& cam_from_grid) {
  const std::vector<double> errors = CornerErrorsPx(detection, model, cam_from_grid);
  ASSERT_FALSE(errors.empty());
  EXPECT_LT(errors[errors.size() / 2], 0.2);
  EXPECT_LT(errors.back(), 1.0);
}

TEST(Aprilgrid, ObjectPointsAreKalibrs) {
  const std::vector<Eigen::Vector3d> points = Grid().ObjectPoints();
  ASSERT_EQ(points.size(), size_t{4 * kTagCols * kTagRows});
  const int cols = 2 * kTagCols;
  // Tag 0's corners, then tag 1's first corner: a gap of spacing x size along x.
  EXPECT_NEAR(points[1].x(), kTagSizeM, 1e-12);
  EXPECT_NEAR(points[2].x(), (1 + kTagSpacing) * kTagSizeM, 1e-12);
  EXPECT_NEAR(points[cols].y(), kTagSizeM, 1e-12);
  EXPECT_NEAR(points[2 * cols].y(), (1 + kTagSpacing) * kTagSizeM, 1e-12);
  EXPECT_EQ(Grid().Describe(), "aprilgrid 5x4 tags (60 mm, spacing 0.3)");
}

TEST(Aprilgrid, ReadsKalibrTargetYaml) {
  const BoardSpec grid = BoardFromKalibrTarget(
      "target_type: 'aprilgrid' #gridtype\n"
      "tagCols: 6               #number of apriltags\n"
      "tagRows: 5\n"
      "tagSize: 0.088           #size of apriltag, edge to edge [m]\n"
      "tagSpacing: 0.3          #ratio of space between tags to tagSize\n");
  EXPECT_EQ(grid.type, BoardSpec::Type::kAprilgrid);
  EXPECT_EQ(grid.cols, 12);
  EXPECT_EQ(grid.rows, 10);
  EXPECT_DOUBLE_EQ(grid.square_size_m, 0.088);
  EXPECT_DOUBLE_EQ(grid.tag_spacing, 0.3);
  const BoardSpec checkerboard = BoardFromKalibrTarget(
      "target_type: 'checkerboard'\ntargetCols: 6\ntargetRows: 7\nrowSpacingMeters: 0.06\n"
      "colSpacingMeters: 0.06\n");
  EXPECT_EQ(checkerboard.type, BoardSpec::Type::kCheckerboard);
  EXPECT_EQ(checkerboard.cols, 6);
  EXPECT_DOUBLE_EQ(checkerboard.square_size_m, 0.06);
  const auto error = [](const std::string& yaml) {
    try {
      BoardFromKalibrTarget(yaml);
    } catch (const InvalidArgument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error("target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0.08\n")
                .find("'tagSpacing'"),
            std::string::npos);
  EXPECT_NE(error("target_type: 'circlegrid'\n").find("circlegrid"), std::string::npos);
  EXPECT_NE(error("target_type: 'aprilgrid'\ntagCols: six\ntagRows: 6\ntagSize: 0.08\n"
                  "tagSpacing: 0.3\n")
                .find("'tagCols'"),
            std::string::npos);
  EXPECT_NE(error("target_type: 'aprilgrid'\ntagCols: 30\ntagRows: 30\ntagSize: 0.08\n"
                  "tagSpacing: 0.3\n")
                .find("587"),
            std::string::npos);
}

TEST(Aprilgrid, DetectsCornersWithKalibrsNumbering) {
  const synth::SynthCamera camera = synth::DefaultCamera(1280, 1024);
  const cv::Mat print = PrintTarget();
  for (int view = 0; view < 4; ++view) {
    const Rigid3d cam_from_grid = CamFromGrid(camera, view, 4);
    const BoardDetection detection =
        DetectBoard(RenderView(camera, print, cam_from_grid), Grid(), DetectOptions());
    ASSERT_TRUE(detection.found) << "view " << view << ": " << detection.reason;
    EXPECT_EQ(detection.method, "aprilgrid");
    // Tags the mirror bends most can be missed; their corners are left out, not guessed.
    EXPECT_GE(detection.corner_ids.size(), size_t{4 * kTagCols * kTagRows * 8 / 10})
        << "view " << view;
    EXPECT_EQ(detection.corner_ids.size() % 4, 0u);
    SCOPED_TRACE("view " + std::to_string(view));
    ExpectAccurateCorners(detection, camera.model, cam_from_grid);
  }
}

TEST(Aprilgrid, PartialAndUpsideDownViewsCount) {
  const synth::SynthCamera camera = synth::DefaultCamera(1280, 1024);
  cv::Mat print = PrintTarget();
  // The right half of the print hidden (a hand over the board).
  print(cv::Rect(print.cols / 2, 0, print.cols - print.cols / 2, print.rows)).setTo(128);
  // Turned upside down in its plane, about the grid's centre.
  const Eigen::Vector3d centre(ExtentM(kTagCols) / 2, ExtentM(kTagRows) / 2, 0);
  const Rigid3d turn = Rigid3d(Eigen::Quaterniond::Identity(), centre) *
                       Rigid3d(Eigen::Quaterniond(0, 0, 0, 1), Eigen::Vector3d::Zero()) *
                       Rigid3d(Eigen::Quaterniond::Identity(), -centre);
  const Rigid3d cam_from_grid = CamFromGrid(camera, 1, 4) * turn;
  const BoardDetection detection =
      DetectBoard(RenderView(camera, print, cam_from_grid), Grid(), DetectOptions());
  ASSERT_TRUE(detection.found) << detection.reason;
  EXPECT_GE(detection.corner_ids.size(), size_t{4 * (kTagCols / 2 - 1) * kTagRows});
  EXPECT_LE(detection.corner_ids.size(), size_t{4 * (kTagCols / 2 + 1) * kTagRows});
  ExpectAccurateCorners(detection, camera.model, cam_from_grid);
}

TEST(Aprilgrid, CalibratesFromItsViews) {
  const synth::SynthCamera camera = synth::DefaultCamera(1280, 1024);
  const cv::Mat print = PrintTarget();
  constexpr int kViews = 10;
  std::vector<CalibrationView> views;
  for (int view = 0; view < kViews; ++view) {
    const cv::Mat image = RenderView(camera, print, CamFromGrid(camera, view, kViews));
    views.push_back({"view_" + std::to_string(view), DetectBoard(image, Grid(), DetectOptions())});
    ASSERT_TRUE(views.back().detection.found) << views.back().detection.reason;
  }
  const CalibrationReport report = Calibrate(views, camera.model.width, camera.model.height,
                                             Grid(), CalibrationOptions(), {});
  EXPECT_EQ(report.num_views_used, kViews);
  EXPECT_LT(report.rms_px, 0.15);
  const UnifiedIntrinsics& truth = camera.model.intrinsics;
  const UnifiedIntrinsics& estimate = report.camera.intrinsics;
  EXPECT_NEAR(estimate.gamma_u() / truth.gamma_u(), 1.0, 0.01);
  EXPECT_NEAR(estimate.u0(), truth.u0(), 1.0);
  EXPECT_NEAR(estimate.v0(), truth.v0(), 1.0);
  // The rays of the calibrated model against the true ones where the boards were seen.
  for (const CalibrationView& view : views) {
    for (const Eigen::Vector2d& pixel : view.detection.corners_px) {
      const auto a = Lift(truth, pixel);
      const auto b = Lift(estimate, pixel);
      ASSERT_TRUE(a && b);
      EXPECT_LT(std::acos(std::clamp(a->dot(*b), -1.0, 1.0)) * 180 / M_PI, 0.05);
    }
  }
}

}  // namespace
}  // namespace omnirig
