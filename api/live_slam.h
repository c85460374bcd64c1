#pragma once
// A live slam job: SLAM over frames a robot sends while it drives (engine/slam/session.h),
// tracked as they arrive and answered with their pose, instead of over a recording uploaded
// before the job.
//
// Params: the slam job's (api/slam_job.h) with
//   "live": true,                 this is a live job
//   "live_idle_timeout_s": 60     optional: the job finishes by itself after this long without
//                                 a frame
// ("ground_truth" and the video-only fields are refused: a live job has no recording yet).
//
// The server hands each frame to the job through a LiveMailbox: one slot, newest wins. A frame
// still waiting when a newer one arrives is skipped (answered "skipped", never tracked), so a
// robot faster than tracking meets a bounded delay, never a growing queue. With 2 threads or
// more (JobContext::num_threads) the job tracks in a pipeline, as the batch RunSlam does: when
// the back end of a frame starts (tracking, keyframes, local adjustment, place recognition), the
// newest frame waiting is taken and its front end (decoding if needed, mirror mask, features of
// both cameras, stereo points: slam::Session::FrontEnd) runs on a thread of its own meanwhile;
// frames arriving later wait in the slot of one. So the job keeps up with the slower of the two
// halves rather than their sum, and only a frame that will be tracked gets a front end. A
// finish tracks the frame in its front end first; a cancel answers it 409 job_finished.
//
// The frames are the dataset's too (stored by the server as they arrive), so that a job whose
// server stopped runs again, as a batch slam job, over all of them. The server hands a frame
// over as it starts storing it (LiveFrame::stored): the front end runs while the files are
// written and synced, and the back end waits for them, so every frame tracked is stored.
//
// A frame's answer (200): {"frame_index" (its index among the tracked frames; null when
// skipped), "name", "stamp_s", "state" ("initialised", "tracked", ... as slam.h's
// FrameReport, or "skipped"), "keyframe", "world_from_rig": {"rotation_wxyz",
// "translation_m"} | null, "latency_ms" (receipt to pose), "num_skipped" (the job's so far)}.
// It leaves once the pose is tracked (slam::Session::Track's on_pose): a keyframe's mapping
// (new landmarks, place recognition, local adjustment) runs after it, before the next frame's
// back end, and refines the keyframe's pose in the job's later artifacts.
//
// While the job runs, trajectory.json and map.ply (as the batch job writes them, the poses as
// the run holds them now) are rewritten in the output folder at most every
// kLiveArtifactInterval_s, and after the first frame; with "dense_map", occupancy.pgm and
// occupancy.yaml too, the grid so far, after new keyframes (api/live_publisher.h: they are
// written off the tracking thread, which only takes the snapshot). At the end: loops settled,
// the global adjustment and the batch job's artifacts and result, with "live": {"num_received",
// "num_tracked_frames", "num_skipped", "latency_ms": {"p50", "p95", "p99", "max"},
// "ended_by": "finish" | "idle_timeout"}.

#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "api/job_types.h"
#include "engine/geometry/camera_model.h"

namespace omnirig::api {

constexpr double kLiveArtifactInterval_s = 1.0;

struct LiveSlamParams {
  double idle_timeout_s = 60.0;
};
// Whether `params` ask for a live job ("live": true). Throws InvalidArgument when "live" is
// there but not a boolean.
bool IsLiveSlam(const nlohmann::json& params);
// The live fields, and the slam params (SlamParamsFromJson) checked as a live job takes them.
// Throws InvalidArgument naming the field.
LiveSlamParams LiveSlamParamsFromJson(const nlohmann::json& params);

// What the server tells the client of one frame: a status (200, or an error's) and the body.
struct LiveAnswer {
  int status = 200;
  nlohmann::json body;
};

struct LiveFrame {
  // The dataset's NAME of the frame (cam0/NAME, cam1/NAME): slam::FrameName of the stamp and
  // the images' extension, e.g. "t000012.345.png".
  std::string name;
  double stamp_s = 0;
  // Each camera's file bytes and, for a stacked frame (split when it is stored), its decoded
  // image. Separate cam0 and cam1 parts are decoded by the job when it takes the frame (a frame
  // skipped for a newer one is never decoded), which refuses an image it cannot decode.
  std::string encoded[2];
  cv::Mat decoded[2];
  std::chrono::steady_clock::time_point received = std::chrono::steady_clock::now();
  std::promise<LiveAnswer> answer;
  // The server stores the frame in the job's dataset while the job runs its front end: ready
  // once the files are committed, holding the storing's exception when they could not be. The
  // job tracks only a stored frame; one that was not is dropped unanswered by the job (its
  // sender hears the server's error). Not valid: the frame was stored before it was handed over.
  std::shared_future<void> stored;
};

// The one-slot mailbox between the HTTP threads (Put) and the job's thread (Take).
class LiveMailbox {
 public:
  // Leaves `frame` for the job. A frame still waiting is answered "skipped" (see above).
  // False once closed: the frame is not taken (the caller answers it).
  bool Put(std::shared_ptr<LiveFrame> frame);
  // Waits up to `timeout_s` for a frame or the end; nullptr when none came. `finish` is set
  // once RequestFinish() was called and no frame waits.
  std::shared_ptr<LiveFrame> Take(double timeout_s, bool* finish);
  void RequestFinish();
  // No frame is taken any more; one still waiting is answered `answer`.
  void Close(const LiveAnswer& answer);
  int num_skipped() const;
  // Seconds since the last frame was put (or since the mailbox was made).
  double IdleSeconds() const;

 private:
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::shared_ptr<LiveFrame> waiting_;
  bool finish_ = false, closed_ = false;
  int num_skipped_ = 0;
  std::chrono::steady_clock::time_point last_put_ = std::chrono::steady_clock::now();
};

// The answer of a frame that was not tracked: skipped, with its latency so far.
nlohmann::json SkippedFrameJson(const LiveFrame& frame, int num_skipped);

// Runs a live job on the job's thread until finished (RequestFinish, or idle past
// live_idle_timeout_s), canceled (context.progress: throws Cancelled) or failed; answers every
// frame it takes; `on_frame` (may be empty) sees every tracked frame's answer, and
// `on_artifacts` (may be empty; called from another thread) every refresh of the files above
// ({"artifacts": [names], ...}, LivePublisherOptions::on_artifacts). Returns the result JSON,
// with the artifacts written into context.output_dir.
nlohmann::json RunLiveSlam(const nlohmann::json& params, const JobContext& context,
                           const StereoRig& rig, LiveMailbox& mailbox,
                           const std::function<void(const nlohmann::json&)>& on_frame,
                           const std::function<void(const nlohmann::json&)>& on_artifacts = {});

}  // namespace omnirig::api
