#include "engine/dense/range_io.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <fstream>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <png.h>

#include "engine/util/check.h"

namespace omnirig::dense {

void WriteRangeTiff(const std::filesystem::path& path, const cv::Mat& range_m) {
  OMNIRIG_CHECK(range_m.type() == CV_32FC1, "a range panorama is single-channel 32-bit float");
  bool written = false;
  try {
    written = cv::imwrite(path.string(), range_m);
  } catch (const cv::Exception&) {
    written = false;
  }
  if (!written) throw std::runtime_error("cannot write " + path.string());
}

namespace {

// Palette index 0 is black (unknown); 1 .. 255 are the turbo colours from far (1) to near (255).
constexpr int kNumLevels = 255;

// The preview as palette indices, and its palette (RGB).
struct IndexedPreview {
  cv::Mat indices;  // CV_8U
  std::array<std::array<uint8_t, 3>, kNumLevels + 1> palette_rgb;
};

IndexedPreview MakeIndexedPreview(const cv::Mat& range_m) {
  OMNIRIG_CHECK(range_m.type() == CV_32FC1, "a range panorama is single-channel 32-bit float");
  IndexedPreview out;
  out.indices = cv::Mat::zeros(range_m.size(), CV_8U);
  cv::Mat levels(1, kNumLevels, CV_8U), colours;
  for (int i = 0; i < kNumLevels; ++i) {
    levels.at<uint8_t>(0, i) = static_cast<uint8_t>(std::lround(255.0 * i / (kNumLevels - 1)));
  }
  cv::applyColorMap(levels, colours, cv::COLORMAP_TURBO);
  out.palette_rgb[0] = {0, 0, 0};
  for (int i = 0; i < kNumLevels; ++i) {
    const cv::Vec3b bgr = colours.at<cv::Vec3b>(0, i);
    out.palette_rgb[i + 1] = {bgr[2], bgr[1], bgr[0]};
  }
  // The percentiles from every 8th known cell (a panorama holds about a million): the log is
  // monotonic, so they are taken on the ranges and their logs used.
  std::vector<float> known;
  int seen = 0;
  for (int r = 0; r < range_m.rows; ++r) {
    const float* row = range_m.ptr<float>(r);
    for (int c = 0; c < range_m.cols; ++c) {
      if (row[c] > 0.f && seen++ % 8 == 0) known.push_back(row[c]);
    }
  }
  if (known.empty()) return out;
  const auto percentile = [&](double q) {
    auto it = known.begin() + static_cast<std::ptrdiff_t>(q * (known.size() - 1));
    std::nth_element(known.begin(), it, known.end());
    return std::log(*it);
  };
  const float lo = percentile(0.02), hi = std::max(percentile(0.98), lo + 1e-3f);
  // Serial on purpose: the job writes previews on a thread of its own while it matches the next
  // pair, and OpenCV runs a parallel_for_ that starts while another one runs (process-wide)
  // serially, so a parallel loop here could leave the matching on one core.
  for (int r = 0; r < range_m.rows; ++r) {
    const float* row = range_m.ptr<float>(r);
    uint8_t* index = out.indices.ptr<uint8_t>(r);
    for (int c = 0; c < range_m.cols; ++c) {
      if (!(row[c] > 0.f)) continue;  // unknown stays black
      const float t = std::clamp((std::log(row[c]) - lo) / (hi - lo), 0.f, 1.f);
      // Near = high level = red.
      index[c] = static_cast<uint8_t>(1 + std::lround((kNumLevels - 1) * (1.f - t)));
    }
  }
  return out;
}

void AppendToBuffer(png_structp png, png_bytep data, png_size_t length) {
  auto* buffer = static_cast<std::vector<uint8_t>*>(png_get_io_ptr(png));
  buffer->insert(buffer->end(), data, data + length);
}

// Encodes an 8-bit indexed image as PNG into `buffer`; false when libpng fails. zlib's fastest
// level with the run-length strategy and no row filter: palette indices gain nothing from the
// filters, and the preview's long runs of one colour are what the strategy finds.
bool EncodeIndexedPng(const IndexedPreview& preview, std::vector<uint8_t>* buffer) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (png == nullptr) return false;
  png_infop info = png_create_info_struct(png);
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, buffer, AppendToBuffer, nullptr);
  png_set_compression_level(png, 1);
  png_set_compression_strategy(png, 3);  // Z_RLE
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
  png_set_IHDR(png, info, static_cast<png_uint_32>(preview.indices.cols),
               static_cast<png_uint_32>(preview.indices.rows), 8, PNG_COLOR_TYPE_PALETTE,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
  png_color palette[kNumLevels + 1];
  for (int i = 0; i <= kNumLevels; ++i) {
    palette[i] = {preview.palette_rgb[i][0], preview.palette_rgb[i][1], preview.palette_rgb[i][2]};
  }
  png_set_PLTE(png, info, palette, kNumLevels + 1);
  png_write_info(png, info);
  for (int r = 0; r < preview.indices.rows; ++r) {
    png_write_row(png, preview.indices.ptr<uint8_t>(r));
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

cv::Mat RangePreview(const cv::Mat& range_m) {
  const IndexedPreview preview = MakeIndexedPreview(range_m);
  cv::Mat bgr(preview.indices.size(), CV_8UC3);
  for (int r = 0; r < bgr.rows; ++r) {
    const uint8_t* index = preview.indices.ptr<uint8_t>(r);
    cv::Vec3b* out = bgr.ptr<cv::Vec3b>(r);
    for (int c = 0; c < bgr.cols; ++c) {
      const auto& rgb = preview.palette_rgb[index[c]];
      out[c] = cv::Vec3b(rgb[2], rgb[1], rgb[0]);
    }
  }
  return bgr;
}

void WriteRangePng(const std::filesystem::path& path, const cv::Mat& range_m) {
  std::vector<uint8_t> buffer;
  buffer.reserve(static_cast<size_t>(range_m.total()) / 2);
  bool written = EncodeIndexedPng(MakeIndexedPreview(range_m), &buffer);
  if (written) {
    std::ofstream file(path, std::ios::binary | std::ios::trunc);
    file.write(reinterpret_cast<const char*>(buffer.data()),
               static_cast<std::streamsize>(buffer.size()));
    written = static_cast<bool>(file.flush());
  }
  if (!written) throw std::runtime_error("cannot write " + path.string());
}

}  // namespace omnirig::dense
