#pragma once
// A dense map fused from the range panoramas (dense clouds) of keyframes along an estimated
// trajectory, and a 2D occupancy grid of the obstacles for navigation.
//
// Fusion is a confidence-weighted average per voxel: each point's weight is its confidence
// divided by its range variance, so that the precise near points dominate the far ones. Open3D's
// TSDF volumes (Debian 12 has Open3D 0.16) integrate pinhole RGB-D images; our panoramas are
// spherical, and resampling them into virtual pinhole views would add a second interpolation and
// lose the per-point uncertainty, which the weighted average uses directly. OctoMap stores
// occupancy, not surface positions. Hence this small fusion of our own.
//
// Frames: the map is in the trajectory's world frame, metres. The occupancy grid assumes an
// upright sensor as in the paper's Fig. 1: cam0's +z axis points down, so "up" is the world's -z
// (the SLAM world is the first frame's cam0 frame).

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/dense/dense_stereo.h"
#include "engine/geometry/ply.h"
#include "engine/geometry/rigid3.h"
#include "engine/util/allocator.h"

namespace omnirig::dense {

struct DenseMapOptions {
  double voxel_m = 0.02;
  // Keyframes: a tracked frame is fused when it lies at least this far from the last fused one.
  // With grid_step_factor, the fusion's cost (the keyframes' dense stereo): bench_slam
  // --dense-map on the 40-frame room (6.3 m) chose 1.5 m (2026-11-26: with factor 1.25, fusion
  // 19-26 % of SLAM's wall time, median 0.37 % of range, 99.5 % of 8,786 occupancy cells
  // agreeing; 1 m keyframes observed 13,088 cells for 29-40 % of SLAM's time). docs/dense.md
  // has the table.
  double keyframe_spacing_m = 1.5;
  // The keyframes' dense stereo runs on a grid this many times coarser than the images' finest
  // angular resolution (SphericalGridOptions::step_factor). Coarser is cheaper (the cells fall
  // with its square) but its range std grows with the step, so fewer points pass
  // max_relative_range_std. Chosen with the map's disparity std (FuseKeyframes: 0.15 cells) on
  // the room (bench_slam --dense-map, 2026-12-08, the refinement stepping from the window's
  // mean disparity): 1.25 and 0.25 cells (before) observed 9,101 cells, 99.6 % agreeing, for
  // 36-40 % of SLAM's wall time; 1.5 and 0.25 5,451; 1.5 and 0.2 10,100 (99.5 %); 1.5 and 0.15
  // 17,433 (99.4 %, but 32 of 639 occupied cells wrongly, against 2 of 128); 1.75 and 0.15
  // 13,364 (99.6 %, 4 of 293 wrongly) for 18-20 %. The street, which did not choose: 12,380
  // cells, 99.7 % agreeing, against 8,340 and 99.7 % before.
  double grid_step_factor = 1.75;
  // A voxel is kept when at least this many points of at least min_frames keyframes fell in it
  // (a surface seen once, or by one frame only, is not confirmed).
  int min_points = 2;
  int min_frames = 2;
  // Points whose range std exceeds this fraction of their range are not fused (far points seen
  // with little parallax would otherwise fill voxels of their own with their larger errors).
  // The map's range std is geometric: FuseKeyframes gives every point 0.15 cells of disparity
  // std, not the calibrated per-point std of dense_stereo.h (see there).
  double max_relative_range_std = 0.02;
  // Occupancy grid: cell size, and the band of heights above the floor that holds obstacles
  // (the floor is the most populated height below the sensor).
  double occupancy_cell_m = 0.05;
  double obstacle_min_height_m = 0.15;
  double obstacle_max_height_m = 2.0;
  // Kept voxels in a cell's band that make it occupied.
  int min_obstacle_voxels = 10;
  // FuseKeyframes: where the rig's rectification tables are kept across processes
  // (SharedRectifier, spherical_rectification.h); empty: built once per process.
  std::filesystem::path rectification_tables_dir;
  // The check and fusion along the rays of the other frames (0: none; the stereo job's merged
  // cloud sets it). Each frame's fused points are also kept as a range panorama around its cam0
  // (per cell of this angular step: the nearest range, and the precision-weighted mean range
  // and its points' std). Cloud() then takes each kept voxel along the ray of every other frame
  // that sees its direction: where that frame's mean range agrees within visibility_sigmas
  // combined stds, the voxel moves to the precision-weighted mean of its range and the frame's
  // (the two pairs' points of one surface, often centimetres apart and so in different voxels,
  // become one layer); where it lies in front of the nearest surface the frame sees by more
  // than that, and the frame's range is at least as precise, it is dropped (the frame sees
  // through it: a wrong match). A voxel behind the frame's surface is hidden from it: kept.
  double visibility_cell_rad = 0.0;
  double visibility_sigmas = 3.0;

  void Check() const;
};

// A 2D grid in the world's x-y plane (ROS map_server conventions): row 0 is the largest y.
struct OccupancyGrid {
  enum Cell : uint8_t { kUnknown = 0, kFree = 1, kOccupied = 2 };
  cv::Mat cells;  // CV_8U of Cell
  double cell_m = 0.05;
  Eigen::Vector2d origin_m = Eigen::Vector2d::Zero();  // x, y of the lower-left cell's corner
  double floor_height_m = 0.0;                         // height (-z) of the floor in the world
};

class DenseMap {
 public:
  explicit DenseMap(const DenseMapOptions& options);

  // Adds one keyframe's points (in its cam0 frame) at world_from_cam0.
  void Add(const Rigid3d& world_from_cam0, const std::vector<DensePoint>& points);
  // The same from a dense cloud as written (ToPlyCloud: confidence and range_std_m); throws
  // InvalidArgument for a cloud without them.
  void Add(const Rigid3d& world_from_cam0, const PlyCloud& cloud_in_cam0);

  // The kept voxels: weighted mean position and colour, mean confidence, and range_std_m the
  // std of the weighted mean (1 / sqrt of the sum of its points' inverse range variances).
  PlyCloud Cloud(const std::string& comment =
                     "omnirig dense map: confidence-weighted voxel means in the SLAM world, "
                     "metres") const;

  // Floor from the kept voxels' heights, then per cell: occupied when a kept voxel lies in the
  // obstacle band, free when the floor was seen there and nothing stands in the band, unknown
  // otherwise.
  OccupancyGrid Occupancy() const;

  const DenseMapOptions& options() const { return options_; }
  int num_frames() const { return num_frames_; }
  size_t num_voxels() const { return voxels_.size(); }

 private:
  struct Voxel {
    int64_t key = 0;
    double weight = 0.0;
    Eigen::Vector3d weighted_position = Eigen::Vector3d::Zero();
    Eigen::Vector3d weighted_rgb = Eigen::Vector3d::Zero();
    double confidence_sum = 0.0;
    double inverse_variance_sum = 0.0;
    int num_points = 0;
    int num_frames = 0;
    int last_frame = -1;
    uint64_t frame_bits = 0;  // bit (frame % 64) of every frame that added a point
  };
  // A point of a frame being added (its cam0 frame), as both Add overloads read theirs.
  struct FramePoint {
    const Eigen::Vector3f& in_cam0;
    const std::array<uint8_t, 3>& rgb;
    float confidence;
    float range_std_m;
  };
  // Both Adds: point_at(i) is point i's FramePoint. The points' world positions, voxel keys and
  // view cells are computed on cv::getNumThreads() threads, then the voxels and the view are
  // filled in point order (each on its own thread): the map does not depend on the thread count.
  template <typename PointAt>
  void AddFrame(const Rigid3d& world_from_cam0, size_t num_points, const PointAt& point_at);
  // Adds one point (world frame, in the voxel of `key`) of the frame being added.
  void AddPoint(int frame, const Eigen::Vector3d& in_world, int64_t key,
                const std::array<uint8_t, 3>& rgb, float confidence, float range_std_m);
  bool Kept(const Voxel& voxel) const {
    return voxel.num_points >= options_.min_points && voxel.num_frames >= options_.min_frames;
  }

  // The voxel of `key`, added (zero) if new.
  Voxel& FindOrAdd(int64_t key);
  // Room for `num_voxels` voxels without growing the index while they are added.
  void Reserve(size_t num_voxels);
  struct Slot {
    int64_t key;     // kEmptyKey (dense_map.cc) when free
    uint32_t voxel;  // index into voxels_
  };

  DenseMapOptions options_;
  // The voxels in the order they were first touched, and an open-addressing index of them
  // (linear probing, at most half full): one cache miss per point. A node-based
  // std::unordered_map cost about 0.8 CPU s per 930,000-point pair (an allocation and several
  // cache misses per voxel), this about 0.2 (bench_dense, 2026-11-27). Both in huge pages
  // (LargeArrayAllocator): a merged cloud's table holds hundreds of MB, touched once it is
  // allocated.
  std::vector<Voxel, LargeArrayAllocator<Voxel>> voxels_;
  std::vector<Slot, LargeArrayAllocator<Slot>> slots_;
  int slot_shift_ = 64;  // 64 - log2(number of slots)
  int num_frames_ = 0;

  // A frame's view for the check along its rays (visibility_cell_rad > 0): per cell of an
  // equirectangular grid around its cam0 (rows: angle from +z, columns: azimuth from +x), the
  // nearest fused range, the precision-weighted mean range and its points' typical std; 0 where
  // the frame fused nothing. Built in CV_32F sums (range / std^2, 1 / std^2, count), then kept
  // in half floats (6 bytes a cell: 4.7 MB a frame at 0.005 rad; their 0.05 % rounding is far
  // below the ranges' stds).
  struct FrameView {
    int frame = 0;
    Rigid3d cam0_from_world;
    cv::Mat nearest_m, mean_m, std_m;  // CV_16F once finished
    cv::Mat weighted_range, weight, count;  // CV_32F while the frame is added
  };
  FrameView NewView(const Rigid3d& world_from_cam0) const;
  // Adds a point at range_m in cell `cell` (row * cols + col) of the view.
  static void AddToView(int cell, double range_m, float range_std_m, FrameView* view);
  static void FinishView(FrameView* view);
  // A kept voxel's position after the other frames' views (see visibility_cell_rad); false
  // when a view sees through it. Only the frames within kViewWindow of the voxel's last frame
  // are asked (the neighbours in a sequence, which see the same surfaces): the check costs
  // O(voxels) however many frames are fused.
  static constexpr int kViewWindow = 8;
  bool FuseAlongRays(const Voxel& voxel, Eigen::Vector3d* position, double std_m) const;
  std::vector<FrameView> views_;
};

// The options of the stereo job's merged cloud of several pairs placed by a trajectory: 1 cm
// voxels (each the confidence- and precision-weighted mean of the points in it, from any pair:
// a surface seen by one pair is kept too), then the check and fusion along the other pairs'
// rays (visibility_cell_rad), so that a surface seen from several pairs becomes one layer
// (bench_dense, 2026-11-27: where both pairs see it, layer 4.90 -> 4.54 % of range on the
// held-out lounge, 2.55 -> 2.42 % on the room; docs/dense.md). Points whose range std exceeds
// 2 % of their range, which would thicken the layer, are left to the pairs' own clouds.
DenseMapOptions MergedCloudOptions();

// Points per square metre of the surface `points` sample: their number over the surface's area,
// taken as the cells of `cell_m` the points occupy times cell_m^2 (a plane at an angle to the
// cells' axes crosses up to 1.7 times more cells than its area holds, so this errs low).
double PointsPerSquareMetre(const std::vector<Eigen::Vector3f>& points, double cell_m = 0.05);

// The frames fused into a map: those with a pose, each at least keyframe_spacing_m from the
// last one kept (the first posed frame is kept).
std::vector<int> SelectKeyframes(const std::vector<std::optional<Rigid3d>>& world_from_rig,
                                 double keyframe_spacing_m);

// The dense stereo run on each keyframe of a map with `options` (its grid, and the points the
// map would fuse), by FuseKeyframes and by a live job's map growing keyframe by keyframe.
DenseStereoOptions KeyframeStereoOptions(const DenseMapOptions& options);

// Loads frame `index`'s images (cam0, cam1; 8-bit BGR or grey). Called from up to num_threads
// threads at once (FuseKeyframes).
using StereoPairLoader = std::function<std::array<cv::Mat, 2>(int index)>;

struct KeyframeFusionReport {
  std::vector<int> keyframes;
  // Wall seconds: the rectification tables (once per rig), the keyframes' dense stereo
  // (loading included) and their fusion into the voxels.
  double setup_s = 0.0;
  double stereo_s = 0.0;
  double fusion_s = 0.0;
};

// Reconstructs the keyframes of `world_from_rig` (SelectKeyframes with the map's spacing) with
// DenseStereo on the map's grid (DenseMapOptions::grid_step_factor), num_threads keyframes at a
// time (each on one thread), and adds them to `map` in frame order. Throws Cancelled through
// `progress`, InvalidArgument for images that do not fit the rig.
KeyframeFusionReport FuseKeyframes(const StereoRig& rig,
                                   const std::vector<std::optional<Rigid3d>>& world_from_rig,
                                   const StereoPairLoader& load, int num_threads,
                                   const ProgressSink& progress, DenseMap* map);

// Writes `grid` as ROS map_server files: NAME.pgm (binary P5: occupied 0, free 254, unknown 205)
// and NAME.yaml (image, resolution, origin, negate, occupied_thresh, free_thresh). The yaml's
// image is `image_name`, or pgm_path's file name when empty (a grid written under temporary
// names and renamed names its final image). Throws std::runtime_error when a file cannot be
// written.
void WriteOccupancyGrid(const std::filesystem::path& pgm_path,
                        const std::filesystem::path& yaml_path, const OccupancyGrid& grid,
                        const std::string& image_name = "");

}  // namespace omnirig::dense
