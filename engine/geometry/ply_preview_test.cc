#include "engine/geometry/ply_preview.h"

#include <cstring>
#include <fstream>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "engine/geometry/ply.h"

namespace omnirig {
namespace {

namespace fs = std::filesystem;

fs::path TempDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() /
                       ("omnirig_ply_preview_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// A cloud whose every vertex can be told apart: x = i, colour and confidence from i.
PlyCloud Numbered(int n) {
  PlyCloud cloud;
  cloud.comment = "frame: test, unit: m";
  cloud.has_confidence = true;
  for (int i = 0; i < n; ++i) {
    cloud.positions.emplace_back(static_cast<float>(i), 0.5f * i, -1.0f);
    cloud.colours.push_back(
        {static_cast<uint8_t>(i % 256), static_cast<uint8_t>(i / 256 % 256), 7});
    cloud.confidence.push_back(static_cast<float>(i % 1000) / 1000.0f);
  }
  return cloud;
}

std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

TEST(PlyPreview, KeepsARandomSubsetWithEveryPropertyUnderTheBounds) {
  const fs::path dir = TempDir("subset");
  const int n = 10000;
  WritePly(dir / "map.ply", Numbered(n));
  PlyPreviewOptions options;
  options.max_points = 1500;
  options.max_bytes = 1 << 20;
  const auto preview = WritePlyPreview(dir / "map.ply", options);
  ASSERT_TRUE(preview);
  EXPECT_EQ(preview->path, dir / "map.preview.ply");
  EXPECT_EQ(preview->source_points, n);
  EXPECT_EQ(preview->preview_points, 1500);
  const std::string bytes = ReadAll(preview->path);
  const size_t body = bytes.find("end_header\n") + 11;
  const std::string header = bytes.substr(0, body);
  EXPECT_EQ(header.rfind("ply\nformat binary_little_endian 1.0\ncomment preview: 1500 of 10000", 0),
            0u)
      << header;
  EXPECT_NE(header.find("comment frame: test, unit: m\n"), std::string::npos);
  EXPECT_NE(header.find("element vertex 1500\n"), std::string::npos);
  EXPECT_NE(header.find("property float confidence\n"), std::string::npos);
  const size_t stride = 19;
  ASSERT_EQ(bytes.size() - body, 1500 * stride);
  // Each kept vertex is one of the source's, whole, in the source's order, spread over it.
  std::set<int> kept;
  int previous = -1;
  for (size_t k = 0; k < 1500; ++k) {
    const char* v = bytes.data() + body + k * stride;
    float x, y, confidence;
    std::memcpy(&x, v, 4);
    std::memcpy(&y, v + 4, 4);
    std::memcpy(&confidence, v + 15, 4);
    const int i = static_cast<int>(x);
    ASSERT_GT(i, previous);
    previous = i;
    EXPECT_FLOAT_EQ(y, 0.5f * i);
    EXPECT_EQ(static_cast<uint8_t>(v[12]), i % 256);
    EXPECT_EQ(static_cast<uint8_t>(v[13]), i / 256 % 256);
    EXPECT_EQ(v[14], 7);
    EXPECT_FLOAT_EQ(confidence, static_cast<float>(i % 1000) / 1000.0f);
    kept.insert(i / 1000);
  }
  EXPECT_EQ(kept.size(), 10u);  // every tenth of the cloud is represented
  // The same cloud gives the same preview.
  const std::string first = bytes;
  ASSERT_TRUE(WritePlyPreview(dir / "map.ply", options));
  EXPECT_EQ(ReadAll(dir / "map.preview.ply"), first);
  fs::remove_all(dir);
}

TEST(PlyPreview, TheByteBoundLimitsThePointsAndSmallCloudsGetNone) {
  const fs::path dir = TempDir("bounds");
  WritePly(dir / "big.ply", Numbered(5000));
  WritePly(dir / "small.ply", Numbered(100));
  fs::create_directories(dir / "pairs");
  WritePly(dir / "pairs" / "p1.ply", Numbered(3000));
  PlyPreviewOptions options;
  options.max_points = 1'000'000;
  options.max_bytes = 40'000;  // about 2,000 vertices of 19 bytes
  const std::vector<PlyPreview> previews = WritePlyPreviews(dir, options);
  ASSERT_EQ(previews.size(), 2u);
  EXPECT_EQ(previews[0].path, dir / "big.preview.ply");
  EXPECT_EQ(previews[1].path, dir / "pairs" / "p1.preview.ply");
  for (const PlyPreview& preview : previews) {
    EXPECT_LE(static_cast<int64_t>(fs::file_size(preview.path)), options.max_bytes);
    EXPECT_GT(preview.preview_points, 1900);
  }
  EXPECT_FALSE(fs::exists(dir / "small.preview.ply"));
  // Previews are not previewed again, and no temporary file is left behind.
  EXPECT_EQ(WritePlyPreviews(dir, options).size(), 2u);
  EXPECT_FALSE(fs::exists(dir / "big.preview.preview.ply"));
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    EXPECT_EQ(entry.path().filename().string().find(".part-"), std::string::npos) << entry.path();
  }
  fs::remove_all(dir);
}

TEST(PlyPreview, LeavesAsciiAndMeshesAloneAndRefusesATruncatedCloud) {
  const fs::path dir = TempDir("other");
  {
    std::ofstream ascii(dir / "ascii.ply");
    ascii << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n";
    std::ofstream mesh(dir / "mesh.ply", std::ios::binary);
    mesh << "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
            "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  }
  PlyPreviewOptions options;
  options.max_points = 1;
  EXPECT_FALSE(WritePlyPreview(dir / "ascii.ply", options));
  EXPECT_FALSE(WritePlyPreview(dir / "mesh.ply", options));
  {
    std::ofstream cut(dir / "cut.ply", std::ios::binary);
    cut << "ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n"
           "end_header\n"
        << std::string(40, '\0');
  }
  EXPECT_THROW(WritePlyPreview(dir / "cut.ply", options), std::runtime_error);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omnirig
