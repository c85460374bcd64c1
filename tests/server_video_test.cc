// Videos through the real service: resumable uploads (PUT with Content-Range) over a
// real HTTP server, each bad video refused at POST /api/v1/jobs with the reason, and a slam job
// on a rendered video pair whose trajectory lands near the ground truth. Small renders, few
// frames: label integration, but light.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <fstream>
#include <map>
#include <optional>
#include <random>
#include <sstream>
#include <thread>

#include <opencv2/videoio.hpp>

#include "api/camera_json.h"
#include "api/job_types.h"
#include "api/synth_json.h"
#include "engine/slam/map_io.h"
#include "engine/synth/presets.h"
#include "server/service.h"
#include "storage/sha256.h"
#include "testing/geometry/test_rig.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr int64_t kChunk = 64 << 10;  // the server's max_chunk_bytes in these tests

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

// A lossless (FFV1) video of noise, which does not compress: ~9 KiB per 64x48 frame.
std::string NoiseVideo(const fs::path& path, int frames, double fps, int width = 64,
                       int height = 48) {
  cv::VideoWriter writer(path.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('F', 'F', 'V', '1'),
                         fps, cv::Size(width, height));
  EXPECT_TRUE(writer.isOpened());
  cv::RNG rng(7);
  for (int i = 0; i < frames; ++i) {
    cv::Mat frame(height, width, CV_8UC3);
    rng.fill(frame, cv::RNG::UNIFORM, 0, 256);
    writer.write(frame);
  }
  writer.release();
  return ReadFile(path);
}

std::string ContentRange(int64_t first, int64_t last, int64_t total) {
  return "bytes " + std::to_string(first) + "-" + std::to_string(last) + "/" +
         std::to_string(total);
}

class ServerVideoTest : public ::testing::Test {
 protected:
  httplib::Client& Start() {
    server::ServiceOptions options;
    options.host = "127.0.0.1";
    options.port = 0;
    options.data_dir = dir_.path() / "data";
    options.workers.num_workers = 2;
    options.workers.threads_per_job = 1;
    options.http_threads = 16;
    options.min_free_bytes = 0;
    options.max_chunk_bytes = kChunk;
    service_ = std::make_unique<server::Service>(options);
    port_ = service_->Start();
    client_ = MakeClient(port_);
    return *client_;
  }

  std::string CreateDataset() {
    const auto result =
        client_->Post("/api/v1/datasets", json{{"name", "video"}}.dump(), "application/json");
    EXPECT_EQ(result->status, 201);
    return JsonOf(result)["id"];
  }

  // PUT of bytes [first, first + size) of `file` with its Content-Range.
  httplib::Result PutChunk(const std::string& dataset, const std::string& name,
                           const std::string& file, int64_t first, int64_t size) {
    httplib::Headers headers = {{"Content-Range", ContentRange(first, first + size - 1,
                                                               static_cast<int64_t>(file.size()))}};
    return client_->Put(("/api/v1/datasets/" + dataset + "/images/" + name).c_str(), headers,
                        file.substr(first, size), "application/octet-stream");
  }

  // Uploads `file` in chunks from `first` on; returns the last answer.
  httplib::Result UploadFrom(const std::string& dataset, const std::string& name,
                             const std::string& file, int64_t first) {
    const int64_t total = static_cast<int64_t>(file.size());
    for (int64_t at = first;;) {
      const int64_t size = std::min(kChunk, total - at);
      httplib::Result result = PutChunk(dataset, name, file, at, size);
      at += size;
      if (at >= total || !result || result->status != 202) return result;
    }
  }

  json UploadStatus(const std::string& dataset, const std::string& name) {
    const auto result = client_->Get(("/api/v1/datasets/" + dataset + "/uploads/" + name).c_str());
    EXPECT_EQ(result->status, 200) << result->body;
    EXPECT_EQ(result->get_header_value("Upload-Offset"),
              std::to_string(JsonOf(result)["received_bytes"].get<int64_t>()));
    return JsonOf(result);
  }

  TempDir dir_;
  std::unique_ptr<server::Service> service_;
  std::unique_ptr<httplib::Client> client_;
  int port_ = 0;
};

void ExpectError(const httplib::Result& result, int status, const std::string& code,
                 const std::string& message_part = "") {
  ASSERT_TRUE(result) << httplib::to_string(result.error());
  EXPECT_EQ(result->status, status) << result->body;
  const json body = json::parse(result->body, nullptr, false);
  ASSERT_TRUE(body.is_object() && body.contains("error")) << result->body;
  EXPECT_EQ(body["error"]["code"], code) << result->body;
  EXPECT_NE(body["error"]["message"].get<std::string>().find(message_part), std::string::npos)
      << result->body;
}

// Sends the headers of a chunk and part of its body, then drops the connection.
void SendHalfAChunk(int port, const std::string& path, const std::string& range,
                    const std::string& body, size_t declared) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);
  const std::string request = "PUT " + path + " HTTP/1.1\r\nHost: x\r\nContent-Range: " + range +
                              "\r\nContent-Length: " + std::to_string(declared) + "\r\n\r\n" + body;
  ASSERT_EQ(::send(fd, request.data(), request.size(), MSG_NOSIGNAL),
            static_cast<ssize_t>(request.size()));
  ::close(fd);
}

TEST_F(ServerVideoTest, ResumableUploadProtocol) {
  Start();
  const std::string dataset = CreateDataset();
  const std::string video = NoiseVideo(dir_.path() / "noise.mkv", 30, 10.0);
  ASSERT_GT(video.size(), 4u * kChunk);
  const int64_t total = static_cast<int64_t>(video.size());
  const std::string url = "/api/v1/datasets/" + dataset + "/images/cam0.mkv";

  // Readers during the whole upload see no file, or the whole file: never a half one.
  std::atomic<bool> done{false};
  std::atomic<int> reads{0}, half_files{0};
  std::thread reader([&] {
    auto client = MakeClient(port_);
    while (!done) {
      const auto got = client->Get(url.c_str());
      if (got && got->status == 200 && got->body != video) ++half_files;
      const auto listing = client->Get(("/api/v1/datasets/" + dataset).c_str());
      if (listing && listing->status == 200 && JsonOf(listing)["video_count"] == 1 &&
          !(got && got->status == 200)) {
        // Listed after the GET missed it: fine only if the file is whole now.
        const auto again = client->Get(url.c_str());
        if (!again || again->body != video) ++half_files;
      }
      ++reads;
    }
  });

  auto first = PutChunk(dataset, "cam0.mkv", video, 0, kChunk);
  ASSERT_EQ(first->status, 202) << first->body;
  EXPECT_EQ(first->get_header_value("Upload-Offset"), std::to_string(kChunk));
  EXPECT_EQ(JsonOf(first)["received_bytes"], kChunk);
  EXPECT_EQ(JsonOf(first)["total_bytes"], total);
  EXPECT_EQ(client_->Get(url.c_str())->status, 404);  // not visible while incomplete

  // A chunk at the wrong offset: 409 with what the server has.
  const auto wrong = PutChunk(dataset, "cam0.mkv", video, 2 * kChunk, kChunk);
  ExpectError(wrong, 409, "upload_offset_mismatch", "send the chunk that starts at 65536");
  EXPECT_EQ(wrong->get_header_value("Upload-Offset"), std::to_string(kChunk));
  EXPECT_EQ(JsonOf(wrong)["error"]["details"]["received_bytes"], kChunk);
  // A chunk over the server's limit: 413 with the limit.
  const auto big = PutChunk(dataset, "cam0.mkv", video, kChunk, kChunk + 1);
  ExpectError(big, 413, "payload_too_large", "send the file in smaller chunks");
  EXPECT_EQ(JsonOf(big)["error"]["details"]["limit_bytes"], kChunk);
  // Content-Length and Content-Range disagree; a malformed range.
  ExpectError(
      client_->Put(url.c_str(), {{"Content-Range", ContentRange(kChunk, kChunk + 9, total)}},
                   std::string(5, 'x'), "application/octet-stream"),
      400, "invalid_argument", "Content-Length");
  ExpectError(client_->Put(url.c_str(), {{"Content-Range", "bytes 0-9/*"}}, std::string(10, 'x'),
                           "application/octet-stream"),
              400, "invalid_argument", "Content-Range");

  // A connection dropped in the middle of a chunk: the server keeps what arrived.
  SendHalfAChunk(port_, url, ContentRange(kChunk, 2 * kChunk - 1, total),
                 video.substr(kChunk, 30000), kChunk);
  json status;
  for (int i = 0; i < 500; ++i) {  // the dropped request ends on the server's side meanwhile
    status = UploadStatus(dataset, "cam0.mkv");
    if (status["received_bytes"] == kChunk + 30000) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(status["received_bytes"], kChunk + 30000) << status.dump();
  EXPECT_TRUE(status["stored"].is_null());

  // A restart (a crash alike: the part is outside the images folder) keeps the part, and still
  // shows no file.
  done = true;
  reader.join();
  service_.reset();
  Start();
  EXPECT_EQ(UploadStatus(dataset, "cam0.mkv")["received_bytes"], kChunk + 30000);
  EXPECT_EQ(client_->Get(url.c_str())->status, 404);
  done = false;
  std::thread second_reader([&] {
    auto client = MakeClient(port_);
    while (!done) {
      const auto got = client->Get(url.c_str());
      if (got && got->status == 200 && got->body != video) ++half_files;
      ++reads;
    }
  });

  // Resume from the server's offset (a request still holding the part would get upload_busy).
  std::optional<httplib::Result> last;
  for (int i = 0; i < 500; ++i) {
    last.emplace(UploadFrom(dataset, "cam0.mkv", video, kChunk + 30000));
    if (!(*last && (*last)->status == 409)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(*last);
  ASSERT_EQ((*last)->status, 201) << (*last)->body;
  EXPECT_EQ(JsonOf(*last)["sha256"], storage::Sha256Hex(video));
  EXPECT_EQ(JsonOf(*last)["content_type"], "video/x-matroska");
  done = true;
  second_reader.join();
  EXPECT_GT(reads.load(), 0);
  EXPECT_EQ(half_files.load(), 0);
  EXPECT_EQ(client_->Get(url.c_str())->body, video);
  status = UploadStatus(dataset, "cam0.mkv");
  EXPECT_EQ(status["received_bytes"], 0);
  EXPECT_EQ(status["stored"]["size"], total);

  // A plain PUT still works, and the counts keep images and videos apart.
  const auto png = client_->Put(("/api/v1/datasets/" + dataset + "/images/a.png").c_str(),
                                PngBytes(64, 48), "image/png");
  EXPECT_EQ(png->status, 201) << png->body;
  const json listed = JsonOf(client_->Get(("/api/v1/datasets/" + dataset).c_str()));
  EXPECT_EQ(listed["image_count"], 1);
  EXPECT_EQ(listed["video_count"], 1);

  // A video cut short, sent in chunks: refused whole when its last byte arrives (the MP4's
  // 'moov' box declares more than the file holds), and nothing is left of it.
  const auto box = [](const std::string& type, uint32_t declared, size_t payload) {
    const std::string size = {static_cast<char>(declared >> 24), static_cast<char>(declared >> 16),
                              static_cast<char>(declared >> 8), static_cast<char>(declared)};
    return size + type + std::string(payload, 'b');
  };
  const std::string cut = box("ftyp", 16, 8) + box("mdat", 8 + (2 << 16), 2 << 16) +
                          box("moov", 16384, 100);  // the index declares more than was sent
  const auto refused = UploadFrom(dataset, "cam1.mp4", cut, 0);
  ExpectError(refused, 422, "corrupt_video", "incomplete");
  EXPECT_EQ(client_->Get(("/api/v1/datasets/" + dataset + "/images/cam1.mp4").c_str())->status,
            404);
  EXPECT_EQ(UploadStatus(dataset, "cam1.mp4")["received_bytes"], 0);
  // Not a video at all, by a plain PUT: 415.
  ExpectError(client_->Put(("/api/v1/datasets/" + dataset + "/images/x.avi").c_str(),
                           std::string(100, 'z'), "video/x-msvideo"),
              415, "unsupported_media_type", "not a video container");
  // Discarding an upload in progress.
  ASSERT_EQ(PutChunk(dataset, "cam2.mkv", video, 0, kChunk)->status, 202);
  EXPECT_EQ(client_->Delete(("/api/v1/datasets/" + dataset + "/uploads/cam2.mkv").c_str())->status,
            204);
  EXPECT_EQ(UploadStatus(dataset, "cam2.mkv")["received_bytes"], 0);
}

// A rendered sequence written as cam0.mp4 and cam1.mp4 (mp4v, lossy), uploaded in chunks, runs
// as a slam job: frames named by the containers' timestamps, the trajectory near the ground
// truth at the bound the image test holds (api/slam_job_test.cc), frame_step and a time range.
TEST_F(ServerVideoTest, SlamJobOnAVideoPair) {
  synth::StereoSequenceOptions options;
  options.num_frames = 12;
  options.path_length_m = 1.65;
  options.width = 640;
  options.height = 480;
  options.render.noise_sigma = 1.0;
  options.render.num_threads = 2;
  const synth::StereoSequence sequence = synth::MakeStereoSequence(options);
  const fs::path rendered = dir_.path() / "rendered";
  api::WriteStereoSequenceVideos(sequence, "room", rendered.string(), "mp4", false);

  auto& client = Start();
  const std::string dataset = CreateDataset();
  for (const char* name : {"cam0.mp4", "cam1.mp4", "trajectory.tum"}) {
    const std::string bytes = ReadFile(rendered / name);
    const auto stored = UploadFrom(dataset, name, bytes, 0);
    ASSERT_TRUE(stored);
    ASSERT_EQ(stored->status, 201) << name << ": " << stored->body;
  }
  const std::string rig = SubmitFakeRelativePose(service_->state().job_types, client, port_,
                                                 dataset, api::RigToJson(sequence.rig));
  const auto run = [&](const json& extra) {
    json params = {{"rig", rig}, {"ground_truth", "trajectory.tum"}};
    params.update(extra);
    const auto created = client.Post(
        "/api/v1/jobs", json{{"type", "slam"}, {"dataset", dataset}, {"params", params}}.dump(),
        "application/json");
    EXPECT_EQ(created->status, 202) << created->body;
    const std::string id = JsonOf(created)["id"];
    const json job = WaitForJob(port_, id, 240);
    EXPECT_EQ(job["state"], "succeeded") << job.dump();
    return std::make_pair(id, JsonOf(client.Get(("/api/v1/jobs/" + id + "/result").c_str())));
  };

  const auto [id, result] = run(json::object());
  ASSERT_EQ(result["num_frames"], 12) << result.dump();
  EXPECT_EQ(result["num_tracked"], 12);
  EXPECT_EQ(result["frames"][3]["name"], "t000000.300");
  EXPECT_LT(result["evaluation"]["ate_rmse_m"].get<double>(), 0.02) << result["evaluation"];
  EXPECT_LT(result["evaluation"]["final_drift_percent"].get<double>(), 3.0);
  const std::string tum =
      client.Get(("/api/v1/jobs/" + id + "/artifacts/trajectory.tum").c_str())->body;
  std::ofstream(dir_.path() / "estimate.tum") << tum;
  const auto poses = slam::ReadTum(dir_.path() / "estimate.tum");
  ASSERT_EQ(poses.size(), 12u);
  EXPECT_NEAR(poses[7].timestamp_s, 0.7, 1e-6);  // the container's time, not an index
  EXPECT_EQ(result["input"]["kind"], "video_pair");
  EXPECT_EQ(result["input"]["codec"], "mp4v");
  EXPECT_EQ(result["input"]["frame_count"], 12);

  // Every second frame of [0.2, 0.9] s: 0.2, 0.4, 0.6, 0.8.
  const auto [step_id, stepped] = run({{"frame_step", 2}, {"start_s", 0.2}, {"end_s", 0.9}});
  ASSERT_EQ(stepped["num_frames"], 4) << stepped.dump();
  EXPECT_EQ(stepped["frames"][0]["name"], "t000000.200");
  EXPECT_EQ(stepped["frames"][3]["name"], "t000000.800");
  EXPECT_EQ(stepped["evaluation"]["num_poses"], 4);
}

// Each bad recording is refused at submission (422, the reason), before any job is queued.
TEST_F(ServerVideoTest, BadVideosAreRefusedAtSubmission) {
  auto& client = Start();
  const std::string rig_job =
      SubmitFakeRelativePose(service_->state().job_types, client, port_, CreateDataset(),
                             api::RigToJson(TinyTestRig(64, 48)));
  const auto submit = [&](const std::map<std::string, std::string>& files,
                          const json& extra = json::object()) {
    const std::string dataset = CreateDataset();
    for (const auto& [name, bytes] : files) {
      const auto stored = client.Put(("/api/v1/datasets/" + dataset + "/images/" + name).c_str(),
                                     bytes, "application/octet-stream");
      EXPECT_EQ(stored->status, 201) << name << ": " << stored->body;
    }
    json params = {{"rig", rig_job}};
    params.update(extra);
    return client.Post("/api/v1/jobs",
                       json{{"type", "slam"}, {"dataset", dataset}, {"params", params}}.dump(),
                       "application/json");
  };
  const std::string twelve = NoiseVideo(dir_.path() / "a.mkv", 12, 10.0);
  const std::string eight = NoiseVideo(dir_.path() / "b.mkv", 8, 10.0);
  const std::string fast = NoiseVideo(dir_.path() / "c.mkv", 12, 20.0);
  const std::string large = NoiseVideo(dir_.path() / "d.mkv", 12, 10.0, 80, 48);
  // A file whose container is whole but whose content no decoder reads.
  const auto box = [](const std::string& type, const std::string& payload) {
    const uint32_t size = static_cast<uint32_t>(8 + payload.size());
    return std::string{static_cast<char>(size >> 24), static_cast<char>(size >> 16),
                       static_cast<char>(size >> 8), static_cast<char>(size)} +
           type + payload;
  };
  const std::string undecodable =
      box("ftyp", "isom\0\0\0\0") + box("moov", std::string(64, 'q')) + box("mdat", "zz");

  ExpectError(submit({{"cam0.mkv", twelve}, {"cam1.mkv", eight}}), 422, "invalid_input",
              "different frame counts (12 and 8)");
  ExpectError(submit({{"cam0.mkv", twelve}, {"cam1.mkv", fast}}), 422, "invalid_input",
              "different frame rates");
  ExpectError(submit({{"cam0.mkv", twelve}, {"cam1.mp4", undecodable}}), 422, "invalid_input",
              "cam1.mp4 cannot be opened as a video");
  ExpectError(submit({{"cam0.mkv", large}, {"cam1.mkv", large}}), 422, "invalid_input",
              "cam0.mkv's frames are 80x48 but the rig's cam0 is calibrated for 64x48");
  ExpectError(submit({{"cam0.mkv", twelve}}), 422, "invalid_input", "has no partner");
  ExpectError(submit({{"cam0.mkv", twelve}, {"cam1.mkv", twelve}, {"stacked.mkv", twelve}}), 422,
              "invalid_input", "both a video pair and a stacked video");
  ExpectError(submit({{"cam0/a.png", PngBytes(64, 48)}, {"cam1/a.png", PngBytes(64, 48)}},
                     {{"start_s", 1.0}}),
              422, "invalid_input", "holds none");
  ExpectError(submit({{"cam0.mkv", twelve}, {"cam1.mkv", twelve}}, {{"frame_step", 0}}), 400,
              "invalid_params", "frame_step");
  // The good pair passes (it would run; it is noise, so it is canceled).
  const auto accepted = submit({{"cam0.mkv", twelve}, {"cam1.mkv", twelve}});
  ASSERT_EQ(accepted->status, 202) << accepted->body;
  const std::string id = JsonOf(accepted)["id"];
  client.Post(("/api/v1/jobs/" + id + "/cancel").c_str(), "", "application/json");
  EXPECT_NE(WaitForJob(port_, id, 60)["state"], "succeeded");
}

}  // namespace
}  // namespace omnirig::testing
