#include "api/live_publisher.h"

#include <chrono>
#include <limits>

#include "api/camera_json.h"
#include "api/job_types.h"
#include "api/json_fields.h"
#include "engine/dense/dense_stereo.h"
#include "engine/slam/image_source.h"
#include "engine/slam/map_io.h"
#include "engine/util/check.h"
#include "engine/util/timer.h"

namespace omnirig::api {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr double kForever_s = std::numeric_limits<double>::infinity();

// Removes the temporaries a failed write left (a full disk: the next snapshot tries again).
void RemoveTemporaries(const fs::path& dir, std::initializer_list<const char*> names) {
  std::error_code ignored;
  for (const char* name : names) fs::remove(dir / name, ignored);
}

}  // namespace

struct LivePublisher::Fusion {
  explicit Fusion(const dense::DenseMapOptions& options) : map(options) {}
  dense::DenseMap map;
  std::unique_ptr<dense::DenseStereo> stereo;    // made at the first keyframe
  int last_frame = -1;                           // the last keyframe fused (or given up)
  std::optional<Eigen::Vector3d> last_position;  // where it was fused
  Timer since_write;
  bool unwritten = false;  // keyframes fused since the grid was last written
};

LivePublisher::LivePublisher(const StereoRig& rig, LivePublisherOptions options)
    : rig_(rig), options_(std::move(options)) {
  writer_ = std::thread([this] { WriteLoop(); });
  if (options_.dense_map) {
    try {
      fuser_ = std::thread([this] { FuseLoop(); });
    } catch (...) {
      Stop();
      throw;
    }
  }
}

LivePublisher::~LivePublisher() { Stop(); }

void LivePublisher::Publish(std::shared_ptr<const LiveSnapshot> snapshot) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    latest_ = std::move(snapshot);
    ++version_;
  }
  changed_.notify_all();
}

void LivePublisher::Stop() noexcept {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  if (writer_.joinable()) writer_.join();
  if (fuser_.joinable()) fuser_.join();
}

bool LivePublisher::Stopping() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stop_;
}

int LivePublisher::num_fused_keyframes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return num_fused_keyframes_;
}

void LivePublisher::Log(const std::string& line) const {
  try {
    if (options_.log) options_.log(line);
  } catch (...) {
    // The log is the job's; a line it cannot take is not the publisher's failure.
  }
}

std::shared_ptr<const LiveSnapshot> LivePublisher::WaitNewer(uint64_t* seen, double timeout_s) {
  std::unique_lock<std::mutex> lock(mutex_);
  const auto ready = [&] { return stop_ || version_ != *seen; };
  if (timeout_s == kForever_s) {
    changed_.wait(lock, ready);
  } else {
    changed_.wait_for(lock, std::chrono::duration<double>(timeout_s), ready);
  }
  if (stop_ || version_ == *seen) return nullptr;
  *seen = version_;
  return latest_;
}

void LivePublisher::WriteLoop() {
  uint64_t seen = 0;
  std::shared_ptr<const LiveSnapshot> unwritten;  // one that could not be written
  while (true) {
    // A snapshot that failed is tried again an interval later, or replaced by a newer one.
    const std::shared_ptr<const LiveSnapshot> newer =
        WaitNewer(&seen, unwritten ? options_.interval_s : kForever_s);
    if (Stopping()) return;
    if (newer) unwritten = newer;
    if (!unwritten) continue;
    try {
      WriteLiveSnapshot(rig_, *unwritten, options_.map_job, options_.output_dir);
      if (options_.on_artifacts) {
        options_.on_artifacts({{"artifacts", {"trajectory.json", "map.ply"}},
                               {"num_frames", unwritten->slam.names.size()}});
      }
      unwritten.reset();
    } catch (const std::exception& e) {
      // A full disk: the robot still gets its poses.
      Log(std::string("the map and trajectory so far cannot be written: ") + e.what());
      RemoveTemporaries(options_.output_dir, {".trajectory.json.part-live", ".map.ply.part-live"});
    }
  }
}

void WriteLiveSnapshot(const StereoRig& rig, const LiveSnapshot& snapshot,
                       const std::optional<std::string>& map_job, const fs::path& dir) {
  const slam::SlamSnapshot& slam = snapshot.slam;
  json frames = json::array();
  for (size_t i = 0; i < slam.names.size(); ++i) {
    frames.push_back(
        {{"name", slam.names[i]},
         {"state", slam.states[i]},
         {"timestamp_s", snapshot.stamps_s[i]},
         {"world_from_rig",
          slam.world_from_rig[i] ? PoseToJson(*slam.world_from_rig[i]) : json(nullptr)}});
  }
  const json trajectory = {
      {"world_frame", map_job ? "the world of the saved map of slam job " + *map_job
                              : std::string("the rig frame (cam0's frame) of the first tracked "
                                            "frame")},
      {"live", true},
      {"num_keyframes", slam.num_keyframes},
      {"frames", frames},
      {"rig", RigToJson(rig)}};
  WriteTextFile(dir / ".trajectory.json.part-live", trajectory.dump(2) + "\n");
  fs::rename(dir / ".trajectory.json.part-live", dir / "trajectory.json");
  slam::WritePly(dir / ".map.ply.part-live", slam.map);
  fs::rename(dir / ".map.ply.part-live", dir / "map.ply");
}

void LivePublisher::FuseLoop() {
  try {
    Fusion fusion(*options_.dense_map);
    uint64_t seen = 0;
    while (true) {
      // Wakes for a newer snapshot, or when a grid held back by the interval is due.
      const double timeout_s =
          fusion.unwritten
              ? std::max(0.0, options_.interval_s - fusion.since_write.ElapsedSeconds())
              : kForever_s;
      const std::shared_ptr<const LiveSnapshot> snapshot = WaitNewer(&seen, timeout_s);
      if (Stopping()) return;
      if (snapshot) FuseNewKeyframes(*snapshot, &fusion);
      if (fusion.unwritten && fusion.since_write.ElapsedSeconds() >= options_.interval_s) {
        WriteGrid(&fusion);
      }
    }
  } catch (const Cancelled&) {
    // Stopped inside a keyframe's dense stereo.
  } catch (const std::exception& e) {
    Log(std::string("the occupancy grid so far is no longer made: ") + e.what());
  }
}

void LivePublisher::FuseNewKeyframes(const LiveSnapshot& first, Fusion* fusion) {
  const dense::DenseMapOptions& options = *options_.dense_map;
  const ProgressSink stopping{{}, [this] { return Stopping(); }};
  std::shared_ptr<const LiveSnapshot> newer;
  const LiveSnapshot* snapshot = &first;
  for (const int frame : first.slam.keyframes) {
    if (frame <= fusion->last_frame) continue;
    // The poses as the run holds them now (a newer snapshot arrives while a keyframe is fused).
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (latest_) newer = latest_;
    }
    if (newer) snapshot = newer.get();
    const std::optional<Rigid3d>& pose = snapshot->slam.world_from_rig[frame];
    if (!pose) continue;
    std::optional<Eigen::Vector3d> last = fusion->last_position;
    if (fusion->last_frame >= 0 && snapshot->slam.world_from_rig[fusion->last_frame]) {
      last = snapshot->slam.world_from_rig[fusion->last_frame]->translation;
    }
    if (last && (pose->translation - *last).norm() < options.keyframe_spacing_m) continue;
    const std::string& name = snapshot->slam.names[frame];
    fusion->last_frame = frame;
    fusion->last_position = pose->translation;
    try {
      const slam::StereoImages images = slam::StereoImageLoader(
          options_.dataset_dir, {{name, "cam0/" + name, "cam1/" + name}})(0);
      if (!fusion->stereo) {
        fusion->stereo = std::make_unique<dense::DenseStereo>(
            rig_, dense::KeyframeStereoOptions(options), options.rectification_tables_dir);
      }
      fusion->map.Add(*pose,
                      fusion->stereo->Reconstruct(images.cam0, images.cam1, stopping).points);
    } catch (const InvalidArgument& e) {
      // Its images cannot be read back: the grid goes on without it (the final grid retries).
      Log("keyframe " + name + " is not in the occupancy grid so far: " + e.what());
      continue;
    }
    fusion->unwritten = true;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      num_fused_keyframes_ = fusion->map.num_frames();
    }
    // A long catch-up still refreshes the grid once per interval.
    if (fusion->since_write.ElapsedSeconds() >= options_.interval_s) WriteGrid(fusion);
  }
}

void LivePublisher::WriteGrid(Fusion* fusion) {
  fusion->since_write.Restart();
  // Fewer keyframes than min_frames confirm no voxel: nothing to show yet.
  if (fusion->map.num_frames() < fusion->map.options().min_frames) {
    fusion->unwritten = false;
    return;
  }
  const fs::path& dir = options_.output_dir;
  try {
    const dense::OccupancyGrid grid = fusion->map.Occupancy();
    dense::WriteOccupancyGrid(dir / ".occupancy.pgm.part-live", dir / ".occupancy.yaml.part-live",
                              grid, "occupancy.pgm");
    fs::rename(dir / ".occupancy.pgm.part-live", dir / "occupancy.pgm");
    fs::rename(dir / ".occupancy.yaml.part-live", dir / "occupancy.yaml");
    if (options_.on_artifacts) {
      options_.on_artifacts({{"artifacts", {"occupancy.pgm", "occupancy.yaml"}},
                             {"num_fused_keyframes", fusion->map.num_frames()}});
    }
    fusion->unwritten = false;
  } catch (const std::exception& e) {
    Log(std::string("the occupancy grid so far cannot be written: ") + e.what());
    // Tried again an interval later.
    RemoveTemporaries(dir, {".occupancy.pgm.part-live", ".occupancy.yaml.part-live"});
  }
}

}  // namespace omnirig::api
