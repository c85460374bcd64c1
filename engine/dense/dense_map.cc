#include "engine/dense/dense_map.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <fstream>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include "engine/util/check.h"
#include "engine/util/option_check.h"
#include "engine/util/parallel.h"
#include "engine/util/timer.h"

namespace omnirig::dense {
namespace {

// 21 bits per axis (+-1048576 voxels, 20 km at 2 cm).
int64_t Key(const Eigen::Vector3i& index) {
  constexpr int64_t kOffset = 1 << 20, kMask = (1 << 21) - 1;
  return ((index.x() + kOffset) & kMask) | (((index.y() + kOffset) & kMask) << 21) |
         (((index.z() + kOffset) & kMask) << 42);
}

// No voxel has this key: Key() keeps the top bit clear.
constexpr int64_t kEmptyKey = -1;

size_t SlotOf(int64_t key, int shift) {
  return static_cast<size_t>((static_cast<uint64_t>(key) * 0x9E3779B97F4A7C15ull) >> shift);
}

}  // namespace

void DenseMapOptions::Check() const {
  OMNIRIG_CHECK_IN(voxel_m, '[', 0.005, 1, ']');
  OMNIRIG_CHECK_NON_NEGATIVE(keyframe_spacing_m);
  OMNIRIG_CHECK_IN(grid_step_factor, '[', 1, 8, ']');
  OMNIRIG_CHECK_POSITIVE(max_relative_range_std);
  OMNIRIG_CHECK_AT_LEAST(min_points, 1);
  OMNIRIG_CHECK_AT_LEAST(min_frames, 1);
  OMNIRIG_CHECK_IN(occupancy_cell_m, '[', voxel_m, 2, ']');
  OMNIRIG_CHECK_AT_LEAST(min_obstacle_voxels, 1);
  OMNIRIG_CHECK_IN(visibility_cell_rad, '[', 0, 0.1, ']');
  OMNIRIG_CHECK_POSITIVE(visibility_sigmas);
  OMNIRIG_CHECK(obstacle_min_height_m > 0.0 && obstacle_max_height_m > obstacle_min_height_m,
                "the obstacle band must satisfy 0 < obstacle_min_height_m < "
                "obstacle_max_height_m");
}

DenseMap::DenseMap(const DenseMapOptions& options) : options_(options) { options_.Check(); }

void DenseMap::Reserve(size_t num_voxels) {
  // Geometric growth: each frame's reservation would otherwise copy every voxel.
  if (num_voxels > voxels_.capacity()) {
    voxels_.reserve(std::max(num_voxels, voxels_.capacity() * 3 / 2));
  }
  if (2 * num_voxels <= slots_.size()) return;
  size_t num_slots = 1 << 16;
  while (num_slots < 2 * num_voxels) num_slots *= 2;
  slot_shift_ = 64;
  for (size_t n = num_slots; n > 1; n /= 2) --slot_shift_;
  slots_.assign(num_slots, Slot{kEmptyKey, 0});
  const size_t mask = num_slots - 1;
  for (uint32_t v = 0; v < voxels_.size(); ++v) {
    size_t slot = SlotOf(voxels_[v].key, slot_shift_);
    while (slots_[slot].key != kEmptyKey) slot = (slot + 1) & mask;
    slots_[slot] = {voxels_[v].key, v};
  }
}

DenseMap::Voxel& DenseMap::FindOrAdd(int64_t key) {
  if (2 * (voxels_.size() + 1) > slots_.size()) Reserve(2 * (voxels_.size() + 1));
  const size_t mask = slots_.size() - 1;
  for (size_t slot = SlotOf(key, slot_shift_);; slot = (slot + 1) & mask) {
    Slot& s = slots_[slot];
    if (s.key == key) return voxels_[s.voxel];
    if (s.key != kEmptyKey) continue;
    s = {key, static_cast<uint32_t>(voxels_.size())};
    voxels_.emplace_back();
    voxels_.back().key = key;
    return voxels_.back();
  }
}

void DenseMap::AddPoint(int frame, const Eigen::Vector3d& in_world, int64_t key,
                        const std::array<uint8_t, 3>& rgb, float confidence, float range_std_m) {
  Voxel& voxel = FindOrAdd(key);
  const double std_m = std::max(static_cast<double>(range_std_m), 1e-4);
  const double weight = confidence / (std_m * std_m);
  voxel.weight += weight;
  voxel.weighted_position += weight * in_world;
  voxel.weighted_rgb += weight * Eigen::Vector3d(rgb[0], rgb[1], rgb[2]);
  voxel.confidence_sum += confidence;
  voxel.inverse_variance_sum += 1.0 / (std_m * std_m);
  ++voxel.num_points;
  voxel.frame_bits |= uint64_t{1} << (frame % 64);
  if (voxel.last_frame != frame) {
    voxel.last_frame = frame;
    ++voxel.num_frames;
  }
}

namespace {

// The cell of a direction on a view's equirectangular grid of step `cell_rad`; false for a
// zero direction.
bool ViewCell(const Eigen::Vector3d& in_cam0, double cell_rad, int rows, int cols, int* row,
              int* col, double* range_m) {
  *range_m = in_cam0.norm();
  if (!(*range_m > 0.0)) return false;
  const double polar = std::acos(std::clamp(in_cam0.z() / *range_m, -1.0, 1.0));
  const double azimuth = std::atan2(in_cam0.y(), in_cam0.x()) + M_PI;
  *row = std::min(rows - 1, static_cast<int>(polar / cell_rad));
  *col = std::min(cols - 1, static_cast<int>(azimuth / cell_rad));
  return true;
}

}  // namespace

DenseMap::FrameView DenseMap::NewView(const Rigid3d& world_from_cam0) const {
  const double cell = options_.visibility_cell_rad;
  FrameView view;
  view.frame = num_frames_ - 1;
  view.cam0_from_world = world_from_cam0.Inverse();
  const int rows = static_cast<int>(std::ceil(M_PI / cell));
  const int cols = static_cast<int>(std::ceil(2.0 * M_PI / cell));
  for (cv::Mat* mat : {&view.nearest_m, &view.weighted_range, &view.weight, &view.count}) {
    *mat = cv::Mat::zeros(rows, cols, CV_32F);
  }
  return view;
}

void DenseMap::FinishView(FrameView* view) {
  cv::Mat mean_m, std_m;
  cv::divide(view->weighted_range, view->weight, mean_m);  // NaN where no point fell
  // The cell's points share image pixels: their typical std, not the std of their mean.
  cv::divide(view->count, view->weight, std_m);
  cv::sqrt(std_m, std_m);
  view->nearest_m.convertTo(view->nearest_m, CV_16F);
  mean_m.convertTo(view->mean_m, CV_16F);
  std_m.convertTo(view->std_m, CV_16F);
  view->weighted_range.release();
  view->weight.release();
  view->count.release();
}

void DenseMap::AddToView(int cell, double range_m, float range_std_m, FrameView* view) {
  float& nearest = view->nearest_m.ptr<float>()[cell];
  if (nearest == 0.f || range_m < nearest) nearest = static_cast<float>(range_m);
  const double std_m = std::max(static_cast<double>(range_std_m), 1e-4);
  view->weighted_range.ptr<float>()[cell] += static_cast<float>(range_m / (std_m * std_m));
  view->weight.ptr<float>()[cell] += static_cast<float>(1.0 / (std_m * std_m));
  view->count.ptr<float>()[cell] += 1.f;
}

namespace {

// A point of the frame being added, placed: computed in parallel, fused in point order.
struct PlacedPoint {
  Eigen::Vector3d in_world;
  double range_m;     // from cam0
  int64_t key;        // its voxel's; kEmptyKey when the point is not fused (range std too large)
  int32_t view_cell;  // row * cols + col in the frame's view; -1 for none
};

// The threads of the fusion: OpenCV's (cv::setNumThreads), which the job's matching runs on.
// Not cv::parallel_for_: the stereo job adds a pair on its writer thread while the next pair is
// matched, and OpenCV runs a parallel_for_ that starts while another runs (in any thread)
// serially, the matching's included.
int FusionThreads() { return std::max(1, cv::getNumThreads()); }

// Runs body(begin, end) over [0, size) in chunks of `chunk` on FusionThreads() threads.
template <typename Body>
void ForChunks(size_t size, size_t chunk, const Body& body) {
  const int num_chunks = static_cast<int>((size + chunk - 1) / chunk);
  RunTasks(
      num_chunks, FusionThreads(), ProgressSink{},
      [&](int i, const ProgressSink&) { body(i * chunk, std::min(size, (i + 1) * chunk)); },
      nullptr);
}

}  // namespace

template <typename PointAt>
void DenseMap::AddFrame(const Rigid3d& world_from_cam0, size_t num_points,
                        const PointAt& point_at) {
  const int frame = num_frames_++;
  Reserve(voxels_.size() + num_points);  // at most one new voxel per point
  const Eigen::Matrix3d rotation = world_from_cam0.rotation.toRotationMatrix();
  std::optional<FrameView> view;
  if (options_.visibility_cell_rad > 0.0) view = NewView(world_from_cam0);
  const int rows = view ? view->nearest_m.rows : 0, cols = view ? view->nearest_m.cols : 0;
  std::vector<PlacedPoint, LargeArrayAllocator<PlacedPoint>> placed(num_points);
  ForChunks(num_points, 1 << 16, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      const FramePoint point = point_at(i);
      PlacedPoint& out = placed[i];
      out.key = kEmptyKey;
      out.view_cell = -1;
      if (point.range_std_m > options_.max_relative_range_std * point.in_cam0.norm()) continue;
      out.in_world = rotation * point.in_cam0.template cast<double>() + world_from_cam0.translation;
      out.key = Key((out.in_world / options_.voxel_m).array().floor().template cast<int>());
      int row = 0, col = 0;
      if (view && ViewCell(point.in_cam0.template cast<double>(), options_.visibility_cell_rad,
                           rows, cols, &row, &col, &out.range_m)) {
        out.view_cell = row * cols + col;
      }
    }
  });
  // The view and the voxels are independent: the view is filled beside the voxels.
  const auto fill_view = [&] {
    for (size_t i = 0; i < num_points; ++i) {
      if (placed[i].view_cell >= 0) {
        AddToView(placed[i].view_cell, placed[i].range_m, point_at(i).range_std_m, &*view);
      }
    }
    FinishView(&*view);
  };
  // An error on the view's thread (out of memory) is rethrown here once it has joined.
  struct JoinOnExit {
    std::thread thread;
    std::exception_ptr error;
    ~JoinOnExit() {
      if (thread.joinable()) thread.join();
    }
  } view_thread;
  if (view && FusionThreads() > 1) {
    view_thread.thread = std::thread([&fill_view, &view_thread] {
      try {
        fill_view();
      } catch (...) {
        view_thread.error = std::current_exception();
      }
    });
  }
  // The keys are known ahead: each slot is fetched while the points before it are added (the
  // index holds no more than it did after Reserve, so the slots stay where they are).
  constexpr size_t kAhead = 16;
  for (size_t i = 0; i < num_points; ++i) {
    if (i + kAhead < num_points && placed[i + kAhead].key != kEmptyKey) {
      __builtin_prefetch(&slots_[SlotOf(placed[i + kAhead].key, slot_shift_)]);
    }
    if (placed[i].key == kEmptyKey) continue;
    const FramePoint point = point_at(i);
    AddPoint(frame, placed[i].in_world, placed[i].key, point.rgb, point.confidence,
             point.range_std_m);
  }
  if (view_thread.thread.joinable()) {
    view_thread.thread.join();
    if (view_thread.error) std::rethrow_exception(view_thread.error);
  } else if (view) {
    fill_view();
  }
  if (view) views_.push_back(std::move(*view));
}

void DenseMap::Add(const Rigid3d& world_from_cam0, const std::vector<DensePoint>& points) {
  AddFrame(world_from_cam0, points.size(), [&points](size_t i) {
    const DensePoint& p = points[i];
    return FramePoint{p.point_in_cam0, p.rgb, p.confidence, p.range_std_m};
  });
}

void DenseMap::Add(const Rigid3d& world_from_cam0, const PlyCloud& cloud_in_cam0) {
  cloud_in_cam0.Check();
  OMNIRIG_CHECK(cloud_in_cam0.has_confidence && cloud_in_cam0.has_range_std,
                "a dense map fuses clouds with confidence and range_std_m");
  AddFrame(world_from_cam0, cloud_in_cam0.size(), [&cloud_in_cam0](size_t i) {
    return FramePoint{cloud_in_cam0.positions[i], cloud_in_cam0.colours[i],
                      cloud_in_cam0.confidence[i], cloud_in_cam0.range_std_m[i]};
  });
}

bool DenseMap::FuseAlongRays(const Voxel& voxel, Eigen::Vector3d* position, double std_m) const {
  const double sigmas = options_.visibility_sigmas;
  const Eigen::Vector3d in_world = *position;
  Eigen::Vector3d correction = Eigen::Vector3d::Zero();
  double weight_sum = 1.0 / (std_m * std_m);
  const int first = std::max(0, voxel.last_frame - kViewWindow);
  const int last = std::min(static_cast<int>(views_.size()) - 1, voxel.last_frame + kViewWindow);
  for (int frame = first; frame <= last; ++frame) {
    const FrameView& view = views_[frame];
    if (voxel.frame_bits & (uint64_t{1} << (view.frame % 64))) continue;  // its own frame
    int row = 0, col = 0;
    double range_m = 0.0;
    const Eigen::Vector3d in_cam0 = view.cam0_from_world * in_world;
    if (!ViewCell(in_cam0, options_.visibility_cell_rad, view.mean_m.rows, view.mean_m.cols, &row,
                  &col, &range_m)) {
      continue;
    }
    const double mean_m = static_cast<float>(view.mean_m.at<cv::float16_t>(row, col));
    if (!(mean_m > 0.0)) continue;
    const double seen_std_m = static_cast<float>(view.std_m.at<cv::float16_t>(row, col));
    const double tolerance_m = sigmas * std::sqrt(std_m * std_m + seen_std_m * seen_std_m);
    const double nearest_m = static_cast<float>(view.nearest_m.at<cv::float16_t>(row, col));
    if (nearest_m - range_m > tolerance_m && seen_std_m <= std_m) return false;
    if (std::abs(mean_m - range_m) > tolerance_m) continue;
    const double seen_weight = 1.0 / (seen_std_m * seen_std_m);
    const Eigen::Vector3d ray_in_world =
        view.cam0_from_world.rotation.inverse() * (in_cam0 / range_m);
    correction += seen_weight * (mean_m - range_m) * ray_in_world;
    weight_sum += seen_weight;
  }
  // The precision-weighted mean of the voxel's range and the agreeing frames' along their rays.
  *position += correction / weight_sum;
  return true;
}

PlyCloud DenseMap::Cloud(const std::string& comment) const {
  // Chunks of voxels on FusionThreads() threads, each into its own part, joined in chunk order:
  // the cloud is the serial one bit for bit, whatever the thread count.
  constexpr size_t kChunk = 1 << 15;
  std::vector<PlyCloud> parts((voxels_.size() + kChunk - 1) / kChunk);
  ForChunks(voxels_.size(), kChunk, [&](size_t begin, size_t end) {
    PlyCloud& part = parts[begin / kChunk];
    for (size_t v = begin; v < end; ++v) {
      const Voxel& voxel = voxels_[v];
      if (!Kept(voxel) || !(voxel.weight > 0.0)) continue;
      Eigen::Vector3d position = voxel.weighted_position / voxel.weight;
      const double std_m = 1.0 / std::sqrt(voxel.inverse_variance_sum);
      // Along the rays, a voxel counts as one measurement per frame: a frame's points in one
      // voxel come from neighbouring cells, which share image pixels (their mean is not more
      // precise than one of them), as the views' cells count theirs (FuseAlongRays).
      const double ray_std_m =
          std::sqrt(voxel.num_points / (voxel.inverse_variance_sum * voxel.num_frames));
      if (!views_.empty() && !FuseAlongRays(voxel, &position, ray_std_m)) continue;
      part.positions.push_back(position.cast<float>());
      const Eigen::Vector3d rgb = voxel.weighted_rgb / voxel.weight;
      part.colours.push_back({static_cast<uint8_t>(std::clamp(std::lround(rgb.x()), 0L, 255L)),
                              static_cast<uint8_t>(std::clamp(std::lround(rgb.y()), 0L, 255L)),
                              static_cast<uint8_t>(std::clamp(std::lround(rgb.z()), 0L, 255L))});
      part.confidence.push_back(static_cast<float>(voxel.confidence_sum / voxel.num_points));
      part.range_std_m.push_back(static_cast<float>(std_m));
    }
  });
  PlyCloud cloud;
  cloud.comment = comment;
  cloud.has_confidence = true;
  cloud.has_range_std = true;
  size_t size = 0;
  for (const PlyCloud& part : parts) size += part.size();
  cloud.positions.reserve(size);
  cloud.colours.reserve(size);
  cloud.confidence.reserve(size);
  cloud.range_std_m.reserve(size);
  for (PlyCloud& part : parts) {
    cloud.positions.insert(cloud.positions.end(), part.positions.begin(), part.positions.end());
    cloud.colours.insert(cloud.colours.end(), part.colours.begin(), part.colours.end());
    cloud.confidence.insert(cloud.confidence.end(), part.confidence.begin(),
                            part.confidence.end());
    cloud.range_std_m.insert(cloud.range_std_m.end(), part.range_std_m.begin(),
                             part.range_std_m.end());
    part = PlyCloud();  // freed as it is copied
  }
  return cloud;
}

namespace {

// Adds `key` to an open-addressing set (linear probing, `slots` a power of two, kEmptyKey when
// free, at most half full: it doubles); true when it was not there.
bool InsertKey(int64_t key, std::vector<int64_t>* slots, int* shift, size_t* size) {
  size_t mask = slots->size() - 1;
  size_t slot = SlotOf(key, *shift);
  for (; (*slots)[slot] != kEmptyKey; slot = (slot + 1) & mask) {
    if ((*slots)[slot] == key) return false;
  }
  (*slots)[slot] = key;
  if (2 * ++*size <= slots->size()) return true;
  std::vector<int64_t> old(2 * slots->size(), kEmptyKey);
  old.swap(*slots);
  --*shift;
  mask = slots->size() - 1;
  for (const int64_t k : old) {
    if (k == kEmptyKey) continue;
    for (slot = SlotOf(k, *shift); (*slots)[slot] != kEmptyKey; slot = (slot + 1) & mask) {
    }
    (*slots)[slot] = k;
  }
  return true;
}

}  // namespace

double PointsPerSquareMetre(const std::vector<Eigen::Vector3f>& points, double cell_m) {
  OMNIRIG_CHECK_POSITIVE(cell_m);
  // The distinct cells' keys (Key's 21 bits per axis: +-52 km at 5 cm) in a hash set: a
  // surface has far fewer cells than points, so the set stays in cache. Sorting the points'
  // keys cost 0.17 CPU s for the 1.9 million points of the development room's merged cloud, the
  // set 0.07 (bench_dense, 2026-11-28).
  std::vector<int64_t> slots(size_t{1} << 12, kEmptyKey);
  int shift = 64 - 12;
  size_t num_cells = 0;
  for (const Eigen::Vector3f& p : points) {
    InsertKey(Key((p.cast<double>() / cell_m).array().floor().cast<int>()), &slots, &shift,
              &num_cells);
  }
  return num_cells == 0 ? 0.0 : points.size() / (num_cells * cell_m * cell_m);
}

DenseMapOptions MergedCloudOptions() {
  DenseMapOptions options;
  options.voxel_m = 0.01;
  options.min_points = 1;
  options.min_frames = 1;
  options.max_relative_range_std = 0.02;
  options.occupancy_cell_m = 0.05;
  // About two cells of the default grid at 1024x768 (0.00263 rad): a cell holds a few of a
  // pair's points, so its mean range is that pair's surface there (bench_dense, 2026-11-27:
  // docs/dense.md, "One surface from several pairs").
  options.visibility_cell_rad = 0.005;
  options.visibility_sigmas = 3.0;
  return options;
}

namespace {

// The floor: the most populated 2 cm height bin below the sensor (height = -z in the world, the
// first frame's sensor at 0); 0 when no point lies 0.2 m below the sensor.
double FloorHeight(const std::vector<Eigen::Vector3d>& kept) {
  std::map<int, int> histogram;
  for (const Eigen::Vector3d& p : kept) {
    if (-p.z() < -0.2) ++histogram[static_cast<int>(std::floor(-p.z() / 0.02))];
  }
  int floor_bin = 0, best = 0;
  for (const auto& [bin, count] : histogram) {
    if (count > best) {
      best = count;
      floor_bin = bin;
    }
  }
  return best > 0 ? (floor_bin + 0.5) * 0.02 : 0.0;
}

// Marks grid->cells (sized and placed, all unknown): occupied where at least
// min_obstacle_voxels kept voxels lie in the obstacle band above the floor (a few stray points of
// a far floor or a wall seen at a grazing angle do not make an obstacle), then free where the
// floor was seen and nothing stands.
void MarkCells(const std::vector<Eigen::Vector3d>& kept, const DenseMapOptions& options,
               OccupancyGrid* grid) {
  const int rows = grid->cells.rows, cols = grid->cells.cols;
  const auto cell = [&](const Eigen::Vector3d& p) -> uint8_t& {
    const int c =
        std::clamp(static_cast<int>((p.x() - grid->origin_m.x()) / grid->cell_m), 0, cols - 1);
    const int r =
        std::clamp(static_cast<int>((p.y() - grid->origin_m.y()) / grid->cell_m), 0, rows - 1);
    return grid->cells.at<uint8_t>(rows - 1 - r, c);  // row 0 is the largest y
  };
  cv::Mat obstacle_voxels = cv::Mat::zeros(rows, cols, CV_32S);
  for (const Eigen::Vector3d& p : kept) {
    const double above_floor = -p.z() - grid->floor_height_m;
    if (above_floor >= options.obstacle_min_height_m &&
        above_floor <= options.obstacle_max_height_m) {
      uint8_t& c = cell(p);
      const int offset = static_cast<int>(&c - grid->cells.data);
      if (++reinterpret_cast<int*>(obstacle_voxels.data)[offset] >= options.min_obstacle_voxels) {
        c = OccupancyGrid::kOccupied;
      }
    }
  }
  for (const Eigen::Vector3d& p : kept) {
    const double above_floor = -p.z() - grid->floor_height_m;
    uint8_t& c = cell(p);
    if (std::abs(above_floor) < 0.05 && c == OccupancyGrid::kUnknown) c = OccupancyGrid::kFree;
  }
}

}  // namespace

OccupancyGrid DenseMap::Occupancy() const {
  OccupancyGrid grid;
  grid.cell_m = options_.occupancy_cell_m;
  std::vector<Eigen::Vector3d> kept;
  for (const Voxel& voxel : voxels_) {
    if (Kept(voxel) && voxel.weight > 0.0) kept.push_back(voxel.weighted_position / voxel.weight);
  }
  if (kept.empty()) {
    grid.cells = cv::Mat::zeros(1, 1, CV_8U);
    return grid;
  }
  grid.floor_height_m = FloorHeight(kept);
  Eigen::Vector2d lo(kept[0].x(), kept[0].y()), hi = lo;
  for (const Eigen::Vector3d& p : kept) {
    lo = lo.cwiseMin(p.head<2>());
    hi = hi.cwiseMax(p.head<2>());
  }
  grid.origin_m = lo;
  const int cols = static_cast<int>(std::floor((hi.x() - lo.x()) / grid.cell_m)) + 1;
  const int rows = static_cast<int>(std::floor((hi.y() - lo.y()) / grid.cell_m)) + 1;
  grid.cells = cv::Mat::zeros(rows, cols, CV_8U);
  MarkCells(kept, options_, &grid);
  return grid;
}

void WriteOccupancyGrid(const std::filesystem::path& pgm_path,
                        const std::filesystem::path& yaml_path, const OccupancyGrid& grid,
                        const std::string& image_name) {
  std::ofstream pgm(pgm_path, std::ios::binary | std::ios::trunc);
  if (!pgm) throw std::runtime_error("cannot write " + pgm_path.string());
  pgm << "P5\n" << grid.cells.cols << " " << grid.cells.rows << "\n255\n";
  for (int r = 0; r < grid.cells.rows; ++r) {
    for (int c = 0; c < grid.cells.cols; ++c) {
      const uint8_t v = grid.cells.at<uint8_t>(r, c);
      pgm.put(static_cast<char>(v == OccupancyGrid::kOccupied ? 0
                                : v == OccupancyGrid::kFree   ? 254
                                                              : 205));
    }
  }
  if (!pgm) throw std::runtime_error("failed writing " + pgm_path.string());
  std::ofstream yaml(yaml_path, std::ios::trunc);
  if (!yaml) throw std::runtime_error("cannot write " + yaml_path.string());
  yaml << "image: " << (image_name.empty() ? pgm_path.filename().string() : image_name) << "\n"
       << "resolution: " << grid.cell_m << "\n"
       << "origin: [" << grid.origin_m.x() << ", " << grid.origin_m.y() << ", 0.0]\n"
       << "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n";
  if (!yaml) throw std::runtime_error("failed writing " + yaml_path.string());
}

std::vector<int> SelectKeyframes(const std::vector<std::optional<Rigid3d>>& world_from_rig,
                                 double keyframe_spacing_m) {
  std::vector<int> keyframes;
  std::optional<Eigen::Vector3d> last;
  for (size_t i = 0; i < world_from_rig.size(); ++i) {
    const std::optional<Rigid3d>& pose = world_from_rig[i];
    if (!pose || (last && (pose->translation - *last).norm() < keyframe_spacing_m)) continue;
    keyframes.push_back(static_cast<int>(i));
    last = pose->translation;
  }
  return keyframes;
}

DenseStereoOptions KeyframeStereoOptions(const DenseMapOptions& options) {
  DenseStereoOptions stereo_options;
  stereo_options.grid.step_factor = options.grid_step_factor;
  // The map selects and weighs its points by their geometry, as a constant disparity std makes
  // them, with the refined disparities' positions. The calibrated std under the 2 % filter let
  // far, wrongly matched points into the map: dense_map_test (4 room keyframes, 2026-11-27)
  // observed 19,668 cells, 98.3 % agreeing, against 8,730 and 99.5 % with 0.25 cells
  // (docs/dense.md); a filter of 0.9 % on the calibrated std kept 99.5 % but left a third of
  // the points of 640x480 images. 0.15 cells since the refinement steps from the window's mean
  // disparity (2026-12-08; its median error on the development renders is 0.05-0.06 cells),
  // chosen with DenseMapOptions::grid_step_factor (see there).
  stereo_options.disparity_std_cells = 0.15;
  stereo_options.disparity_std_scale = 0.0;
  // Points the map would not fuse are not made.
  stereo_options.max_relative_range_std =
      std::min(stereo_options.max_relative_range_std, options.max_relative_range_std);
  return stereo_options;
}

KeyframeFusionReport FuseKeyframes(const StereoRig& rig,
                                   const std::vector<std::optional<Rigid3d>>& world_from_rig,
                                   const StereoPairLoader& load, int num_threads,
                                   const ProgressSink& progress, DenseMap* map) {
  OMNIRIG_CHECK(num_threads >= 1, "num_threads must be at least 1, got " << num_threads);
  KeyframeFusionReport report;
  report.keyframes = SelectKeyframes(world_from_rig, map->options().keyframe_spacing_m);
  if (report.keyframes.empty()) return report;
  Timer timer;
  const DenseStereo stereo(rig, KeyframeStereoOptions(map->options()),
                           map->options().rectification_tables_dir);
  report.setup_s = timer.ElapsedSeconds();
  // Batches of num_threads keyframes, each reconstructed on one thread, then fused in frame
  // order: the map does not depend on the thread count, and at most one batch of clouds is held.
  const int num_keyframes = static_cast<int>(report.keyframes.size());
  for (int first = 0; first < num_keyframes; first += num_threads) {
    const int batch = std::min(num_threads, num_keyframes - first);
    std::vector<std::vector<DensePoint>> clouds(batch);
    timer.Restart();
    RunTasks(
        batch, num_threads, progress,
        [&](int i, const ProgressSink&) {
          const std::array<cv::Mat, 2> images = load(report.keyframes[first + i]);
          clouds[i] = stereo.Reconstruct(images[0], images[1]).points;
        },
        [](int) {});
    report.stereo_s += timer.ElapsedSeconds();
    timer.Restart();
    for (int i = 0; i < batch; ++i) {
      const int frame = report.keyframes[first + i];
      map->Add(*world_from_rig[frame], clouds[i]);
      progress.Report((first + i + 1.0) / num_keyframes, "dense_map",
                      "keyframe " + std::to_string(first + i + 1) + " of " +
                          std::to_string(num_keyframes));
    }
    report.fusion_s += timer.ElapsedSeconds();
  }
  return report;
}

}  // namespace omnirig::dense
