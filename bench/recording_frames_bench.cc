// Stereo frames decoded from a recording as a slam job reads them (engine/io/recording_frames.h
// through the service's storage reader), against the same frames read from PNG files as a slam
// job on an image folder reads them (cv::imread of cam0/ and cam1/), in the same process.
// Target: decoding from a recording adds at most 5 ms per stereo frame to slam.
//
//   bench_recording_frames [--dir DIR] [--size-mb 128] [--work-ms 60]
//
// Without --dir the bags are written first (testing/recordings/write_bench_recordings.py,
// python3-rosbag): /cam0/image_raw and /cam1/image_raw, 1280x1024 mono8 at 20 Hz, uncompressed
// and lz4. Figures per stereo frame:
//   stamps    the pass that reads every header stamp and pairs the topics (before frame 0)
//   decode    Load(k) back to back, the job doing nothing else: the whole cost of a frame
//   added     the time Load(k) blocks when the job works --work-ms per frame between loads (a
//             busy loop, as tracking is): what decoding adds to slam
//   png       the same frames from PNG files, cam0's then cam1's (slam on an image folder)

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "engine/io/recording_frames.h"
#include "server/dataset_recordings.h"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Keeps a core busy for `seconds`, as the job's own work would.
void Work(double seconds) {
  const auto start = Clock::now();
  volatile uint64_t x = 0;
  while (SecondsSince(start) < seconds) x = x + 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string dir;
  int size_mb = 128;
  double work_ms = 60;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--dir") dir = argv[i + 1];
    if (flag == "--size-mb") size_mb = std::atoi(argv[i + 1]);
    if (flag == "--work-ms") work_ms = std::atof(argv[i + 1]);
  }
  bool remove = false;
  if (dir.empty()) {
    dir = (fs::temp_directory_path() / ("omnirig-frames-bench-" + std::to_string(::getpid())))
              .string();
    const std::string command = "/usr/bin/python3 " + std::string(OMNIRIG_SOURCE_DIR) +
                                "/testing/recordings/write_bench_recordings.py " + dir + " " +
                                std::to_string(size_mb);
    std::fprintf(stderr, "writing the recordings: %s\n", command.c_str());
    if (std::system(command.c_str()) != 0) return 1;
    remove = true;
  }
  const std::vector<std::string> topics = {"/cam0/image_raw", "/cam1/image_raw"};
  std::printf("%-15s %7s %10s %10s %10s %10s  (ms per stereo frame, --work-ms %.0f)\n",
              "recording", "frames", "stamps", "decode", "added", "png", work_ms);
  for (const std::string name : {"bench_none.bag", "bench_lz4.bag"}) {
    if (!fs::exists(fs::path(dir) / name)) continue;
    const auto source = omnirig::server::OpenDatasetRecording(dir, {name}, name);
    auto start = Clock::now();
    omnirig::io::RecordingFrames frames =
        omnirig::io::SelectRecordingFrames(*source, topics, omnirig::io::RecordingFrameOptions());
    const double n = static_cast<double>(frames.frames.size());
    const double stamps_s = SecondsSince(start);
    // decode: back to back.
    std::vector<std::vector<cv::Mat>> first_frames;
    {
      omnirig::io::RecordingFrameReader reader(source, frames);
      start = Clock::now();
      for (int k = 0; k < static_cast<int>(n); ++k) {
        std::vector<cv::Mat> images = reader.Load(k);
        if (k < 20) first_frames.push_back(images);
      }
    }
    const double decode_s = SecondsSince(start);
    // added: the job works between loads.
    double blocked_s = 0;
    {
      omnirig::io::RecordingFrameReader reader(source, frames);
      for (int k = 0; k < static_cast<int>(n); ++k) {
        const auto load_start = Clock::now();
        reader.Load(k);
        blocked_s += SecondsSince(load_start);
        Work(work_ms * 1e-3);
      }
    }
    // png: the first 20 frames as files.
    const fs::path png_dir = fs::path(dir) / "png";
    fs::create_directories(png_dir);
    for (size_t k = 0; k < first_frames.size(); ++k) {
      for (int c = 0; c < 2; ++c) {
        cv::imwrite((png_dir / ("cam" + std::to_string(c) + "_" + std::to_string(k) + ".png")).string(),
                    first_frames[k][c]);
      }
    }
    start = Clock::now();
    for (size_t k = 0; k < first_frames.size(); ++k) {
      for (int c = 0; c < 2; ++c) {
        cv::imread((png_dir / ("cam" + std::to_string(c) + "_" + std::to_string(k) + ".png")).string(),
                   cv::IMREAD_COLOR);
      }
    }
    const double png_s = SecondsSince(start) / first_frames.size();
    fs::remove_all(png_dir);
    std::printf("%-15s %7.0f %10.2f %10.2f %10.2f %10.2f\n", name.c_str(), n, 1e3 * stamps_s / n,
                1e3 * decode_s / n, 1e3 * blocked_s / n, 1e3 * png_s);
  }
  if (remove) fs::remove_all(dir);
  return 0;
}
