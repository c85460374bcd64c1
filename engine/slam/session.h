#pragma once
// SLAM one frame at a time, for a robot that sends its frames as it captures them: the tracker
// RunSlam (slam.h) drives over a whole sequence, fed here by the caller. Track() gives each
// frame's pose as tracking has it then (keyframes are adjusted later by the local and global
// bundle adjustments, so the final pose may differ); Snapshot() gives the run so far for maps
// and trajectories a client can look at while it drives; Finish() settles the run as RunSlam
// ends one (the global adjustment, non-keyframes placed by their keyframes) and returns the
// same SlamResult. The same frames through Track() (the last one with last_frame) and Finish()
// give RunSlam's result.
//
// Not thread-safe: one caller at a time (the live job's thread).

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/slam/slam.h"

namespace omnirig::slam {

namespace internal {
class Tracker;
}

// The run so far: per frame tracked or lost, its name and current world_from_rig; the frames
// that entered the map as keyframes (their poses the local adjustments refined), in order.
struct SlamSnapshot {
  std::vector<std::string> names;
  std::vector<std::string> states;
  std::vector<std::optional<Rigid3d>> world_from_rig;
  std::vector<MapPoint> map;
  std::vector<int> keyframes;  // frame indices
  int num_keyframes = 0;
};

class Session {
 public:
  // Throws InvalidArgument on invalid options. `progress` is asked for cancellation inside the
  // bundle adjustments and told of the global adjustment in Finish().
  Session(const StereoRig& rig, const SlamOptions& options,
          const ProgressSink& progress = ProgressSink());
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  // Tracks the next frame (index num_frames()) and returns its report with world_from_rig as
  // tracked now (nullopt when lost). `last_frame` makes it a keyframe, as RunSlam does with a
  // sequence's last frame. Throws InvalidArgument when an image's size differs from the rig's
  // calibration (the session is unchanged and goes on), and after Finish().
  FrameReport Track(const std::string& name, const StereoImages& images, bool last_frame = false);
  SlamSnapshot Snapshot() const;
  // The end of the run: loops settled, the global adjustment; the result of every frame
  // tracked. Throws InvalidArgument without frames or when called twice.
  SlamResult Finish();

  int num_frames() const { return static_cast<int>(result_.frames.size()); }
  const StereoRig& rig() const { return rig_; }

 private:
  const StereoRig rig_;
  const SlamOptions options_;
  const ProgressSink progress_;
  std::unique_ptr<internal::Tracker> tracker_;
  SlamResult result_;
  double start_wall_s_ = 0, start_cpu_s_ = 0;
  bool finished_ = false;
};

}  // namespace omnirig::slam
