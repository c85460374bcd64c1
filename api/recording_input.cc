#include "api/recording_input.h"

#include <cmath>

#include "api/json_fields.h"
#include "engine/util/check.h"
#include "engine/util/error_prefix.h"

namespace omnirig::api {

using nlohmann::json;

std::set<std::string> RecordingFieldNames() {
  return {"recording", "topic", "topics", "pair_tolerance_s", "start_s", "end_s", "frame_step"};
}

namespace {

std::vector<std::string> TopicsField(const json& params, int num_topics) {
  if (num_topics == 1) {
    OMNIRIG_CHECK(!params.contains("topics"),
                  "a calibration reads one camera: name its topic with \"topic\": "
                  "\"/cam0/image_raw\", not \"topics\"");
    OMNIRIG_CHECK(params.contains("topic"),
                  "\"recording\" needs \"topic\": the camera's image topic, e.g. "
                  "\"topic\": \"/cam0/image_raw\"");
    return {StringField(params, "params", "topic")};
  }
  OMNIRIG_CHECK(!params.contains("topic"),
                "this job reads two cameras: name their topics with \"topics\": {\"cam0\": "
                "\"/cam0/image_raw\", \"cam1\": \"/cam1/image_raw\"}, not \"topic\"");
  OMNIRIG_CHECK(params.contains("topics"),
                "\"recording\" needs \"topics\": {\"cam0\": \"/cam0/image_raw\", \"cam1\": "
                "\"/cam1/image_raw\"}, the two cameras' image topics");
  const json& topics = params["topics"];
  OMNIRIG_CHECK(topics.is_object() && topics.size() == 2 && topics.contains("cam0") &&
                    topics.contains("cam1") && topics["cam0"].is_string() &&
                    topics["cam1"].is_string(),
                "field 'params.topics' must be {\"cam0\": TOPIC, \"cam1\": TOPIC}");
  const std::string cam0 = topics["cam0"], cam1 = topics["cam1"];
  OMNIRIG_CHECK(cam0 != cam1, "'topics' names " << cam0 << " for both cameras");
  return {cam0, cam1};
}

}  // namespace

std::optional<RecordingInput> RecordingInputFromJson(const json& params, int num_topics) {
  if (!params.is_object() || !params.contains("recording")) {
    for (const char* key : {"topic", "topics"}) {
      OMNIRIG_CHECK(!params.is_object() || !params.contains(key),
                    "'" << key << "' names topics of a recording: add \"recording\": NAME (a "
                        << "recording of the dataset)");
    }
    return std::nullopt;
  }
  RecordingInput input;
  input.recording = StringField(params, "params", "recording");
  OMNIRIG_CHECK(!input.recording.empty(), "field 'params.recording' is empty");
  input.topics = TopicsField(params, num_topics);
  ReadOptions(params, "params",
              {{"frame_step", &input.frames.frame_step},
               {"start_s", &input.frames.start_s},
               {"end_s", &input.frames.end_s},
               {"pair_tolerance_s", &input.frames.pair_tolerance_s}});
  OMNIRIG_CHECK(num_topics == 2 || !params.contains("pair_tolerance_s"),
                "'pair_tolerance_s' pairs two cameras' frames; a calibration reads one topic");
  WithErrorPrefix("invalid 'params': ", [&] { input.frames.Check(); });
  return input;
}

void CheckRecordingInput(const RecordingInput& input, const SubmissionInputs& inputs) {
  const auto source = OpenJobRecording(inputs.open_recording, input.recording);
  for (const std::string& topic : input.topics) io::CheckImageTopic(*source, topic);
}

RecordingFramesRead ReadRecordingFrames(const RecordingInput& input, const OpenRecording& open,
                                        const ProgressSink& progress) {
  RecordingFramesRead read;
  read.source = OpenJobRecording(open, input.recording);
  read.frames = io::SelectRecordingFrames(*read.source, input.topics, input.frames, progress);
  return read;
}

json RecordingFramesJson(const RecordingInput& input, const io::RecordingFrames& frames) {
  json result = {{"kind", "recording"},
                 {"recording", input.recording},
                 {"topics", input.topics},
                 {"num_messages", frames.num_messages},
                 {"num_unpaired", frames.num_unpaired},
                 {"frame_step", input.frames.frame_step},
                 {"start_s", input.frames.start_s},
                 {"end_s", std::isfinite(input.frames.end_s) ? json(input.frames.end_s) : json()},
                 {"num_frames", frames.frames.size()},
                 {"first_stamp_s", frames.first_stamp_s}};
  if (input.topics.size() == 2) result["pair_tolerance_s"] = frames.pair_tolerance_s;
  return result;
}

json RecordingTopicsJson(const RecordingInput& input) {
  json topics = json::object();
  for (size_t c = 0; c < input.topics.size(); ++c) topics["cam" + std::to_string(c)] = input.topics[c];
  return topics;
}

}  // namespace omnirig::api
