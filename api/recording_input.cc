#include "api/recording_input.h"

#include <cmath>
#include <map>
#include <memory>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

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

RecordingImages CollectRecordingImages(const RecordingFramesRead& frames,
                                       const ProgressSink& progress) {
  const io::RecordingFrames& selected = frames.frames;
  const size_t num_topics = selected.topics.size();
  // Per topic: message position -> frame; the frames' serialized messages, by frame.
  std::vector<std::map<int64_t, size_t>> frame_of(num_topics);
  for (size_t k = 0; k < selected.frames.size(); ++k) {
    for (size_t t = 0; t < num_topics; ++t) frame_of[t][selected.frames[k].message[t]] = k;
  }
  auto messages = std::make_shared<std::vector<std::vector<std::string>>>(
      num_topics, std::vector<std::string>(selected.frames.size()));
  std::vector<const io::RecordedTopic*> topics(num_topics, nullptr);
  std::vector<int64_t> position(num_topics, 0);
  size_t remaining = selected.frames.size() * num_topics;
  frames.source->ReadMessages(
      std::set<std::string>(selected.topics.begin(), selected.topics.end()),
      [&](const io::RecordedMessage& message) {
        for (size_t t = 0; t < num_topics; ++t) {
          if (message.topic->name != selected.topics[t]) continue;
          topics[t] = message.topic;
          const auto it = frame_of[t].find(position[t]++);
          if (it == frame_of[t].end()) continue;
          (*messages)[t][it->second] = std::string(message.data);
          --remaining;
        }
        progress.ThrowIfCancelled();
        return remaining > 0;
      });
  RecordingImages images;
  // Name -> (topic, frame).
  auto index = std::make_shared<std::map<std::string, std::pair<size_t, size_t>>>();
  for (size_t k = 0; k < selected.frames.size(); ++k) {
    const std::string name = selected.frames[k].name + ".msg";
    if (num_topics == 1) {
      images.names.push_back(name);
      (*index)[name] = {0, k};
    } else {
      images.pairs.push_back({name, "cam0/" + name, "cam1/" + name});
      (*index)["cam0/" + name] = {0, k};
      (*index)["cam1/" + name] = {1, k};
    }
  }
  std::vector<io::RecordedTopic> topic_copies;
  for (const io::RecordedTopic* topic : topics) topic_copies.push_back(topic ? *topic : io::RecordedTopic{});
  images.read = [messages, index, topic_copies](const std::string& name, int imread_flags) {
    const auto it = index->find(name);
    if (it == index->end()) return cv::Mat();
    const auto [t, k] = it->second;
    cv::Mat image;
    try {
      image = io::DecodeFrameImage(topic_copies[t], (*messages)[t][k]);
    } catch (const InvalidArgument&) {
      return cv::Mat();  // reported as unreadable, as a damaged file is
    }
    cv::Mat converted;
    if (imread_flags == cv::IMREAD_GRAYSCALE && image.channels() == 3) {
      cv::cvtColor(image, converted, cv::COLOR_BGR2GRAY);
      return converted;
    }
    if (imread_flags == cv::IMREAD_COLOR && image.channels() == 1) {
      cv::cvtColor(image, converted, cv::COLOR_GRAY2BGR);
      return converted;
    }
    return image;
  };
  return images;
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

StereoPairsInput ReadStereoPairs(const nlohmann::json& params, const JobContext& context) {
  StereoPairsInput out{FolderImageReader(context.dataset_dir), {}, nullptr};
  const auto recording = RecordingInputFromJson(params, 2);
  if (!recording) {
    out.pairs = MatchImagePairs(context.image_names);
    return out;
  }
  const RecordingFramesRead frames = ReadRecordingFrames(*recording, context.open_recording,
                                                         SubRange(context.progress, 0.0, 0.0));
  RecordingImages images = CollectRecordingImages(frames, context.progress);
  out.read = std::move(images.read);
  out.pairs = std::move(images.pairs);
  out.input = RecordingFramesJson(*recording, frames.frames);
  return out;
}

}  // namespace omnirig::api
