#include "storage/image_header.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace omnirig::storage
