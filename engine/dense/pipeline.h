#pragma once
// 3D points from a calibrated rig's image pairs, as the `stereo_reconstruct` job and
// `omnirig stereo` run it: per pair read -> match (dense, dense_stereo.h, or sparse,
// engine/stereo/stereo_reconstruct.h) -> write the pair's cloud (and, dense, its range
// panoramas), and the placed pairs merged into one cloud in a trajectory's world.
//
// Files written into the output folder: one pair without a placement writes cloud.ply (in its
// cam0 frame). Otherwise each pair writes CloudFileName(NAME) in its own cam0 frame, and with a
// placement cloud.ply holds every placed pair in the placement's world (no merged cloud
// without one: the pairs of a moving rig share no frame): dense pairs fused into one surface
// (a DenseMap with MergedCloudOptions, dense_map.h), sparse pairs' points appended. Dense also
// writes per pair RangeBaseName(NAME) + "_range.tiff" and "_range.png" (range_io.h).

#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "engine/dense/dense_stereo.h"
#include "engine/features/image.h"
#include "engine/geometry/rigid3.h"
#include "engine/stereo/stereo_reconstruct.h"
#include "engine/util/image_pairs.h"
#include "engine/util/progress.h"

namespace omnirig::dense {

// Each pair's cam0 pose in one world, from a trajectory (a slam run's, or a TUM file's).
struct PairPlacement {
  std::string source;                                   // what placed them, e.g. "NAME.tum"
  std::vector<std::optional<Rigid3d>> world_from_cam0;  // per pair
  std::string warning;                                  // why some or all pairs could not be placed
};

struct StereoPairsOptions {
  bool use_dense = true;            // dense matching, else sparse features
  DenseStereoOptions dense;         // use_dense
  StereoReconstructOptions sparse;  // !use_dense
  // Dense: where the rig's rectification tables are kept across processes (SharedRectifier);
  // empty: built once per process.
  std::filesystem::path rectification_tables_dir;
  void Check() const;
};

// One pair, handed to the caller once it is matched (on the calling thread, in pair order,
// before its files are written).
struct StereoPairOutcome {
  size_t index = 0;
  const ImagePairNames* names = nullptr;
  const StereoPairReport* sparse = nullptr;  // !use_dense
  const DensePairResult* dense = nullptr;    // use_dense
  std::string cloud_file;                    // the pair's own cloud; empty when it is cloud.ply
  std::optional<bool> placed;         // with a placement: whether the pair is in the merged cloud
  std::string range_tiff, range_png;  // dense
};

struct StereoPairsReport {
  size_t num_points = 0;
  std::string artifact;               // the cloud to show first: cloud.ply or the first pair's
  std::optional<bool> clouds_merged;  // set for several pairs or a placement
  // Dense pairs fused into cloud.ply: its points per square metre of the surface they sample
  // (PointsPerSquareMetre, dense_map.h).
  std::optional<double> merged_points_per_m2;
  // With a placement: its source, how many pairs it placed, and why not all (empty when all).
  struct Trajectory {
    std::string source;
    int num_pairs_placed = 0;
    std::string warning;
  };
  std::optional<Trajectory> trajectory;
  // Dense: the rectified grid.
  struct Grid {
    int rows = 0, cols = 0;
    double step_rad = 0;
    int num_disparities = 0;
  };
  std::optional<Grid> grid;
};

// "cloud_NAME.ply", '/', '\\' and '.' of NAME replaced by '_'.
std::string CloudFileName(const std::string& pair_name);
// NAME of a pair's range panoramas: the pair's name without its extension, '/' and '\\'
// replaced by '_'.
std::string RangeBaseName(const std::string& pair_name);

// Reads `dataset_dir / pair.cam0` (colour) and `.cam1` (grey) of each pair, matches them with
// `rig`, calls `on_pair` with the outcome and writes the pair's files into `output_dir`. Dense:
// two pairs are read and matched at once, each on a thread of its own (a job of one pair on
// the calling thread), and each pair's on_pair and files follow on a background thread while
// the next pairs are matched; at most one pair waits to be written. `on_pair` is called once
// per pair, in pair order, one call at a time, but for dense pairs not on the calling thread.
// `placement` (optional) holds one pose per pair. Throws InvalidArgument for an image that
// cannot be read ("cannot read image 'cam0/NAME'") and, naming the pair ("pair 'NAME': ..."),
// for images that do not fit the rig; std::runtime_error naming the pair when a file cannot be
// written; Cancelled. Nothing is written twice.
StereoPairsReport ReconstructStereoPairs(
    const StereoRig& rig, const std::filesystem::path& dataset_dir,
    const std::vector<ImagePairNames>& pairs, const std::optional<PairPlacement>& placement,
    const StereoPairsOptions& options, const std::filesystem::path& output_dir,
    const std::function<void(const StereoPairOutcome&)>& on_pair, const ProgressSink& progress);
// As above, the images read through `read` (e.g. frames of a recording).
StereoPairsReport ReconstructStereoPairs(
    const StereoRig& rig, const ImageReader& read, const std::vector<ImagePairNames>& pairs,
    const std::optional<PairPlacement>& placement, const StereoPairsOptions& options,
    const std::filesystem::path& output_dir,
    const std::function<void(const StereoPairOutcome&)>& on_pair, const ProgressSink& progress);

}  // namespace omnirig::dense
