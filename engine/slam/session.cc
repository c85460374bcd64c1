#include "engine/slam/session.h"

#include <ctime>
#include <stdexcept>

#include "engine/slam/tracker.h"
#include "engine/util/check.h"

namespace omnirig::slam {
namespace internal {

struct PreparedFrameData {
  int index = -1;
  Tracker::FrontEndResult front;
};

}  // namespace internal

namespace {

double WallSeconds() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

}  // namespace

Session::Session(const StereoRig& rig, const SlamOptions& options, const ProgressSink& progress)
    : rig_(rig), options_(options), progress_(progress) {
  options_.Check();
  tracker_ = std::make_unique<internal::Tracker>(rig_, options_, progress_);
  start_wall_s_ = WallSeconds();
  start_cpu_s_ = internal::CpuSeconds(CLOCK_PROCESS_CPUTIME_ID);
}

Session::~Session() = default;

PreparedFrame::PreparedFrame(std::unique_ptr<internal::PreparedFrameData> data)
    : data_(std::move(data)) {}
PreparedFrame::PreparedFrame(PreparedFrame&&) noexcept = default;
PreparedFrame& PreparedFrame::operator=(PreparedFrame&&) noexcept = default;
PreparedFrame::~PreparedFrame() = default;

const std::string& PreparedFrame::name() const { return data_->front.report.name; }

FrameReport Session::Track(const std::string& name, const StereoImages& images, bool last_frame) {
  return Track(FrontEnd(name, images), last_frame);
}

PreparedFrame Session::FrontEnd(const std::string& name, const StereoImages& images) {
  OMNIRIG_CHECK(!finished_, "the SLAM session has finished");
  const CameraModel* camera[2] = {&rig_.cam0, &rig_.cam1};
  const cv::Mat* image[2] = {&images.cam0, &images.cam1};
  // Checked before the tracker sees the frame and before it takes an index: a frame refused
  // here leaves no trace, so the session goes on with the next one.
  for (int c = 0; c < 2; ++c) {
    OMNIRIG_CHECK(image[c]->cols == camera[c]->width && image[c]->rows == camera[c]->height,
                  "frame " << name << ": cam" << c << " image is " << image[c]->cols << "x"
                           << image[c]->rows << " but the rig's calibration is " << camera[c]->width
                           << "x" << camera[c]->height);
  }
  auto data = std::make_unique<internal::PreparedFrameData>();
  data->index = num_prepared_;
  data->front = tracker_->FrontEnd(
      data->index, name, [&images](int) { return images; },
      /*parallel_cameras=*/options_.num_threads >= 2);
  ++num_prepared_;
  return PreparedFrame(std::move(data));
}

FrameReport Session::Track(PreparedFrame prepared, bool last_frame,
                           const std::function<void(const FrameReport&)>& on_pose) {
  OMNIRIG_CHECK(!finished_, "the SLAM session has finished");
  if (!prepared.data_ || prepared.data_->index != num_frames()) {
    throw std::logic_error("Session::Track: the prepared frame is not the next one to track");
  }
  const int index = num_frames();
  FrameReport report = tracker_->BackEnd(std::move(prepared.data_->front), last_frame, on_pose);
  result_.stage_totals.Add(report.times);
  result_.cpu_stage_totals.Add(report.cpu_times);
  result_.frames.push_back(report);
  const int map_index = tracker_->first_frame() + index;
  if (tracker_->map().has_pose[map_index]) {
    report.world_from_rig = tracker_->map().rig_from_world[map_index].Inverse();
  }
  return report;
}

void Session::Discard(PreparedFrame prepared) {
  if (!prepared.data_ || prepared.data_->index != num_prepared_ - 1) {
    throw std::logic_error("Session::Discard: only the last frame prepared can be given back");
  }
  --num_prepared_;
}

SlamSnapshot Session::Snapshot() const {
  SlamSnapshot snapshot;
  for (size_t i = 0; i < result_.frames.size(); ++i) {
    const FrameReport& frame = result_.frames[i];
    snapshot.names.push_back(frame.name);
    snapshot.states.push_back(frame.state);
    if (frame.keyframe) snapshot.keyframes.push_back(static_cast<int>(i));
  }
  snapshot.world_from_rig = tracker_->CurrentWorldFromRig();
  snapshot.map = tracker_->CurrentMap();
  snapshot.num_keyframes = tracker_->num_keyframes();
  return snapshot;
}

SlamResult Session::Finish() {
  OMNIRIG_CHECK(!finished_, "the SLAM session has finished");
  OMNIRIG_CHECK(!result_.frames.empty(), "SLAM needs at least one stereo frame");
  finished_ = true;
  tracker_->Finish(progress_, &result_);
  result_.total_s = WallSeconds() - start_wall_s_;
  result_.total_cpu_s = internal::CpuSeconds(CLOCK_PROCESS_CPUTIME_ID) - start_cpu_s_;
  return std::move(result_);
}

}  // namespace omnirig::slam
