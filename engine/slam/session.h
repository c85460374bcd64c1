#pragma once
// SLAM one frame at a time, for a robot that sends its frames as it captures them: the tracker
// RunSlam (slam.h) drives over a whole sequence, fed here by the caller. Track() gives each
// frame's pose as tracking has it then (keyframes are adjusted later by the local and global
// bundle adjustments, so the final pose may differ); Snapshot() gives the run so far for maps
// and trajectories a client can look at while it drives; Finish() settles the run as RunSlam
// ends one (the global adjustment, non-keyframes placed by their keyframes) and returns the
// same SlamResult. The same frames through Track() (the last one with last_frame) and Finish()
// give RunSlam's result, whether each frame goes through Track(name, images) or through
// FrontEnd() then Track(prepared) with the next frame's FrontEnd() beside this one's Track().
//
// Not thread-safe, but for one pairing: FrontEnd() of the next frame may run on another thread
// while Track() of the frame before runs (RunSlam's pipeline: the tracker's front end one frame
// ahead of its back end). Otherwise one caller at a time (the live job's thread).

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/slam/slam.h"

namespace omnirig::slam {

namespace internal {
class Tracker;
struct PreparedFrameData;
}  // namespace internal

// A frame through the tracker's front end (Session::FrontEnd: mirror mask, features of both
// cameras, stereo points), waiting for its Session::Track(). Move-only; opaque.
class PreparedFrame {
 public:
  PreparedFrame(PreparedFrame&&) noexcept;
  PreparedFrame& operator=(PreparedFrame&&) noexcept;
  ~PreparedFrame();
  const std::string& name() const;

 private:
  friend class Session;
  explicit PreparedFrame(std::unique_ptr<internal::PreparedFrameData> data);
  std::unique_ptr<internal::PreparedFrameData> data_;
};

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
  // Track(FrontEnd(name, images), last_frame).
  FrameReport Track(const std::string& name, const StereoImages& images, bool last_frame = false);
  // The front end of the next frame to track, which takes the next index (num_frames() if no
  // frame waits prepared, else one more). May run on another thread while Track() of the frame
  // prepared before runs; never two FrontEnd() at once, and every frame prepared is tracked, in
  // the order prepared. Throws InvalidArgument when an image's size differs from the rig's
  // calibration (the frame takes no index: the session is unchanged and goes on), and after
  // Finish().
  PreparedFrame FrontEnd(const std::string& name, const StereoImages& images);
  // The back end of a prepared frame (tracking, keyframes, local adjustment, place
  // recognition): its report as Track(name, images, last_frame) gives it. `on_pose` (may be
  // empty) hears the report once the frame's pose is tracked, with world_from_rig as tracked,
  // before a keyframe's mapping (new landmarks, place recognition, local adjustment) refines
  // it: a live caller answers there. Throws std::logic_error when `prepared` is not the next
  // frame to track.
  FrameReport Track(PreparedFrame prepared, bool last_frame = false,
                    const std::function<void(const FrameReport&)>& on_pose = {});
  // Gives back the index of the last frame prepared, which will not be tracked (a live frame
  // the server could not store): the next FrontEnd() takes it again. Throws std::logic_error
  // for any other frame.
  void Discard(PreparedFrame prepared);
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
  int num_prepared_ = 0;  // FrontEnd()'s alone: the indices given so far
  double start_wall_s_ = 0, start_cpu_s_ = 0;
  bool finished_ = false;
};

}  // namespace omnirig::slam
