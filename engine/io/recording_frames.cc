#include "engine/io/recording_frames.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <condition_variable>
#include <exception>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>
#include <unordered_map>

#include "engine/io/image_message.h"
#include "engine/util/check.h"
#include "engine/util/image_pairs.h"

namespace omnirig::io {
namespace {

// How many decoded frames the reader keeps ready ahead of the job: enough to hide the jitter of
// one frame's decode, few enough that frames of 1280x1024 stay a few megabytes.
constexpr size_t kFramesAhead = 3;

const RecordedTopic* FindTopic(const MessageSource& source, const std::string& name) {
  for (const RecordedTopic& topic : source.topics()) {
    if (topic.name == name) return &topic;
  }
  return nullptr;
}

std::string ImageTopicList(const MessageSource& source) {
  const std::vector<std::string> topics = ImageTopics(source);
  if (topics.empty()) return "it holds no image topic (sensor_msgs/Image or CompressedImage)";
  std::string list = "its image topics are";
  for (size_t i = 0; i < topics.size(); ++i) list += (i ? ", " : " ") + topics[i];
  return list;
}

double Seconds(int64_t ns) { return static_cast<double>(ns) * 1e-9; }

// A topic's stamps with the position of their message, sorted by stamp.
using StampedMessages = std::vector<std::pair<int64_t, int64_t>>;

std::vector<StampedMessages> ReadStamps(const MessageSource& source,
                                        const std::vector<std::string>& topics,
                                        const ProgressSink& progress) {
  std::vector<StampedMessages> stamps(topics.size());
  int64_t total = 0;
  for (const std::string& name : topics) total += FindTopic(source, name)->message_count;
  int64_t seen = 0;
  source.ReadMessages(std::set<std::string>(topics.begin(), topics.end()),
                      [&](const RecordedMessage& message) {
                        for (size_t t = 0; t < topics.size(); ++t) {
                          if (message.topic->name != topics[t]) continue;
                          const int64_t stamp_ns = ImageMessageStamp(
                              message.topic->type, ParseSerialization(message.topic->encoding),
                              message.data);
                          stamps[t].push_back(
                              {stamp_ns, static_cast<int64_t>(stamps[t].size())});
                        }
                        if (++seen % 256 == 0) {
                          progress.ThrowIfCancelled();
                          progress.Report(std::min(1.0, static_cast<double>(seen) / total),
                                          "stamps");
                        }
                        return true;
                      });
  for (size_t t = 0; t < topics.size(); ++t) {
    OMNIRIG_CHECK(!stamps[t].empty(), source.name() << ": topic " << topics[t] << " holds no message");
    std::stable_sort(stamps[t].begin(), stamps[t].end());
  }
  return stamps;
}

double MedianPeriodS(const StampedMessages& stamps) {
  if (stamps.size() < 2) return 0.0;
  std::vector<int64_t> periods;
  for (size_t i = 1; i < stamps.size(); ++i) periods.push_back(stamps[i].first - stamps[i - 1].first);
  std::nth_element(periods.begin(), periods.begin() + periods.size() / 2, periods.end());
  return Seconds(periods[periods.size() / 2]);
}

// Pairs each of `first`'s frames with `second`'s nearest within `tolerance_ns`, each at most once.
std::vector<std::pair<size_t, size_t>> PairByStamp(const StampedMessages& first,
                                                   const StampedMessages& second,
                                                   int64_t tolerance_ns) {
  std::vector<std::pair<size_t, size_t>> pairs;
  std::vector<bool> used(second.size(), false);
  for (size_t i = 0; i < first.size(); ++i) {
    const int64_t t = first[i].first;
    auto it = std::lower_bound(second.begin(), second.end(), std::make_pair(t, int64_t{-1}));
    size_t j = static_cast<size_t>(it - second.begin());
    if (j == second.size() || (j > 0 && t - second[j - 1].first <= second[j].first - t)) --j;
    if (j >= second.size() || used[j] || std::llabs(second[j].first - t) > tolerance_ns) continue;
    used[j] = true;
    pairs.push_back({i, j});
  }
  return pairs;
}

}  // namespace

std::vector<std::string> ImageTopics(const MessageSource& source) {
  std::vector<std::string> names;
  for (const RecordedTopic& topic : source.topics()) {
    if (IsImageMessageType(topic.type)) names.push_back(topic.name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

void CheckImageTopic(const MessageSource& source, const std::string& topic) {
  const RecordedTopic* found = FindTopic(source, topic);
  OMNIRIG_CHECK(found != nullptr, "recording " << source.name() << " has no topic " << topic
                                               << ": " << ImageTopicList(source));
  OMNIRIG_CHECK(IsImageMessageType(found->type),
                "topic " << topic << " of recording " << source.name() << " holds "
                         << found->type
                         << " messages, not images (sensor_msgs/Image or CompressedImage): "
                         << ImageTopicList(source));
}

void RecordingFrameOptions::Check() const {
  OMNIRIG_CHECK(pair_tolerance_s >= 0 && std::isfinite(pair_tolerance_s),
                "'pair_tolerance_s' must be >= 0 (0 picks a quarter of the frame period)");
  OMNIRIG_CHECK(frame_step >= 1, "'frame_step' must be >= 1");
  OMNIRIG_CHECK(start_s >= 0 && std::isfinite(start_s), "'start_s' must be >= 0");
  OMNIRIG_CHECK(end_s >= start_s, "'end_s' must be >= 'start_s'");
}

RecordingFrames SelectRecordingFrames(const MessageSource& source,
                                      const std::vector<std::string>& topics,
                                      const RecordingFrameOptions& options,
                                      const ProgressSink& progress) {
  options.Check();
  OMNIRIG_CHECK(topics.size() == 1 || topics.size() == 2, "one or two topics are read, not "
                                                              << topics.size());
  for (const std::string& topic : topics) CheckImageTopic(source, topic);
  const std::vector<StampedMessages> stamps = ReadStamps(source, topics, progress);
  RecordingFrames selected;
  selected.topics = topics;
  for (const auto& topic : stamps) selected.num_messages.push_back(static_cast<int64_t>(topic.size()));
  selected.num_unpaired.assign(topics.size(), 0);
  const int64_t first_ns = stamps[0].front().first;
  selected.first_stamp_s = Seconds(first_ns);
  // The first topic's frames in the time range.
  StampedMessages in_range;
  for (const auto& stamp : stamps[0]) {
    const double t_s = Seconds(stamp.first - first_ns);
    if (t_s >= options.start_s && t_s <= options.end_s) in_range.push_back(stamp);
  }
  OMNIRIG_CHECK(!in_range.empty(),
                "no frame of " << topics[0] << " lies in [" << options.start_s << ", "
                               << options.end_s << "] s: its frames span "
                               << Seconds(stamps[0].back().first - first_ns)
                               << " s from its first stamp");
  std::vector<RecordingFrame> all;
  if (topics.size() == 1) {
    for (const auto& stamp : in_range) {
      all.push_back({FrameName(Seconds(stamp.first)), Seconds(stamp.first), {stamp.second}});
    }
  } else {
    selected.pair_tolerance_s = options.pair_tolerance_s > 0 ? options.pair_tolerance_s
                                                             : 0.25 * MedianPeriodS(stamps[0]);
    // A single frame has no period: its partner must carry its very stamp (to the microsecond).
    if (selected.pair_tolerance_s <= 0) selected.pair_tolerance_s = 1e-6;
    const int64_t tolerance_ns = static_cast<int64_t>(selected.pair_tolerance_s * 1e9);
    const auto pairs = PairByStamp(in_range, stamps[1], tolerance_ns);
    OMNIRIG_CHECK(!pairs.empty(),
                  "no frame of " << topics[0] << " pairs with a frame of " << topics[1]
                                 << " within " << selected.pair_tolerance_s * 1000
                                 << " ms ('pair_tolerance_s'): their first stamps are "
                                 << std::fixed << Seconds(stamps[0].front().first) << " and "
                                 << Seconds(stamps[1].front().first) << " s");
    selected.num_unpaired[0] = static_cast<int64_t>(in_range.size() - pairs.size());
    int64_t second_in_range = 0;
    for (const auto& stamp : stamps[1]) {
      second_in_range += stamp.first >= in_range.front().first - tolerance_ns &&
                         stamp.first <= in_range.back().first + tolerance_ns;
    }
    selected.num_unpaired[1] = second_in_range - static_cast<int64_t>(pairs.size());
    for (const auto& [i, j] : pairs) {
      const double t_s = Seconds(in_range[i].first);
      all.push_back({FrameName(t_s), t_s, {in_range[i].second, stamps[1][j].second}});
    }
  }
  for (size_t k = 0; k < all.size(); k += options.frame_step) selected.frames.push_back(all[k]);
  return selected;
}

cv::Mat DecodeFrameImage(const RecordedTopic& topic, std::string_view data) {
  cv::Mat image =
      DecodeImageMessage(topic.type, ParseSerialization(topic.encoding), data).image;
  if (image.depth() == CV_8U) return image;
  // 16-bit (mono16, a 16-bit PNG): the jobs read 8-bit images; the high byte keeps the scale.
  cv::Mat eight;
  image.convertTo(eight, CV_8U, 1.0 / 257.0);
  return eight;
}

// What the reading thread and Load share.
struct RecordingFrameReader::Shared {
  std::mutex mutex;
  std::condition_variable changed;
  std::map<int, std::vector<cv::Mat>> ready;  // whole frames, by index
  int wanted = 0;         // the frame Load waits for (earlier ones are not decoded)
  bool stop = false;      // set by Stop: the thread ends at its next message
  bool finished = false;  // the thread ended (all frames delivered, stopped, or failed)
  std::exception_ptr error;
  std::thread thread;
};

RecordingFrameReader::RecordingFrameReader(std::shared_ptr<const MessageSource> source,
                                           RecordingFrames frames)
    : source_(std::move(source)), frames_(std::move(frames)) {}

RecordingFrameReader::~RecordingFrameReader() { Stop(); }

void RecordingFrameReader::Stop() {
  if (!shared_) return;
  {
    std::lock_guard<std::mutex> lock(shared_->mutex);
    shared_->stop = true;
  }
  shared_->changed.notify_all();
  if (shared_->thread.joinable()) shared_->thread.join();
  shared_.reset();
}

void RecordingFrameReader::Start(int first_frame) {
  shared_ = std::make_unique<Shared>();
  shared_->wanted = first_frame;
  next_ = first_frame;
  Shared* shared = shared_.get();
  shared->thread = std::thread([this, shared, first_frame] {
    const size_t num_topics = frames_.topics.size();
    // Per topic: message position -> the frame that takes it (from first_frame on).
    std::vector<std::unordered_map<int64_t, int>> frame_of(num_topics);
    for (int k = first_frame; k < static_cast<int>(frames_.frames.size()); ++k) {
      for (size_t t = 0; t < num_topics; ++t) frame_of[t][frames_.frames[k].message[t]] = k;
    }
    std::vector<int64_t> position(num_topics, 0);
    std::map<int, std::vector<cv::Mat>> partial;
    // Messages still to come; the reading stops after the last selected frame's.
    size_t remaining = (frames_.frames.size() - first_frame) * num_topics;
    try {
      source_->ReadMessages(
          std::set<std::string>(frames_.topics.begin(), frames_.topics.end()),
          [&](const RecordedMessage& message) {
            size_t t = 0;
            while (t < num_topics && frames_.topics[t] != message.topic->name) ++t;
            if (t == num_topics) return true;
            const auto it = frame_of[t].find(position[t]++);
            if (it == frame_of[t].end()) return true;
            const int k = it->second;
            --remaining;
            bool skipped = false;
            {
              std::lock_guard<std::mutex> lock(shared->mutex);
              if (shared->stop) return false;
              skipped = k < shared->wanted;  // passed over by the job: not decoded
            }
            if (skipped) {
              partial.erase(k);
              return remaining > 0;
            }
            std::vector<cv::Mat>& images = partial[k];
            images.resize(num_topics);
            images[t] = DecodeFrameImage(*message.topic, message.data);
            const bool whole = std::none_of(images.begin(), images.end(),
                                            [](const cv::Mat& image) { return image.empty(); });
            if (!whole) return remaining > 0;
            std::unique_lock<std::mutex> lock(shared->mutex);
            shared->ready[k] = std::move(images);
            partial.erase(k);
            shared->changed.notify_all();
            // Waits while the job has its next frame and enough after it.
            shared->changed.wait(lock, [&] {
              return shared->stop || shared->ready.size() < kFramesAhead ||
                     !shared->ready.count(shared->wanted);
            });
            return !shared->stop && remaining > 0;
          });
    } catch (...) {
      std::lock_guard<std::mutex> lock(shared->mutex);
      shared->error = std::current_exception();
    }
    std::lock_guard<std::mutex> lock(shared->mutex);
    shared->finished = true;
    shared->changed.notify_all();
  });
}

std::vector<cv::Mat> RecordingFrameReader::Load(int k) {
  OMNIRIG_CHECK(k >= 0 && k < static_cast<int>(frames_.frames.size()),
                "frame " << k << " of " << frames_.frames.size());
  if (!shared_ || k < next_) {
    Stop();
    Start(k);
  }
  std::unique_lock<std::mutex> lock(shared_->mutex);
  shared_->wanted = k;
  // Frames before k are not needed any more.
  shared_->ready.erase(shared_->ready.begin(), shared_->ready.lower_bound(k));
  shared_->changed.notify_all();
  shared_->changed.wait(lock, [&] { return shared_->ready.count(k) || shared_->finished; });
  if (!shared_->ready.count(k)) {
    if (shared_->error) std::rethrow_exception(shared_->error);
    throw InvalidArgument(source_->name() + ": frame " + frames_.frames[k].name +
                          " was not found on a second reading of the recording");
  }
  std::vector<cv::Mat> images = std::move(shared_->ready[k]);
  shared_->ready.erase(k);
  shared_->wanted = k + 1;
  next_ = k + 1;
  shared_->changed.notify_all();
  return images;
}

}  // namespace omnirig::io
