#include "engine/slam/video_source.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "engine/util/check.h"
#include "engine/util/image_pairs.h"
#include "engine/util/option_check.h"

namespace omnirig::slam {
namespace {

namespace fs = std::filesystem;

std::string FileName(const fs::path& path) { return path.filename().string(); }

// A property as an integer, 0 when the back-end reports none (negative, NaN or out of range).
int64_t IntegerProperty(const cv::VideoCapture& capture, int property) {
  const double value = capture.get(property);
  return std::isfinite(value) && value > 0 && value < 9e15 ? static_cast<int64_t>(value) : 0;
}

std::string FourCc(int64_t value) {
  const auto code = static_cast<uint32_t>(value);
  std::string text;
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((code >> (8 * i)) & 0xFF);
    text += (c >= 32 && c < 127) ? c : '?';
  }
  return code == 0 ? "" : text;
}

cv::VideoCapture Open(const fs::path& path) {
  cv::VideoCapture capture;
  // FFmpeg only: the other back-ends (GStreamer, images) read other things under a file name.
  capture.open(path.string(), cv::CAP_FFMPEG);
  OMNIRIG_CHECK(capture.isOpened(),
                FileName(path) << " cannot be opened as a video (OpenCV's FFmpeg back-end does "
                                  "not read its container or codec, or the file is damaged)");
  return capture;
}

// cam0's and cam1's timestamps up to `last_s` (inclusive), in seconds, read by grabbing every
// frame. Throws when a file yields no frame or its timestamps go backwards.
std::vector<double> ReadTimestamps(const fs::path& path, double last_s, int64_t expected_frames,
                                   const ProgressSink& progress, double progress_begin,
                                   double progress_end) {
  cv::VideoCapture capture = Open(path);
  std::vector<double> stamps;
  bool decoded_any = false;
  while (capture.grab()) {
    decoded_any = true;
    const double t = capture.get(cv::CAP_PROP_POS_MSEC) / 1000.0;
    if (t > last_s) break;
    OMNIRIG_CHECK(stamps.empty() || t > stamps.back(),
                  FileName(path) << ": the timestamps go backwards or repeat at frame "
                                 << stamps.size() << " (" << t << " s after " << stamps.back()
                                 << " s)");
    stamps.push_back(t);
    if (stamps.size() % 64 == 0) {
      progress.ThrowIfCancelled();
      const double done = expected_frames > 0
                              ? std::min(1.0, static_cast<double>(stamps.size()) / expected_frames)
                              : 0.0;
      progress.Report(progress_begin + (progress_end - progress_begin) * done, "timestamps",
                      FileName(path) + ": " + std::to_string(stamps.size()) + " frames");
    }
  }
  OMNIRIG_CHECK(decoded_any, FileName(path)
                                 << ": no frame could be decoded (codec "
                                 << FourCc(IntegerProperty(capture, cv::CAP_PROP_FOURCC)) << ")");
  return stamps;
}

}  // namespace

std::string FrameName(double timestamp_s) { return omnirig::FrameName(timestamp_s); }

VideoInfo ProbeVideo(const fs::path& path) {
  cv::VideoCapture capture = Open(path);
  VideoInfo info;
  info.width = static_cast<int>(
      std::min<int64_t>(IntegerProperty(capture, cv::CAP_PROP_FRAME_WIDTH), 1 << 20));
  info.height = static_cast<int>(
      std::min<int64_t>(IntegerProperty(capture, cv::CAP_PROP_FRAME_HEIGHT), 1 << 20));
  info.frame_count = IntegerProperty(capture, cv::CAP_PROP_FRAME_COUNT);
  info.fps = capture.get(cv::CAP_PROP_FPS);
  info.codec = FourCc(IntegerProperty(capture, cv::CAP_PROP_FOURCC));
  OMNIRIG_CHECK(info.width > 0 && info.height > 0,
                FileName(path) << " holds no video stream with a frame size");
  OMNIRIG_CHECK(info.frame_count > 0, FileName(path) << " holds no frames");
  OMNIRIG_CHECK(std::isfinite(info.fps) && info.fps > 0, FileName(path)
                                                             << " declares no frame rate");
  return info;
}

StereoVideoInfo ProbeStereoVideo(const StereoVideoFiles& files) {
  StereoVideoInfo info;
  info.video[0] = ProbeVideo(files.cam0);
  if (files.stacked()) {
    const VideoInfo& video = info.video[0];
    OMNIRIG_CHECK(video.height % 2 == 0, FileName(files.cam0)
                                             << " is " << video.width << "x" << video.height
                                             << ": a stacked video (cam0 on top of cam1) needs an "
                                                "even height");
    info.video[1] = video;
    for (int c = 0; c < 2; ++c) {
      info.width[c] = video.width;
      info.height[c] = video.height / 2;
    }
    return info;
  }
  info.video[1] = ProbeVideo(files.cam1);
  const VideoInfo& a = info.video[0];
  const VideoInfo& b = info.video[1];
  const std::string names = FileName(files.cam0) + " and " + FileName(files.cam1);
  OMNIRIG_CHECK(std::abs(a.fps - b.fps) <= 1e-3 * std::max(a.fps, b.fps),
                names << " have different frame rates (" << a.fps << " and " << b.fps
                      << " frames/s): their frames cannot be paired");
  OMNIRIG_CHECK(a.frame_count == b.frame_count, names << " have different frame counts ("
                                                      << a.frame_count << " and " << b.frame_count
                                                      << "): their frames cannot be paired");
  for (int c = 0; c < 2; ++c) {
    info.width[c] = info.video[c].width;
    info.height[c] = info.video[c].height;
  }
  return info;
}

void VideoFrameOptions::Check() const {
  OMNIRIG_CHECK_NON_NEGATIVE(pair_tolerance_s);
  OMNIRIG_CHECK_AT_LEAST(frame_step, 1);
  OMNIRIG_CHECK_NON_NEGATIVE(start_s);
  OMNIRIG_CHECK(end_s > start_s,
                "end_s (" << end_s << ") must be after start_s (" << start_s << ")");
}

std::vector<std::pair<int64_t, int64_t>> PairTimestamps(const std::vector<double>& t0_s,
                                                        const std::vector<double>& t1_s,
                                                        double tolerance_s) {
  std::vector<std::pair<int64_t, int64_t>> pairs;
  std::ostringstream unpaired;
  int num_unpaired = 0;
  const auto note = [&](int c, size_t index, double t) {
    if (num_unpaired++ < 5) unpaired << " cam" << c << " frame " << index << " at " << t << " s;";
  };
  size_t i = 0, j = 0;
  while (i < t0_s.size() && j < t1_s.size()) {
    const double d = t0_s[i] - t1_s[j];
    if (std::abs(d) <= tolerance_s) {
      pairs.emplace_back(i++, j++);
    } else if (d < 0) {
      note(0, i, t0_s[i]), ++i;
    } else {
      note(1, j, t1_s[j]), ++j;
    }
  }
  for (; i < t0_s.size(); ++i) note(0, i, t0_s[i]);
  for (; j < t1_s.size(); ++j) note(1, j, t1_s[j]);
  OMNIRIG_CHECK(num_unpaired == 0, num_unpaired << " frame(s) have no partner within "
                                                << tolerance_s * 1000
                                                << " ms in the other video:" << unpaired.str());
  return pairs;
}

std::vector<StereoVideoFrame> PairStereoVideoFrames(const StereoVideoFiles& files,
                                                    const VideoFrameOptions& options,
                                                    const ProgressSink& progress) {
  options.Check();
  const StereoVideoInfo info = ProbeStereoVideo(files);
  const double tolerance_s =
      options.pair_tolerance_s > 0 ? options.pair_tolerance_s : 0.25 / info.video[0].fps;
  const double last_s = options.end_s + tolerance_s;
  std::vector<double> stamps[2];
  stamps[0] = ReadTimestamps(files.cam0, last_s, info.video[0].frame_count, progress, 0.0,
                             files.stacked() ? 1.0 : 0.5);
  stamps[1] = files.stacked() ? stamps[0]
                              : ReadTimestamps(files.cam1, last_s, info.video[1].frame_count,
                                               progress, 0.5, 1.0);
  std::vector<StereoVideoFrame> frames;
  int64_t in_range = 0;
  for (const auto& [i, j] : PairTimestamps(stamps[0], stamps[1], tolerance_s)) {
    const double t = stamps[0][i];
    if (t < options.start_s || t > options.end_s) continue;
    if (in_range++ % options.frame_step != 0) continue;
    frames.push_back({FrameName(t), t, {i, j}});
  }
  OMNIRIG_CHECK(!frames.empty(), "no stereo frame lies in the time range ["
                                     << options.start_s << ", " << options.end_s
                                     << "] s (the videos hold " << stamps[0].front() << " to "
                                     << stamps[0].back() << " s)");
  return frames;
}

StereoVideoReader::StereoVideoReader(StereoVideoFiles files, std::vector<StereoVideoFrame> frames)
    : files_(std::move(files)), frames_(std::move(frames)) {}

cv::Mat StereoVideoReader::ReadFrame(int c, int64_t index) {
  cv::VideoCapture& capture = capture_[c];
  const fs::path& path = c == 0 ? files_.cam0 : files_.cam1;
  if (!capture.isOpened() || index < next_index_[c]) {
    capture = Open(path);
    next_index_[c] = 0;
  }
  for (; next_index_[c] < index; ++next_index_[c]) {
    OMNIRIG_CHECK(capture.grab(), FileName(path) << " ended at frame " << next_index_[c]
                                                 << ", before frame " << index);
  }
  cv::Mat image;
  OMNIRIG_CHECK(capture.grab() && capture.retrieve(image) && !image.empty(),
                FileName(path) << ": frame " << index << " cannot be decoded");
  ++next_index_[c];
  return image;
}

StereoImages StereoVideoReader::Load(int k) {
  OMNIRIG_CHECK(k >= 0 && k < static_cast<int>(frames_.size()),
                "video frame " << k << " out of range");
  const StereoVideoFrame& frame = frames_[k];
  if (files_.stacked()) {
    const cv::Mat both = ReadFrame(0, frame.index[0]);
    return StereoImages{both.rowRange(0, both.rows / 2), both.rowRange(both.rows / 2, both.rows)};
  }
  // Two videos are two decoders: each camera's frame is read on its own thread.
  return ReadBoth([&](int c) { return ReadFrame(c, frame.index[c]); });
}

}  // namespace omnirig::slam
