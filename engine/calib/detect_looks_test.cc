// The detector on boards as real ones look (engine/synth BoardLook): margins of any width, a
// frame of another grey, a hand over a corner, a specular highlight, a paracatadioptric camera
// at 1280x1024 in 8-bit grey PGM. Wherever OpenCV's own detectors find the board at its size,
// omnirig must find it too, to sub-pixel, and never call it a sub-board of a larger board.

#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "engine/calib/detect.h"
#include "engine/synth/presets.h"
#include "testing/synth/calib_board.h"

namespace omnirig {
namespace {

struct LookCase {
  std::string name;
  double margin_m = 0.03;
  synth::BoardLook look;
  bool parabolic = false;
};

std::vector<LookCase> Cases() {
  std::vector<LookCase> cases;
  cases.push_back({"narrow margin", 0.004, {}, false});
  cases.push_back({"wide margin", 0.08, {}, false});
  LookCase dark_frame{"dark frame", 0.01, {}, false};
  dark_frame.look.frame_width_m = 0.03;
  dark_frame.look.frame_grey = 0.15;
  cases.push_back(dark_frame);
  LookCase grey_frame{"grey frame, no margin", 0.0, {}, false};
  grey_frame.look.frame_width_m = 0.05;
  grey_frame.look.frame_grey = 0.6;
  cases.push_back(grey_frame);
  LookCase light_frame{"light frame", 0.006, {}, false};
  light_frame.look.frame_width_m = 0.04;
  light_frame.look.frame_grey = 1.0;
  cases.push_back(light_frame);
  LookCase hand{"hand over a corner", 0.02, {}, false};
  hand.look.hand = true;
  cases.push_back(hand);
  LookCase glare{"specular highlight", 0.03, {}, false};
  glare.look.highlight_sigma_squares = 0.8;
  cases.push_back(glare);
  LookCase parabolic{"parabolic mirror, grey PGM, frame and hand", 0.03, {}, true};
  parabolic.look.frame_width_m = 0.02;
  parabolic.look.frame_grey = 0.4;
  parabolic.look.hand = true;
  cases.push_back(parabolic);
  return cases;
}

synth::MonoCalibrationSet Render(const LookCase& c) {
  synth::MonoCalibrationOptions options;
  options.num_views = 4;
  options.width = c.parabolic ? 1280 : 640;
  options.height = c.parabolic ? 1024 : 480;
  if (c.parabolic) options.camera = synth::ParabolicCamera(1280, 1024);
  options.board.margin_m = c.margin_m;
  options.look = c.look;
  options.render.supersampling = 2;
  options.render.noise_sigma = 2.0;
  options.render.blur_sigma_px = 0.5;
  options.render.grayscale = c.parabolic;
  options.render.num_threads = 2;
  options.seed = 11;
  synth::MonoCalibrationSet set = synth::MakeMonoCalibrationSet(options);
  if (c.parabolic) {
    // Through the file format a user uploads: 8-bit grey PGM.
    for (cv::Mat& image : set.images) {
      std::vector<uint8_t> bytes;
      EXPECT_TRUE(cv::imencode(".pgm", image, bytes));
      image = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
      EXPECT_EQ(image.type(), CV_8UC1);
    }
  }
  return set;
}

bool OpenCvFinds(const cv::Mat& image, const BoardSpec& board) {
  std::vector<cv::Point2f> corners;
  const cv::Size size(board.cols, board.rows);
  return cv::findChessboardCorners(image, size, corners,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE) ||
         cv::findChessboardCornersSB(image, size, corners, cv::CALIB_CB_NORMALIZE_IMAGE);
}

TEST(DetectLooks, EveryBoardOpenCvFindsIsFoundAndNoneIsCalledASubBoard) {
  for (const LookCase& c : Cases()) {
    SCOPED_TRACE(c.name);
    const synth::MonoCalibrationSet set = Render(c);
    const BoardSpec board = ToBoardSpec(set.board);
    int opencv_found = 0, omnirig_found = 0;
    for (size_t v = 0; v < set.images.size(); ++v) {
      const bool opencv = OpenCvFinds(set.images[v], board);
      const BoardDetection detection = DetectBoard(set.images[v], board, DetectOptions());
      opencv_found += opencv;
      omnirig_found += detection.found;
      EXPECT_EQ(detection.reason.find("sub-board"), std::string::npos)
          << set.names[v] << ": " << detection.reason;
      if (opencv) {
        EXPECT_TRUE(detection.found) << set.names[v] << ": " << detection.reason;
      }
      if (detection.found) {
        EXPECT_GE(detection.corners_px.size(), static_cast<size_t>(board.NumCorners() - 2))
            << set.names[v];
        EXPECT_LT(MeanCornerError(detection, set.corners_px[v]), 0.3) << set.names[v];
      }
    }
    std::cout << c.name << ": OpenCV finds " << opencv_found << ", omnirig " << omnirig_found
              << " of " << set.images.size() << "\n";
    EXPECT_GE(omnirig_found, opencv_found);
    // The renders are meant to be detectable: a variant nobody finds tests nothing.
    EXPECT_GE(omnirig_found, 3);
  }
}

TEST(DetectLooks, ASizeOneTooSmallIsCalledWrongWithTheSizeSeen) {
  LookCase c{"wide margin and frame", 0.06, {}, false};
  c.look.frame_width_m = 0.03;
  c.look.frame_grey = 0.3;
  const synth::MonoCalibrationSet set = Render(c);
  const BoardSpec board = ToBoardSpec(set.board);
  const auto& truth = set.corners_px[0];
  EXPECT_EQ(ValidateBoardGrid(set.images[0], board, truth), "");
  // The first cols - 1 columns: the squares continue beyond the last one.
  BoardSpec narrower = board;
  narrower.cols -= 1;
  std::vector<Eigen::Vector2d> sub;
  for (int r = 0; r < board.rows; ++r) {
    for (int col = 0; col + 1 < board.cols; ++col) sub.push_back(truth[r * board.cols + col]);
  }
  const std::string reason = ValidateBoardGrid(set.images[0], narrower, sub);
  EXPECT_NE(reason.find("size looks wrong"), std::string::npos) << reason;
  const std::string seen = "at least " + std::to_string(board.cols) + "x" + std::to_string(board.rows);
  EXPECT_NE(reason.find(seen), std::string::npos) << reason;
}

}  // namespace
}  // namespace omnirig
