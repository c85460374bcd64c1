// Indexing robot recordings (storage/recording.h) from a warm page cache: one pass that lists
// each topic's type, message count, first/last receive time and rate. Target: >= 500 MB/s.
// The peer, run on the same file in the same process: reading the file with read() into a
// 1 MiB buffer (what any pass over the bytes costs). Also timed: reading every message
// (decompressing chunks), which jobs do, not the index.
//
//   bench_recording_index [--dir DIR] [--size-mb 512]
//
// Without --dir the recordings are written first (testing/recordings/write_bench_recordings.py
// and write_mcap.mjs --bench: python3-rosbag, @mcap/core, rosbag2's SQLite schema), two topics
// of 1280x1024 mono8 images at 20 Hz, about SIZE_MB each, into a temporary folder.

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "storage/recording.h"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Reads the whole file with read(): the peer, and what warms the page cache.
double ReadFileS(const fs::path& path) {
  const auto start = Clock::now();
  const int fd = ::open(path.c_str(), O_RDONLY);
  std::vector<char> buffer(1 << 20);
  while (::read(fd, buffer.data(), buffer.size()) > 0) {
  }
  ::close(fd);
  return SecondsSince(start);
}

template <typename F>
double BestOf(int runs, const F& f) {
  double best = 1e300;
  for (int i = 0; i < runs; ++i) {
    const auto start = Clock::now();
    f();
    best = std::min(best, SecondsSince(start));
  }
  return best;
}

}  // namespace

int main(int argc, char** argv) {
  std::string dir;
  int size_mb = 512;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--dir") dir = argv[i + 1];
    if (flag == "--size-mb") size_mb = std::atoi(argv[i + 1]);
  }
  bool remove = false;
  if (dir.empty()) {
    dir = (fs::temp_directory_path() / ("omnirig-recording-bench-" + std::to_string(::getpid())))
              .string();
    const std::string scripts = std::string(OMNIRIG_SOURCE_DIR) + "/testing/recordings/";
    const std::string command = "/usr/bin/python3 " + scripts + "write_bench_recordings.py " + dir +
                                " " + std::to_string(size_mb) + " && node " + scripts +
                                "write_mcap.mjs " + dir + " --bench " + std::to_string(size_mb);
    std::fprintf(stderr, "writing the recordings: %s\n", command.c_str());
    if (std::system(command.c_str()) != 0) return 1;
    remove = true;
  }
  std::printf("%-18s %9s %11s %13s %7s %14s\n", "recording", "size MB", "read() MB/s",
              "index MB/s", "ratio", "messages MB/s");
  for (const std::string name :
       {"bench_none.bag", "bench_lz4.bag", "bench_lz4.mcap", "bench_zstd.mcap", "bench.db3"}) {
    const fs::path path = fs::path(dir) / name;
    if (!fs::exists(path)) continue;
    const double mb = static_cast<double>(fs::file_size(path)) / (1 << 20);
    ReadFileS(path);  // warms the page cache
    const double read_s = BestOf(3, [&] { ReadFileS(path); });
    // A lone .db3 is a part of a ROS 2 bag: checked and indexed the way an upload is.
    const auto open = [&] {
      if (name == "bench.db3") {
        omnirig::storage::CheckRecordingFile(name, path);
        return std::unique_ptr<omnirig::storage::Recording>();
      }
      return omnirig::storage::Recording::Open(path);
    };
    const double index_s = BestOf(3, [&] { open(); });
    double messages_s = 0;
    if (const auto recording = open()) {
      messages_s = BestOf(1, [&] {
        uint64_t sum = 0;
        recording->ReadMessages({}, [&](const omnirig::storage::RecordingMessage& message) {
          sum += static_cast<uint8_t>(message.data[message.data.size() / 2]);
          return true;
        });
        if (sum == 1) std::printf(" ");
      });
    }
    std::printf("%-18s %9.0f %11.0f %13.0f %7.2f %14s\n", name.c_str(), mb, mb / read_s,
                mb / index_s, read_s / index_s,
                messages_s > 0 ? std::to_string(static_cast<int>(mb / messages_s)).c_str() : "-");
  }
  if (remove) fs::remove_all(dir);
  return 0;
}
