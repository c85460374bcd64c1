// The live job's loop (api/live_slam.h) fed as the server feeds it, without HTTP: frames put in
// the mailbox as their storing starts, the storing's outcome told through LiveFrame::stored.
// A frame whose storing failed is not tracked, and the job goes on with the next one at the
// index the dropped frame would have had. The server's side (the request answered with the
// storing's error) is tested through the server (tests/live_faults_test.cc).

#include "api/live_slam.h"

#include <filesystem>
#include <fstream>
#include <future>
#include <stdexcept>
#include <thread>
#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "engine/slam/video_source.h"
#include "testing/slam/sequence_accuracy.h"

namespace omnirig::api {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

class TempFolder {
 public:
  TempFolder() {
    std::string pattern = (fs::temp_directory_path() / "omnirig-live-slam-XXXXXX").string();
    if (!::mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~TempFolder() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

std::string Png(const cv::Mat& image) {
  std::vector<uchar> bytes;
  cv::imencode(".png", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

TEST(RunLiveSlam, AFrameThatWasNotStoredIsNotTrackedAndTheJobGoesOn) {
  constexpr int kFrames = 5, kNotStored = 2;
  const synth::StereoSequence sequence =
      synth::MakeStereoSequence(slam::ShortSequenceOptions(kFrames));
  TempFolder folder;
  JobContext context;
  context.dataset_dir = folder.path() / "dataset";
  context.output_dir = folder.path() / "output";
  context.num_threads = 2;  // the pipeline: a frame's front end beside the back end before it
  fs::create_directories(context.output_dir);
  LiveMailbox mailbox;
  std::promise<json> result;
  std::thread job([&] {
    try {
      result.set_value(RunLiveSlam({{"live", true}, {"rig", "rig-job"}}, context, sequence.rig,
                                   mailbox, {}));
    } catch (...) {
      result.set_exception(std::current_exception());
    }
    // As the server does when a run ends: a frame still waiting, or put later, is refused.
    mailbox.Close({409, {{"error", {{"code", "job_finished"}}}}});
  });

  std::vector<LiveAnswer> answers;
  for (int i = 0; i < kFrames; ++i) {
    auto frame = std::make_shared<LiveFrame>();
    frame->stamp_s = 0.1 * i;
    frame->name = slam::FrameName(frame->stamp_s) + ".png";
    for (int c = 0; c < 2; ++c) frame->encoded[c] = Png(sequence.images[c][i]);
    std::promise<void> stored;
    frame->stored = stored.get_future().share();
    std::future<LiveAnswer> answer = frame->answer.get_future();
    if (!mailbox.Put(frame)) {
      job.join();
      std::string why;
      try {
        why = result.get_future().get().dump();
      } catch (const std::exception& e) {
        why = e.what();
      }
      FAIL() << "the job ended before frame " << i << ": " << why;
    }
    // The files, as the server writes them while the job has the frame.
    if (i == kNotStored) {
      stored.set_exception(std::make_exception_ptr(std::runtime_error("the disk is full")));
    } else {
      for (int c = 0; c < 2; ++c) {
        const fs::path path = context.dataset_dir / ("cam" + std::to_string(c)) / frame->name;
        fs::create_directories(path.parent_path());
        std::ofstream(path, std::ios::binary) << frame->encoded[c];
      }
      stored.set_value();
    }
    answers.push_back(answer.get());  // one frame at a time: none is skipped
  }
  mailbox.RequestFinish();
  job.join();
  const json report = result.get_future().get();

  for (int i = 0, index = 0; i < kFrames; ++i) {
    const LiveAnswer& answer = answers[i];
    if (i == kNotStored) {
      EXPECT_EQ(answer.status, 409) << answer.body.dump();
      EXPECT_EQ(answer.body["error"]["code"], "frame_not_stored") << answer.body.dump();
      continue;
    }
    ASSERT_EQ(answer.status, 200) << i << ": " << answer.body.dump();
    EXPECT_EQ(answer.body["frame_index"], index++) << answer.body.dump();
    EXPECT_NE(answer.body["state"], "lost") << answer.body.dump();
    EXPECT_TRUE(answer.body["world_from_rig"].is_object()) << answer.body.dump();
  }
  EXPECT_EQ(report["num_frames"], kFrames - 1) << report.dump();
  EXPECT_EQ(report["num_tracked"], kFrames - 1) << report.dump();
  EXPECT_EQ(report["live"]["num_tracked_frames"], kFrames - 1);
  EXPECT_EQ(report["live"]["num_received"], kFrames);
  EXPECT_EQ(report["live"]["num_skipped"], 0);
}

}  // namespace
}  // namespace omnirig::api
