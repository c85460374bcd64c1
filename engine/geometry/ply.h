#pragma once
// The project's one PLY writer: binary little-endian point clouds (read by Open3D, PCL, MeshLab,
// CloudCompare, three.js). Used by the sparse and dense stereo reconstructions and the SLAM map.

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace omnirig {

// Vertices with float x y z (metres, in the frame the comment names) and uchar red green blue,
// then the optional properties, in this order, when their flags are set:
//   float confidence        (dense stereo: 0 .. 1)
//   float range_std_m       (dense stereo: the point's range standard deviation, metres)
//   int num_observations    (SLAM map)
// A flagged property's vector holds one value per point (an empty cloud still declares it).
struct PlyCloud {
  std::string comment;  // one header comment line (no newline), e.g. the frame and unit
  std::vector<Eigen::Vector3f> positions;
  std::vector<std::array<std::uint8_t, 3>> colours;  // one per position
  bool has_confidence = false;
  std::vector<float> confidence;
  bool has_num_observations = false;
  std::vector<std::int32_t> num_observations;
  bool has_range_std = false;  // written after confidence (the order above)
  std::vector<float> range_std_m;

  size_t size() const { return positions.size(); }
  // Throws InvalidArgument when a vector's length does not match positions (an unflagged
  // property's must be empty) or the comment holds a newline.
  void Check() const;
};

// Writes `cloud` at `path`: an ASCII header and a packed body. Throws InvalidArgument for an
// inconsistent cloud and std::runtime_error when the file cannot be written.
void WritePly(const std::filesystem::path& path, const PlyCloud& cloud);

// Writes a cloud too large to hold at once (e.g. many stereo pairs merged) in parts of the same
// properties: Append() writes each part's vertices to PATH.part, Finish() writes PATH's header
// with the total count and moves the vertices behind it. The parts' comment is the first's.
// Throws as WritePly does, and InvalidArgument for a part whose properties differ.
class PlyAppender {
 public:
  explicit PlyAppender(std::filesystem::path path);
  void Append(const PlyCloud& part);
  void Finish();
  size_t size() const { return count_; }

 private:
  std::filesystem::path path_;
  PlyCloud header_;  // properties and comment, no points
  size_t count_ = 0;
  bool started_ = false;
};

}  // namespace omnirig
