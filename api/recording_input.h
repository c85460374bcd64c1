#pragma once
// Params that make a job read its frames from one of its dataset's robot recordings instead of
// its image files (docs/recordings.md):
//   "recording": NAME                  the recording as the dataset lists it ("run.bag", "run")
//   "topic": T                         calibration: the camera's image topic
//   "topics": {"cam0": T0, "cam1": T1} relative_pose, stereo_reconstruct, slam: the two cameras'
//                                      topics, frames paired by header stamp
//   "pair_tolerance_s"                 optional (two topics; default a quarter of cam0's period)
//   "start_s", "end_s", "frame_step"   optional, as for videos: seconds after the first topic's
//                                      first stamp, every n-th frame
// The frames are decoded from the recording as the job reads them (engine/io/recording_frames.h).

#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "engine/features/image.h"
#include "engine/io/recording_frames.h"
#include "engine/util/image_pairs.h"
#include "engine/util/progress_range.h"

namespace omnirig::api {

struct RecordingInput {
  std::string recording;
  std::vector<std::string> topics;  // [T] or [T0, T1]
  io::RecordingFrameOptions frames;
};

// The keys above, for CheckKnownFields.
std::set<std::string> RecordingFieldNames();

// Reads the fields above from `params`: nullopt when there is no "recording". `num_topics` is
// the job's: 1 ("topic") or 2 ("topics"). Throws InvalidArgument saying what to write: "topic"
// on a stereo job, "topics" on a calibration, a missing topic, "topics" without exactly "cam0"
// and "cam1", "topic"/"topics" or the frame fields without "recording", a bad frame field.
std::optional<RecordingInput> RecordingInputFromJson(const nlohmann::json& params, int num_topics);

// The check at submission: the dataset holds the recording, and its topics are image topics.
// Throws InvalidArgument naming the recording and listing its image topics.
void CheckRecordingInput(const RecordingInput& input, const SubmissionInputs& inputs);

// Opens the recording and selects its frames (one pass over the stamps).
struct RecordingFramesRead {
  std::shared_ptr<const io::MessageSource> source;
  io::RecordingFrames frames;
};
RecordingFramesRead ReadRecordingFrames(const RecordingInput& input, const OpenRecording& open,
                                        const ProgressSink& progress);

// A recording's selected frames as images by name, for the pipelines that read images more than
// once and in parallel (calibration, rig, stereo): the frames' messages are held serialized in
// memory (a compressed frame its encoded bytes, a raw one its pixels; never written to disk) and
// decoded when read. Names: FRAME.msg (one topic), cam0/FRAME.msg and cam1/FRAME.msg (two), with
// FRAME the frame's name ("t1700000000.050"); the ".msg" keeps the stamp's decimals when
// artifacts take a name's stem (overlays, clouds).
struct RecordingImages {
  ImageReader read;
  std::vector<std::string> names;     // one topic: every frame's
  std::vector<ImagePairNames> pairs;  // two topics: the pairs'
};
RecordingImages CollectRecordingImages(const RecordingFramesRead& frames,
                                       const ProgressSink& progress);

// The stereo pairs a job reads: a recording's two topics when `params` name one ("recording",
// "topics"), the dataset's cam0/NAME, cam1/NAME images otherwise; `input` is the result's
// "input" (RecordingFramesJson) for a recording and null for images.
struct StereoPairsInput {
  ImageReader read;
  std::vector<ImagePairNames> pairs;
  nlohmann::json input;
};
StereoPairsInput ReadStereoPairs(const nlohmann::json& params, const JobContext& context);

// The result's "input" of a job on a recording: {"kind": "recording", "recording", "topics",
// "num_messages" (per topic), "num_unpaired" (per topic), "pair_tolerance_s" (two topics),
// "frame_step", "start_s", "end_s" (null: to the end), "num_frames", "first_stamp_s"}.
nlohmann::json RecordingFramesJson(const RecordingInput& input, const io::RecordingFrames& frames);

// Where each camera's images came from, for the exports: cam0's (and cam1's) topic.
nlohmann::json RecordingTopicsJson(const RecordingInput& input);

}  // namespace omnirig::api
