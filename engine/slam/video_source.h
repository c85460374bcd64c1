#pragma once
// Stereo frames from videos, for RunSlam's StereoFrameLoader: two videos (cam0's and cam1's,
// any container and codec OpenCV's FFmpeg backend reads) or one top/bottom stacked video (cam0
// on top). Frames are decoded one at a time inside the job, never all held in memory.
//
// Time is the container's: a frame's timestamp is its presentation time (CAP_PROP_POS_MSEC,
// the stream's start time subtracted), so variable frame rates and dropped frames keep their
// true times. The two videos' frames are paired by timestamp within a tolerance; a time range
// and a step select the frames SLAM sees. Each selected pair is named by its timestamp
// ("t000012.345"), so a trajectory written from the names carries the container's times.
//
// What fails, and when: ProbeStereoVideo opens the files and reads their headers only (what
// opening needs: the demuxer's stream probe), for a check before a job is queued; it refuses a
// file OpenCV cannot open, a stream without frames, and two videos of different frame counts or
// rates. PairStereoVideoFrames then reads every frame's timestamp (grab: the codec runs, no
// colour conversion) and refuses timestamps that do not pair, before the first frame is
// processed.

#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/videoio.hpp>

#include "engine/slam/slam.h"

namespace omnirig::slam {

// The video files of a stereo recording.
struct StereoVideoFiles {
  // Two files (cam0, cam1), or one stacked file in `cam0` (cam0 the top half of every frame,
  // cam1 the bottom half) with `cam1` empty.
  std::filesystem::path cam0, cam1;
  bool stacked() const { return cam1.empty(); }
};

// What opening a video tells without decoding its frames.
struct VideoInfo {
  int width = 0, height = 0;  // of the whole frame (a stacked video holds both cameras)
  int64_t frame_count = 0;    // the container's count (for some containers an estimate)
  double fps = 0;             // the container's nominal rate
  std::string codec;          // FourCC, e.g. "mp4v", "FFV1"
};

// Opens `path` with OpenCV's FFmpeg backend and reads its header. Throws InvalidArgument
// naming the file when it cannot be opened or holds no frames.
VideoInfo ProbeVideo(const std::filesystem::path& path);

struct StereoVideoInfo {
  VideoInfo video[2];     // cam0's and cam1's files (a stacked video: the same twice)
  int width[2] = {0, 0};  // per camera (a stacked video: half the height each)
  int height[2] = {0, 0};
};

// Probes both files (see above) and checks they can be paired: the same frame count and frame
// rate (relative 1e-3); a stacked video needs an even height. Throws InvalidArgument with the
// reason.
StereoVideoInfo ProbeStereoVideo(const StereoVideoFiles& files);

struct VideoFrameOptions {
  // Frames of the two videos pair when their timestamps differ by at most this; 0 picks a
  // quarter of the frame period (from the container's rate), which two videos of one clock meet
  // and neighbouring frames never do.
  double pair_tolerance_s = 0.0;
  int frame_step = 1;    // every frame_step-th pair of the time range
  double start_s = 0.0;  // the time range, container time of cam0, both ends included
  double end_s = std::numeric_limits<double>::infinity();
  void Check() const;
};

// A frame's name from its capture time: "t%010.3f", e.g. "t000012.345" (recordings' frames, as
// read from videos or stored by a live run; api's NameAsTimestamp reads it back).
std::string FrameName(double timestamp_s);

// One selected stereo frame: where it lies in each video.
struct StereoVideoFrame {
  std::string name;           // "t%010.3f" of the timestamp, e.g. "t000012.345"
  double timestamp_s = 0;     // cam0's
  int64_t index[2] = {0, 0};  // frame index in cam0's and cam1's video (stacked: equal)
};

// Pairs two sorted timestamp lists: each frame pairs with the other video's nearest frame when
// they differ by at most `tolerance_s`. Throws InvalidArgument naming the first frames (up to
// five) that do not pair. Returned as (index in t0, index in t1).
std::vector<std::pair<int64_t, int64_t>> PairTimestamps(const std::vector<double>& t0_s,
                                                        const std::vector<double>& t1_s,
                                                        double tolerance_s);

// Reads every frame's timestamp of `files` (up to options.end_s), pairs cam0's and cam1's, and
// selects the time range and step. Throws InvalidArgument: a frame that cannot be decoded,
// timestamps that do not pair, different frame counts, no frame in the range. Cancelled
// through `progress` (this reads the whole file once).
std::vector<StereoVideoFrame> PairStereoVideoFrames(const StereoVideoFiles& files,
                                                    const VideoFrameOptions& options,
                                                    const ProgressSink& progress = ProgressSink());

// Decodes the selected frames in order: Load(k) returns frames[k]'s images, 8-bit BGR. Forward
// calls skip frames by grabbing them (no colour conversion); a call for an earlier frame than
// the last reopens the files (a second pass, e.g. the dense map's keyframes). Not thread-safe;
// RunSlam calls its loader from one thread at a time.
class StereoVideoReader {
 public:
  StereoVideoReader(StereoVideoFiles files, std::vector<StereoVideoFrame> frames);
  StereoImages Load(int k);
  const std::vector<StereoVideoFrame>& frames() const { return frames_; }

 private:
  // The frame at `index` of camera c's capture, decoded.
  cv::Mat ReadFrame(int c, int64_t index);

  StereoVideoFiles files_;
  std::vector<StereoVideoFrame> frames_;
  cv::VideoCapture capture_[2];
  int64_t next_index_[2] = {0, 0};  // the index the next grab() returns
};

}  // namespace omnirig::slam
