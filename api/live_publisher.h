#pragma once
// A live slam job's artifacts written off its tracking thread (api/live_slam.h): the tracking
// thread takes the run so far (slam::Session::Snapshot, a copy: the session is not
// thread-safe) and hands it over without waiting; the publisher writes trajectory.json and
// map.ply from it on a thread of its own, and with a dense map (SlamParams::dense_map) grows
// the occupancy grid keyframe by keyframe on another, so that neither the map's export nor a
// keyframe's dense stereo adds to a frame's latency.
//
// The occupancy grid while the job runs: the snapshot's keyframes (those that entered the SLAM
// map, their poses refined by the local adjustments), each at least keyframe_spacing_m from the
// last one fused, are fused in order, as fast as one thread reconstructs them, into a
// dense::DenseMap at their poses of the snapshot at hand (images read back from the job's
// dataset, where each frame is stored before it is tracked); occupancy.pgm and occupancy.yaml
// are rewritten after new keyframes, at most once per interval. Poses the map corrects later
// are not refused: the grid at the job's end is made again over the final poses (FuseDenseMap).
//
// Every file is written under a temporary name (".NAME.part-live": the artifact collector and
// the start-up check skip such names) and renamed: a client reading one while it is refreshed
// sees the old or the new file. A file that cannot be written (a full disk) is logged, its
// temporary removed, and written again an interval later (from a newer snapshot if one came).

#include <condition_variable>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/dense/dense_map.h"
#include "engine/geometry/camera_model.h"
#include "engine/slam/session.h"

namespace omnirig::api {

// The run so far, as the tracking thread hands it over.
struct LiveSnapshot {
  slam::SlamSnapshot slam;
  std::vector<double> stamps_s;  // per frame of slam.names
};

// Writes trajectory.json and map.ply of `snapshot` into `output_dir` (each under its temporary
// name, then renamed); `map_job` names the trajectory's world. Throws when a file cannot be
// written (the temporaries are left to the caller).
void WriteLiveSnapshot(const StereoRig& rig, const LiveSnapshot& snapshot,
                       const std::optional<std::string>& map_job,
                       const std::filesystem::path& output_dir);

struct LivePublisherOptions {
  std::filesystem::path output_dir;
  // The saved map's job ("map"): names the trajectory's world.
  std::optional<std::string> map_job;
  // With a dense map: the grid while the job runs, from the frames stored in dataset_dir
  // (cam0/NAME, cam1/NAME).
  std::optional<dense::DenseMapOptions> dense_map;
  std::filesystem::path dataset_dir;
  // trajectory.json and map.ply, and the grid, are each written at most this often.
  double interval_s = 1.0;
  // Called from the publisher's threads (must be thread-safe; may be empty): a line for the
  // job's log, and each refresh of files ({"artifacts": [names]}, with the grid
  // "num_fused_keyframes" too).
  std::function<void(const std::string& line)> log;
  std::function<void(const nlohmann::json& refreshed)> on_artifacts;
};

class LivePublisher {
 public:
  LivePublisher(const StereoRig& rig, LivePublisherOptions options);
  // Stop().
  ~LivePublisher();
  LivePublisher(const LivePublisher&) = delete;
  LivePublisher& operator=(const LivePublisher&) = delete;

  // Hands the run so far over and returns at once: a snapshot not yet written is replaced.
  void Publish(std::shared_ptr<const LiveSnapshot> snapshot);
  // Stops the threads and waits for them: a write under way ends first, a keyframe's dense
  // stereo is interrupted. Never throws; called again, does nothing.
  void Stop() noexcept;

  int num_fused_keyframes() const;

 private:
  // The threads' bodies; neither lets an exception out.
  void WriteLoop();
  void FuseLoop();
  bool Stopping() const;
  // Waits up to `timeout_s` for a snapshot newer than `*seen`; nullptr when none came or on
  // the stop.
  std::shared_ptr<const LiveSnapshot> WaitNewer(uint64_t* seen, double timeout_s);
  void Log(const std::string& line) const;

  // The fusion's state (FuseLoop's thread alone).
  struct Fusion;
  // Fuses the snapshot's keyframes not yet fused, in order.
  void FuseNewKeyframes(const LiveSnapshot& snapshot, Fusion* fusion);
  // Writes the grid (unless no voxel can be confirmed yet); on failure it stays unwritten.
  void WriteGrid(Fusion* fusion);

  const StereoRig rig_;
  const LivePublisherOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::shared_ptr<const LiveSnapshot> latest_;
  uint64_t version_ = 0;
  bool stop_ = false;
  int num_fused_keyframes_ = 0;
  std::thread writer_, fuser_;
};

}  // namespace omnirig::api
