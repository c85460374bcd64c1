#include "storage/image_header.h"

#include <algorithm>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

namespace omnirig::storage {
namespace {

std::string PngHeader(uint32_t width, uint32_t height) {
  std::string png("\x89PNG\r\n\x1a\n", 8);
  png += std::string("\0\0\0\x0dIHDR", 8);
  for (uint32_t value : {width, height}) {
    for (int shift = 24; shift >= 0; shift -= 8) png.push_back(static_cast<char>(value >> shift));
  }
  png += std::string("\x08\x00\x00\x00\x00", 5);
  return png;
}

TEST(ImageHeader, ReadsPngSize) {
  const ImageHeader header = ProbeImageHeader(PngHeader(1024, 768));
  ASSERT_EQ(header.status, ImageHeader::Status::kOk) << header.problem;
  EXPECT_EQ(header.format, "png");
  EXPECT_EQ(header.content_type, "image/png");
  EXPECT_EQ(header.width, 1024);
  EXPECT_EQ(header.height, 768);
}

TEST(ImageHeader, ReadsJpegSizeAfterApplicationSegment) {
  std::string jpeg("\xFF\xD8", 2);
  jpeg += std::string("\xFF\xE0\x00\x06JFIF", 8);                       // APP0, 4 bytes
  jpeg += std::string("\xFF\xC0\x00\x11\x08\x02\x58\x03\xC0\x03", 10);  // 960x600
  jpeg += std::string(20, '\0');
  const ImageHeader header = ProbeImageHeader(jpeg);
  ASSERT_EQ(header.status, ImageHeader::Status::kOk) << header.problem;
  EXPECT_EQ(header.width, 960);
  EXPECT_EQ(header.height, 600);
}

TEST(ImageHeader, ReadsPgm) {
  const ImageHeader header = ProbeImageHeader("P5\n# comment\n640 480\n255\n\x01\x02");
  ASSERT_EQ(header.status, ImageHeader::Status::kOk) << header.problem;
  EXPECT_EQ(header.width, 640);
  EXPECT_EQ(header.height, 480);
}

TEST(ImageHeader, RefusesNonImagesAndCorruptHeaders) {
  EXPECT_EQ(ProbeImageHeader("hello, not an image").status, ImageHeader::Status::kNotAnImage);
  EXPECT_EQ(ProbeImageHeader("").status, ImageHeader::Status::kNotAnImage);
  EXPECT_EQ(ProbeImageHeader(PngHeader(100, 100).substr(0, 14)).status,
            ImageHeader::Status::kCorrupt);
  EXPECT_EQ(ProbeImageHeader(PngHeader(0, 100)).status, ImageHeader::Status::kCorrupt);
  EXPECT_EQ(ProbeImageHeader(std::string("\xFF\xD8\xFF\xE0\x00\x10", 6)).status,
            ImageHeader::Status::kCorrupt);
}

std::string Encode(const std::string& ext, const cv::Mat& image,
                   const std::vector<int>& params = {}) {
  std::vector<uint8_t> bytes;
  EXPECT_TRUE(cv::imencode(ext, image, bytes, params));
  return std::string(bytes.begin(), bytes.end());
}

cv::Mat Gradient(int channels) {
  cv::Mat image(48, 64, CV_8UC(channels));
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols * channels; ++x) image.ptr<uint8_t>(y)[x] = (x * 7 + y * 3) % 256;
  }
  return image;
}

// The completeness check's verdict on `bytes`, fed in pieces of `piece` bytes as an upload
// arrives.
std::string Completeness(const std::string& bytes, size_t piece = 1000) {
  const std::string head = bytes.substr(0, kImageProbeBytes);
  const ImageHeader header = ProbeImageHeader(head);
  EXPECT_EQ(header.status, ImageHeader::Status::kOk) << header.problem;
  ImageCompletenessCheck check;
  for (size_t at = 0; at < bytes.size(); at += piece) {
    check.Append(bytes.data() + at, std::min(piece, bytes.size() - at));
  }
  return check.Finish(header, head);
}

TEST(ImageCompleteness, WholeFilesOfEveryFormatPass) {
  for (const std::string ext : {".png", ".jpg", ".pgm", ".ppm", ".bmp"}) {
    const cv::Mat image = Gradient(ext == ".pgm" ? 1 : 3);
    EXPECT_EQ(Completeness(Encode(ext, image)), "") << ext;
    EXPECT_EQ(Completeness(Encode(ext, image), 1), "") << ext << " byte by byte";
  }
  // ASCII PGM, a progressive JPEG, and a trailer after the end.
  EXPECT_EQ(Completeness(Encode(".pgm", Gradient(1), {cv::IMWRITE_PXM_BINARY, 0})), "");
  EXPECT_EQ(Completeness(Encode(".jpg", Gradient(3), {cv::IMWRITE_JPEG_PROGRESSIVE, 1})), "");
  EXPECT_EQ(Completeness(Encode(".jpg", Gradient(3)) + "trailer"), "");
}

TEST(ImageCompleteness, TruncatedFilesAreRefusedWithTheReason) {
  for (const std::string ext : {".png", ".jpg", ".pgm", ".ppm", ".bmp"}) {
    const std::string whole = Encode(ext, Gradient(ext == ".pgm" ? 1 : 3));
    for (const size_t cut : {whole.size() - 1, whole.size() - 20, whole.size() / 2}) {
      const std::string problem = Completeness(whole.substr(0, cut));
      EXPECT_NE(problem.find("truncated"), std::string::npos) << ext << " cut at " << cut;
    }
  }
  const std::string ascii = Encode(".pgm", Gradient(1), {cv::IMWRITE_PXM_BINARY, 0});
  EXPECT_NE(Completeness(ascii.substr(0, ascii.size() / 2)).find("truncated"), std::string::npos);
  const std::string progressive = Encode(".jpg", Gradient(3), {cv::IMWRITE_JPEG_PROGRESSIVE, 1});
  EXPECT_NE(Completeness(progressive.substr(0, progressive.size() - 2)).find("truncated"),
            std::string::npos);
}

TEST(ImageCompleteness, ACorruptPngChunkFailsItsCrc) {
  std::string png = Encode(".png", Gradient(3));
  png[png.size() / 2] = static_cast<char>(png[png.size() / 2] ^ 0x10);  // inside IDAT
  const std::string problem = Completeness(png);
  EXPECT_NE(problem.find("CRC"), std::string::npos) << problem;
  EXPECT_NE(problem.find("IDAT"), std::string::npos) << problem;
}

}  // namespace
}  // namespace omnirig::storage
