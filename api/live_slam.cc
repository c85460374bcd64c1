#include "api/live_slam.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <future>

#include "api/camera_json.h"
#include "api/json_fields.h"
#include "api/live_publisher.h"
#include "api/slam_job.h"
#include "engine/features/image.h"
#include "engine/slam/image_source.h"
#include "engine/slam/map_io.h"
#include "engine/slam/session.h"
#include "engine/util/check.h"
#include "engine/util/timer.h"

namespace omnirig::api {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double Percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * values.size()));
  return values[std::clamp<size_t>(rank, 1, values.size()) - 1];
}

cv::Mat Decode(const std::string& bytes, const std::string& what) {
  cv::Mat image = DecodeImageBgr(bytes);
  OMNIRIG_CHECK(!image.empty(), what << " cannot be decoded");
  return image;
}

slam::StereoImages Images(const LiveFrame& frame) {
  slam::StereoImages images;
  // cam1 on a thread beside cam0's when both are still encoded.
  std::future<cv::Mat> cam1;
  if (frame.decoded[1].empty()) {
    cam1 = std::async(frame.decoded[0].empty() ? std::launch::async : std::launch::deferred,
                      [&frame] { return Decode(frame.encoded[1], frame.name + " cam1"); });
  }
  images.cam0 =
      frame.decoded[0].empty() ? Decode(frame.encoded[0], frame.name + " cam0") : frame.decoded[0];
  images.cam1 = cam1.valid() ? cam1.get() : frame.decoded[1];
  return images;
}

json TrackedFrameJson(const slam::FrameReport& report, const LiveFrame& frame, int index,
                      int num_skipped) {
  return {{"frame_index", index},
          {"name", frame.name},
          {"stamp_s", frame.stamp_s},
          {"state", report.state},
          {"reason", report.reason},
          {"keyframe", report.keyframe},
          {"in_map", report.in_map},
          {"world_from_rig",
           report.world_from_rig ? PoseToJson(*report.world_from_rig) : json(nullptr)},
          {"latency_ms", MillisecondsSince(frame.received)},
          {"num_skipped", num_skipped}};
}

// The answer to a frame whose job ended (`how`: "was canceled", "has ended") before it was
// tracked; it is stored in the job's dataset all the same.
LiveAnswer JobFinishedAnswer(const LiveFrame& frame, const std::string& how) {
  return {409,
          {{"error",
            {{"code", "job_finished"},
             {"message", "the live job " + how + ": frame " + frame.name +
                             " is stored in its dataset but not tracked"},
             {"details", {{"name", frame.name}}}}}}};
}

LiveAnswer CanceledAnswer(const LiveFrame& frame) {
  return JobFinishedAnswer(frame, "was canceled");
}

// A frame the server could not store: not tracked. The server answers its sender with the
// storing's error; this answer is the job's side of it, for a reader of the frame's promise.
LiveAnswer NotStoredAnswer(const LiveFrame& frame) {
  return {409,
          {{"error",
            {{"code", "frame_not_stored"},
             {"message", "frame " + frame.name +
                             " could not be stored in the job's dataset: it was not tracked"},
             {"details", {{"name", frame.name}}}}}}};
}

// A frame taken from the mailbox whose job ended (canceled or failed) before it was tracked.
LiveAnswer EndedAnswer(const LiveFrame& frame, const ProgressSink& progress) {
  return JobFinishedAnswer(frame, progress.IsCancelled() ? "was canceled" : "has ended");
}

// A frame taken from the mailbox and its front end (decoding if the request's thread left it
// undecoded, Session::FrontEnd). Pipelined (a job with 2 threads or more, as RunSlam), the front
// end runs on a thread of its own, beside the back end of the frame before; otherwise on the
// job's thread when the frame's turn comes. The destructor waits for that thread; a frame never
// handed over by Take() (the job ended first) is answered there.
class FrontEndJob {
 public:
  FrontEndJob(std::shared_ptr<LiveFrame> frame, slam::Session& session, bool pipelined,
              const ProgressSink& progress)
      : frame_(std::move(frame)), progress_(progress) {
    const LiveFrame* taken = frame_.get();
    prepared_ =
        std::async(pipelined ? std::launch::async : std::launch::deferred,
                   [&session, taken] { return session.FrontEnd(taken->name, Images(*taken)); });
  }
  ~FrontEndJob() {
    // A front end on its own thread ends first; one not yet run on the job's thread never runs.
    if (prepared_.valid() &&
        prepared_.wait_for(std::chrono::seconds(0)) != std::future_status::deferred) {
      prepared_.wait();
    }
    try {
      if (frame_) frame_->answer.set_value(EndedAnswer(*frame_, progress_));
    } catch (const std::exception&) {
      // Out of memory for the answer: the sender's request ends with the job (the promise is
      // broken).
    }
  }
  FrontEndJob(const FrontEndJob&) = delete;
  FrontEndJob& operator=(const FrontEndJob&) = delete;

  // Hands the frame over (`*frame`: the caller answers it from now on, also when this throws)
  // and waits for its front end; throws what the front end threw.
  slam::PreparedFrame Take(std::shared_ptr<LiveFrame>* frame) {
    *frame = std::move(frame_);
    return prepared_.get();
  }

 private:
  std::shared_ptr<LiveFrame> frame_;
  const ProgressSink& progress_;
  std::future<slam::PreparedFrame> prepared_;
};

// What the job's loop keeps of the frames it tracked.
struct TrackedFrames {
  std::vector<double> stamps;
  std::vector<std::string> names;
  std::vector<double> latencies_ms;
  int num_received = 0;  // taken from the mailbox
  bool snapshot_due = false;
  Timer since_frame;  // since the last frame was answered
};

// Tracks the frame of `*next` (waits for its front end) and answers it. Pipelined, the newest
// frame waiting in the mailbox, if any, becomes `*next` when the back end starts and goes through
// its front end meanwhile (a frame arriving later waits in the slot of one). A frame the
// front end refuses (InvalidArgument: undecodable, another size) is answered 422 and the job
// goes on; cancellation and failures are answered and thrown.
void TrackNext(slam::Session& session, LiveMailbox& mailbox, bool pipelined,
               const ProgressSink& progress, std::optional<FrontEndJob>* next,
               TrackedFrames* tracked, const std::function<void(const json&)>& on_frame) {
  std::shared_ptr<LiveFrame> frame;
  std::optional<slam::PreparedFrame> prepared;
  std::exception_ptr front_failure;
  try {
    prepared.emplace((*next)->Take(&frame));
  } catch (...) {
    front_failure = std::current_exception();
  }
  next->reset();
  // The server stored the frame while its front end ran; one it could not store is not tracked
  // (its sender hears why from the server, which answers that request itself).
  if (!front_failure && frame->stored.valid()) {
    try {
      frame->stored.get();
    } catch (...) {
      session.Discard(std::move(*prepared));
      frame->answer.set_value(NotStoredAnswer(*frame));
      return;
    }
  }
  LiveAnswer answer;
  bool answered = false;  // the sender has its pose; the keyframe's mapping may still run
  try {
    if (front_failure) std::rethrow_exception(front_failure);
    // Canceled while its front end ran: the sender hears that the job has ended.
    progress.ThrowIfCancelled();
    bool finish = false;  // the loop hears of it when no frame is under way
    std::shared_ptr<LiveFrame> newer = pipelined ? mailbox.Take(0.0, &finish) : nullptr;
    if (newer) {
      ++tracked->num_received;
      next->emplace(std::move(newer), session, pipelined, progress);
    }
    // The sender hears its pose as soon as it is tracked; a keyframe's mapping (new landmarks,
    // place recognition, local adjustment) runs after the answer, before the next frame's back
    // end, so the run is the one it would be had the answer waited.
    const int index = session.num_frames();
    session.Track(std::move(*prepared), /*last_frame=*/false,
                  [&](const slam::FrameReport& report) {
                    answer.body = TrackedFrameJson(report, *frame, index, mailbox.num_skipped());
                    frame->answer.set_value(answer);
                    answered = true;
                  });
    tracked->stamps.push_back(frame->stamp_s);
    tracked->names.push_back(frame->name);
    tracked->latencies_ms.push_back(answer.body["latency_ms"].get<double>());
    tracked->snapshot_due = true;
  } catch (const InvalidArgument& e) {
    // Refused after its pose was answered: the session holds part of the frame, so the job
    // cannot go on.
    if (answered) throw;
    answer = {422,
              {{"error",
                {{"code", "invalid_frame"},
                 {"message", e.what()},
                 {"details", {{"name", frame->name}}}}}}};
  } catch (const Cancelled&) {
    // Canceled while this frame was tracked: the sender hears that the job has ended.
    if (!answered) frame->answer.set_value(CanceledAnswer(*frame));
    throw;
  } catch (const std::exception& e) {
    // The job fails (the runner records why); the frame's sender hears it first.
    if (!answered) {
      frame->answer.set_value({500,
                               {{"error",
                                 {{"code", "job_failed"},
                                  {"message", e.what()},
                                  {"details", {{"name", frame->name}}}}}}});
    }
    throw;
  }
  if (!answered) frame->answer.set_value(answer);
  tracked->since_frame.Restart();
  if (answer.status == 200) {
    if (on_frame) on_frame(answer.body);
    progress.Report(0.0, "live",
                    std::to_string(session.num_frames()) + " frames tracked, " +
                        std::to_string(mailbox.num_skipped()) + " skipped");
  }
}

}  // namespace

bool IsLiveSlam(const json& params) {
  if (!params.is_object() || !params.contains("live")) return false;
  OMNIRIG_CHECK(params["live"].is_boolean(), "field 'params.live' must be true or false");
  return params["live"].get<bool>();
}

LiveSlamParams LiveSlamParamsFromJson(const json& params) {
  LiveSlamParams live;
  ReadOptions(params, "params", {{"live_idle_timeout_s", &live.idle_timeout_s}});
  OMNIRIG_CHECK(std::isfinite(live.idle_timeout_s) && live.idle_timeout_s > 0,
                "field 'params.live_idle_timeout_s' must be positive");
  const SlamParams slam = SlamParamsFromJson(params);
  OMNIRIG_CHECK(!slam.ground_truth,
                "field 'params.ground_truth' is for a recording: a live job "
                "has none yet (omnirig live compares with a ground truth)");
  OMNIRIG_CHECK(!slam.video_only_fields && slam.frames.frame_step == 1,
                "'frame_step', 'start_s', 'end_s' and 'pair_tolerance_s' select frames of a "
                "recording: a live job tracks the frames as they are sent");
  return live;
}

bool LiveMailbox::Put(std::shared_ptr<LiveFrame> frame) {
  std::shared_ptr<LiveFrame> displaced;
  int skipped = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_) return false;
    displaced = std::move(waiting_);
    if (displaced) skipped = ++num_skipped_;
    waiting_ = std::move(frame);
    last_put_ = Clock::now();
  }
  wake_.notify_all();
  if (displaced) displaced->answer.set_value({200, SkippedFrameJson(*displaced, skipped)});
  return true;
}

std::shared_ptr<LiveFrame> LiveMailbox::Take(double timeout_s, bool* finish) {
  std::unique_lock<std::mutex> lock(mutex_);
  wake_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                 [this] { return waiting_ || finish_ || closed_; });
  *finish = finish_ && !waiting_;
  return std::move(waiting_);
}

void LiveMailbox::RequestFinish() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    finish_ = true;
  }
  wake_.notify_all();
}

void LiveMailbox::Close(const LiveAnswer& answer) {
  std::shared_ptr<LiveFrame> waiting;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    waiting = std::move(waiting_);
  }
  wake_.notify_all();
  if (waiting) waiting->answer.set_value(answer);
}

int LiveMailbox::num_skipped() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return num_skipped_;
}

double LiveMailbox::IdleSeconds() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return std::chrono::duration<double>(Clock::now() - last_put_).count();
}

json SkippedFrameJson(const LiveFrame& frame, int num_skipped) {
  return {{"frame_index", nullptr},
          {"name", frame.name},
          {"stamp_s", frame.stamp_s},
          {"state", "skipped"},
          {"reason", "a newer frame arrived before this one could be tracked"},
          {"keyframe", false},
          {"world_from_rig", nullptr},
          {"latency_ms", MillisecondsSince(frame.received)},
          {"num_skipped", num_skipped}};
}

json RunLiveSlam(const json& params, const JobContext& context, const StereoRig& rig,
                 LiveMailbox& mailbox, const std::function<void(const json&)>& on_frame,
                 const std::function<void(const json&)>& on_artifacts) {
  const LiveSlamParams live = LiveSlamParamsFromJson(params);
  SlamParams parsed = SlamParamsFromJson(params);
  if (parsed.dense_map) {
    parsed.dense_map->rectification_tables_dir = context.RectificationTablesDir();
  }
  slam::SlamOptions options = parsed.options;
  options.num_threads = std::max(1, context.num_threads);
  if (parsed.map_job) options.saved_map = LoadSavedMap(context, *parsed.map_job);
  slam::Session session(rig, options, context.progress);
  LivePublisherOptions publishing;
  publishing.output_dir = context.output_dir;
  publishing.map_job = parsed.map_job;
  publishing.dense_map = parsed.dense_map;
  publishing.dataset_dir = context.dataset_dir;
  publishing.interval_s = kLiveArtifactInterval_s;
  publishing.log = context.log;
  publishing.on_artifacts = on_artifacts;
  // Stopped and joined when this returns or throws (its destructor).
  LivePublisher publisher(rig, std::move(publishing));
  TrackedFrames tracked;
  std::string ended_by = "finish";
  Timer since_snapshot;
  context.progress.Report(0.0, "live", "waiting for frames");
  // With 2 threads or more the next frame's front end runs beside this one's back end, so that
  // the job keeps up with the slower of the two rather than their sum.
  const bool pipelined = options.num_threads >= 2;
  // The frame whose front end runs or is due (declared after the session: its thread ends
  // first).
  std::optional<FrontEndJob> next;
  while (true) {
    bool finish = false;
    // With no front end under way, wait for a frame; otherwise its turn has come.
    if (!next) {
      std::shared_ptr<LiveFrame> taken = mailbox.Take(0.1, &finish);
      if (taken) ++tracked.num_received;
      if (taken && context.progress.IsCancelled()) {
        taken->answer.set_value(CanceledAnswer(*taken));
      } else if (taken) {
        next.emplace(std::move(taken), session, pipelined, context.progress);
      }
    }
    context.progress.ThrowIfCancelled();
    const bool tracked_one = next.has_value();
    if (next) TrackNext(session, mailbox, pipelined, context.progress, &next, &tracked, on_frame);
    // The first frame's snapshot at once, then at most one per interval: the copy of the map
    // grows with the run; the publisher writes it while tracking goes on (and while the next
    // frame's front end runs: Session::Snapshot reads only what the back end writes).
    if (tracked.snapshot_due && (tracked.stamps.size() == 1 ||
                                 since_snapshot.ElapsedSeconds() >= kLiveArtifactInterval_s)) {
      publisher.Publish(
          std::make_shared<const LiveSnapshot>(LiveSnapshot{session.Snapshot(), tracked.stamps}));
      tracked.snapshot_due = false;
      since_snapshot.Restart();
    }
    if (finish) break;
    // Idle: no frame received, nor one being tracked, for the timeout.
    if (!tracked_one && std::min(mailbox.IdleSeconds(), tracked.since_frame.ElapsedSeconds()) >=
                            live.idle_timeout_s) {
      ended_by = "idle_timeout";
      context.Log("no frame for " + std::to_string(live.idle_timeout_s) + " s: finishing");
      break;
    }
  }
  mailbox.Close({409,
                 {{"error",
                   {{"code", "job_finished"},
                    {"message", "the live job is finishing: it takes no more frames"},
                    {"details", json::object()}}}}});
  // The final artifacts replace the publisher's, made again from the final poses.
  publisher.Stop();
  OMNIRIG_CHECK(session.num_frames() > 0,
                "the live job ended (" << ended_by << ") before any frame was tracked");
  const slam::SlamResult result = session.Finish();
  const fs::path dataset_dir = context.dataset_dir;
  // The dense map (with "dense_map") reads the tracked frames back from the dataset.
  std::vector<ImagePairNames> pairs;
  for (const std::string& name : tracked.names)
    pairs.push_back({name, "cam0/" + name, "cam1/" + name});
  const slam::StereoFrameLoader load = slam::StereoImageLoader(dataset_dir, pairs);
  const json input = {{"kind", "live"}, {"num_frames", tracked.stamps.size()}};
  json report = WriteSlamReport(rig, result, tracked.stamps, {}, input, load, parsed.dense_map,
                                options.num_threads, context.output_dir, context.progress,
                                {parsed.rig_job, parsed.map_job});
  report["live"] = {{"num_received", tracked.num_received + mailbox.num_skipped()},
                    {"num_tracked_frames", tracked.stamps.size()},
                    {"num_skipped", mailbox.num_skipped()},
                    {"latency_ms",
                     {{"p50", Percentile(tracked.latencies_ms, 50)},
                      {"p95", Percentile(tracked.latencies_ms, 95)},
                      {"p99", Percentile(tracked.latencies_ms, 99)},
                      {"max", Percentile(tracked.latencies_ms, 100)}}},
                    {"ended_by", ended_by}};
  return report;
}

}  // namespace omnirig::api
