#pragma once
// Frames of a robot recording's image topics, as jobs read them: one camera's frames (a
// calibration) or two cameras' frames paired by header stamp (a rig, stereo, SLAM), selected by
// time range and step, decoded from the recording's messages one frame at a time as the job asks
// (no frame is copied to disk).
//
// The engine knows no container: a recording reaches it as a MessageSource, which the service
// implements with its storage's reader (storage/recording.h) and hands to jobs
// (api::JobContext::open_recording). Frames are named by their header stamp as recordings'
// frames are elsewhere ("t1700000000.050", FrameName in engine/util/image_pairs.h).
//
// Pairing: each cam0 frame pairs with the cam1 frame of nearest stamp when they differ by at
// most the tolerance, each cam1 frame at most once. Frames of either topic without a partner
// (a recorder drops messages under load) are left out and counted; no pair at all is an error.

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/util/progress.h"

namespace omnirig::io {

struct RecordedTopic {
  std::string name;      // "/cam0/image_raw"
  std::string type;      // "sensor_msgs/Image", "sensor_msgs/msg/CompressedImage", ...
  std::string encoding;  // "ros1" or "cdr"
  int64_t message_count = 0;
};

// One message, valid only during the callback that receives it.
struct RecordedMessage {
  const RecordedTopic* topic = nullptr;
  std::string_view data;  // the serialized message
};

// A recording's messages, read in the order the recording stores them.
class MessageSource {
 public:
  virtual ~MessageSource() = default;
  // The name the dataset lists the recording under ("run.bag", a ROS 2 bag's folder "run").
  virtual const std::string& name() const = 0;
  virtual const std::vector<RecordedTopic>& topics() const = 0;
  // Calls `on_message` with each message of `topics` in stored order until it returns false.
  // Throws InvalidArgument when the recording turns out damaged while reading.
  virtual void ReadMessages(const std::set<std::string>& topics,
                            const std::function<bool(const RecordedMessage&)>& on_message) const = 0;
};

// The topics of `source` that hold images (sensor_msgs/Image or CompressedImage), by name.
std::vector<std::string> ImageTopics(const MessageSource& source);

// Throws InvalidArgument, naming the recording and listing its image topics, when `topic` is not
// one of its topics or holds no images (its type named).
void CheckImageTopic(const MessageSource& source, const std::string& topic);

struct RecordingFrameOptions {
  // cam0 and cam1 frames pair when their stamps differ by at most this; 0 picks a quarter of
  // cam0's median frame period: hardware-triggered cameras stamp a pair within microseconds and
  // software-triggered ones within a few milliseconds, while a quarter period never pairs a
  // frame with its neighbour's partner.
  double pair_tolerance_s = 0.0;
  int frame_step = 1;    // every frame_step-th frame (or pair) of the time range
  double start_s = 0.0;  // the time range, seconds after the first topic's first stamp, both
  double end_s = std::numeric_limits<double>::infinity();  // ends included
  void Check() const;
};

struct RecordingFrame {
  std::string name;          // FrameName of the stamp, e.g. "t1700000000.050"
  double timestamp_s = 0;    // the first topic's header stamp, seconds since the Unix epoch
  std::vector<int64_t> message;  // per topic: the message's position among the topic's messages
};

struct RecordingFrames {
  std::vector<std::string> topics;  // one (a camera) or two (cam0, cam1)
  std::vector<RecordingFrame> frames;
  double pair_tolerance_s = 0;            // used (two topics)
  std::vector<int64_t> num_messages;      // per topic
  std::vector<int64_t> num_unpaired;      // per topic, frames left without a partner
  double first_stamp_s = 0;               // the first topic's first stamp (start_s counts from it)
};

// Reads the header stamp of every message of `topics` (one pass; no pixels decoded), pairs two
// topics' frames by stamp, and selects the time range and step. Throws InvalidArgument: a topic
// that is no image topic (CheckImageTopic), a message whose header cannot be read, no pair, no
// frame in the range. Cancelled through `progress`.
RecordingFrames SelectRecordingFrames(const MessageSource& source,
                                      const std::vector<std::string>& topics,
                                      const RecordingFrameOptions& options,
                                      const ProgressSink& progress = ProgressSink());

// Decodes the selected frames' images: Load(k) returns frames[k]'s image per topic, 8-bit grey
// or BGR (16-bit images scaled by 1/257). A background thread reads the recording ahead of the
// job and decodes up to a few frames in advance, so decoding overlaps the job's own work; a call
// for an earlier frame than the last starts the reading again from the beginning (a second pass,
// e.g. the dense map's keyframes). Load is called from one thread at a time.
class RecordingFrameReader {
 public:
  RecordingFrameReader(std::shared_ptr<const MessageSource> source, RecordingFrames frames);
  ~RecordingFrameReader();
  RecordingFrameReader(const RecordingFrameReader&) = delete;
  RecordingFrameReader& operator=(const RecordingFrameReader&) = delete;

  std::vector<cv::Mat> Load(int k);
  const RecordingFrames& frames() const { return frames_; }

 private:
  struct Shared;
  void Start(int first_frame);
  void Stop();

  std::shared_ptr<const MessageSource> source_;
  RecordingFrames frames_;
  std::unique_ptr<Shared> shared_;
  int next_ = 0;  // the frame the running reader delivers next
};

// One image message decoded as RecordingFrameReader returns it (8-bit grey or BGR).
cv::Mat DecodeFrameImage(const RecordedTopic& topic, std::string_view data);

}  // namespace omnirig::io
