#include "engine/features/mirror_mask.h"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// A bright mirror disk (rim 360 px, hole 80 px) around (512, 384) on a dark border, with a dark
// object inside the mirror.
cv::Mat MirrorImage() {
  cv::Mat image(768, 1024, CV_8UC3, cv::Scalar(6, 6, 6));
  cv::circle(image, cv::Point(512, 384), 360, cv::Scalar(150, 160, 170), cv::FILLED);
  cv::circle(image, cv::Point(512, 384), 80, cv::Scalar(6, 6, 6), cv::FILLED);
  cv::rectangle(image, cv::Rect(700, 300, 40, 40), cv::Scalar(3, 3, 3), cv::FILLED);
  return image;
}

TEST(EstimateMirrorAnnulus, FindsRimAndHole) {
  const MirrorAnnulus annulus = EstimateMirrorAnnulus(MirrorImage(), {512, 384}, 24);
  EXPECT_NEAR(annulus.rim_radius_px, 360, 3);
  EXPECT_NEAR(annulus.hole_radius_px, 80, 3);
}

TEST(MirrorMask, AnnulusIsShrunkByTheMarginAndIgnoresDarkSceneInside) {
  MirrorMaskOptions options;
  options.shape = MirrorMaskOptions::Shape::kAnnulus;
  options.dark_level = 24;
  options.margin_px = 8;
  const cv::Mat mask = MirrorMask(MirrorImage(), {512, 384}, options);
  EXPECT_EQ(mask.at<uint8_t>(5, 5), 0);
  EXPECT_EQ(mask.at<uint8_t>(384, 512), 0);
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 84), 0);  // hole edge + margin
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 200), 255);
  EXPECT_EQ(mask.at<uint8_t>(320, 720), 255);      // a circle does not follow the dark object
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 355), 0);  // within the margin of the rim
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 345), 255);
}

TEST(MirrorMask, DarkRegionsMasksRimAndHoleButKeepsDarkSceneInside) {
  MirrorMaskOptions options;  // kDarkRegions, dark_level 20, margin 6
  const cv::Mat mask = MirrorMask(MirrorImage(), {512, 384}, options);
  EXPECT_EQ(mask.at<uint8_t>(5, 5), 0);           // outside the rim
  EXPECT_EQ(mask.at<uint8_t>(384, 512), 0);       // the hole
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 83), 0);  // hole edge + margin
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 200), 255);
  EXPECT_EQ(mask.at<uint8_t>(320, 720), 255);      // the dark object inside the mirror
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 357), 0);  // within the margin of the rim
  EXPECT_EQ(mask.at<uint8_t>(384, 512 + 350), 255);
}

// A grid whose rows run from a dark rim (columns < 20) to a dark hole (columns >= 180), with a
// dark patch in the middle of row band 40-59, and no image in the last 10 rows.
TEST(MirrorMask, DarkRowEndsMasksTheRunsFromEitherEndAndCellsWithoutImage) {
  cv::Mat grid(100, 200, CV_8U, cv::Scalar(150));
  grid.colRange(0, 20).setTo(5);
  grid.colRange(180, 200).setTo(5);
  grid(cv::Rect(90, 40, 20, 20)).setTo(5);
  cv::Mat valid(100, 200, CV_8U, cv::Scalar(255));
  valid.rowRange(90, 100).setTo(0);
  MirrorMaskOptions options;
  options.shape = MirrorMaskOptions::Shape::kDarkRowEnds;
  options.margin_px = 4;
  const cv::Mat mask = MirrorMask(grid, Eigen::Vector2d::Zero(), options, valid);
  EXPECT_EQ(mask.at<uint8_t>(20, 10), 0);
  EXPECT_EQ(mask.at<uint8_t>(20, 22), 0);  // within the margin of the rim
  EXPECT_EQ(mask.at<uint8_t>(20, 30), 255);
  EXPECT_EQ(mask.at<uint8_t>(50, 100), 255);  // the dark patch does not reach a row's end
  EXPECT_EQ(mask.at<uint8_t>(20, 170), 255);
  EXPECT_EQ(mask.at<uint8_t>(20, 190), 0);
  EXPECT_EQ(mask.at<uint8_t>(95, 100), 0);  // no image
  EXPECT_EQ(mask.at<uint8_t>(87, 100), 0);  // within the margin of the cells without image
  EXPECT_EQ(mask.at<uint8_t>(2, 100), 0);   // the grid's edge counts as outside
  EXPECT_EQ(mask.at<uint8_t>(10, 100), 255);
}

TEST(MirrorMask, RefusesInvalidOptionsAndValidMasks) {
  MirrorMaskOptions options;
  options.dark_level = 300;
  EXPECT_THROW(MirrorMask(MirrorImage(), {512, 384}, options), InvalidArgument);
  options = MirrorMaskOptions();
  options.shape = MirrorMaskOptions::Shape::kDarkRowEnds;
  EXPECT_THROW(MirrorMask(MirrorImage(), {512, 384}, options, cv::Mat(10, 10, CV_8U)),
               InvalidArgument);
}

}  // namespace
}  // namespace omnirig
