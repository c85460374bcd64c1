#pragma once
// Previews of large point clouds, as Potree-style viewers load them: a random subset of a binary
// PLY's vertices, every property kept byte for byte (colour, confidence, observation counts, ...),
// small enough for a web page to load at once. NAME.ply's preview is NAME.preview.ply beside it.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <vector>

namespace omnirig {

struct PlyPreviewOptions {
  // A cloud with more points or bytes than these gets a preview holding at most as many.
  int64_t max_points = 2'000'000;
  int64_t max_bytes = 20'000'000;
  uint64_t seed = 1;  // of the random subset: the same cloud gives the same preview

  void Check() const;
};

struct PlyPreview {
  std::filesystem::path path;
  int64_t source_points = 0;
  int64_t preview_points = 0;
};

// NAME.preview.ply for NAME.ply.
std::filesystem::path PlyPreviewPath(const std::filesystem::path& cloud);

// Whether `path` names a preview (NAME.preview.ply).
bool IsPlyPreviewPath(const std::filesystem::path& path);

// Writes the preview of the binary PLY `cloud` at PlyPreviewPath(cloud) when the cloud is over
// the options' bounds: a uniformly random subset of exactly as many vertices as both bounds
// allow, in the file's order, under the same header (the vertex count changed, a comment added).
// Nothing (nullopt) for a cloud within the bounds or one the preview cannot subset (ASCII, an
// element other than the vertices, a list property); throws std::runtime_error when the file
// cannot be read or written or is shorter than its header says.
std::optional<PlyPreview> WritePlyPreview(const std::filesystem::path& cloud,
                                          const PlyPreviewOptions& options);

// WritePlyPreview for every .ply file under `dir` (recursively) that is not itself a preview.
std::vector<PlyPreview> WritePlyPreviews(const std::filesystem::path& dir,
                                         const PlyPreviewOptions& options);

}  // namespace omnirig
