// The REST API end to end: the real service on an ephemeral loopback port with a temporary
// data folder, driven through a real HTTP client. Covers every endpoint and the bad inputs
// the API promises to refuse. Jobs use the test-only "test_sleep" type (server_test_util.h).

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <set>
#include <thread>
#include <vector>

#include "api/camera_json.h"
#include "api/job_types.h"
#include "engine/util/check.h"
#include "server/service.h"
#include "storage/sha256.h"
#include "storage/sqlite_job_store.h"
#include "testing/geometry/test_rig.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

class ServerApiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::filesystem::create_directories(dir_.path() / "web");
    std::ofstream(dir_.path() / "web" / "index.html") << "<html>omnirig test page</html>";
  }

  server::ServiceOptions Options() const {
    server::ServiceOptions options;
    options.host = "127.0.0.1";
    options.port = 0;
    options.data_dir = dir_.path() / "data";
    options.web_dir = dir_.path() / "web";
    options.workers.num_workers = 2;
    options.workers.threads_per_job = 1;
    options.http_threads = 8;
    options.min_free_bytes = 0;
    options.workers.progress_interval_s = 0.02;
    options.extra_job_types = {SleepJobType()};
    return options;
  }

  // Starts a service with `options` (default Options()) and returns a client for it.
  httplib::Client& Start(const server::ServiceOptions& options) {
    service_ = std::make_unique<server::Service>(options);
    port_ = service_->Start();
    client_ = MakeClient(port_, options.token);
    return *client_;
  }
  httplib::Client& Start() { return Start(Options()); }

  std::string CreateDataset(httplib::Client& client, const std::string& name = "rig") {
    const auto result =
        client.Post("/api/v1/datasets", json{{"name", name}}.dump(), "application/json");
    EXPECT_EQ(result->status, 201);
    return JsonOf(result)["id"];
  }

  json SubmitSleep(httplib::Client& client, const std::string& dataset, const json& params,
                   int expected_status = 202) {
    const auto result =
        client.Post("/api/v1/jobs",
                    json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", params}}.dump(),
                    "application/json");
    EXPECT_EQ(result->status, expected_status) << result->body;
    return JsonOf(result);
  }

  TempDir dir_;
  std::unique_ptr<server::Service> service_;
  std::unique_ptr<httplib::Client> client_;
  int port_ = 0;
};

void ExpectError(const httplib::Result& result, int status, const std::string& code) {
  ASSERT_TRUE(result) << httplib::to_string(result.error());
  EXPECT_EQ(result->status, status) << result->body;
  const json body = json::parse(result->body, nullptr, false);
  ASSERT_TRUE(body.is_object()) << result->body;
  ASSERT_TRUE(body.contains("error")) << result->body;
  EXPECT_EQ(body["error"]["code"], code) << result->body;
  EXPECT_TRUE(body["error"]["message"].is_string());
  EXPECT_TRUE(body["error"]["details"].is_object());
}

// A raw TCP connection to the server, for what httplib's client cannot send: pipelined
// requests and "Expect: 100-continue".
class RawConnection {
 public:
  explicit RawConnection(int port) : fd_(::socket(AF_INET, SOCK_STREAM, 0)) {
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<uint16_t>(port));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
    const timeval timeout{5, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
  }
  ~RawConnection() { ::close(fd_); }
  bool connected() const { return connected_; }
  void Send(const std::string& bytes) {
    ASSERT_EQ(::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL),
              static_cast<ssize_t>(bytes.size()));
  }
  // Reads until `count` occurrences of `marker` arrived (or 5 s pass); returns all bytes read.
  std::string ReadUntil(const std::string& marker, int count = 1) {
    std::string received;
    char buffer[4096];
    while (Count(received, marker) < count) {
      const ssize_t got = ::recv(fd_, buffer, sizeof(buffer), 0);
      if (got <= 0) break;
      received.append(buffer, static_cast<size_t>(got));
    }
    return received;
  }
  static int Count(const std::string& text, const std::string& marker) {
    int count = 0;
    for (size_t at = text.find(marker); at != std::string::npos; at = text.find(marker, at + 1)) {
      ++count;
    }
    return count;
  }

 private:
  int fd_;
  bool connected_ = false;
};

TEST_F(ServerApiTest, KeepAliveAndExpectContinue) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  // Many requests on one keep-alive connection.
  httplib::Client keep_alive("127.0.0.1", port_);
  keep_alive.set_keep_alive(true);
  for (int i = 0; i < 50; ++i) {
    const auto health = keep_alive.Get("/api/v1/health");
    ASSERT_TRUE(health);
    ASSERT_EQ(health->status, 200);
  }
  // curl's default for large uploads: the server must send "100 Continue" before the body.
  const std::string png = PngBytes(64, 48);
  RawConnection upload(port_);
  ASSERT_TRUE(upload.connected());
  upload.Send("PUT /api/v1/datasets/" + dataset + "/images/a.png HTTP/1.1\r\nHost: x\r\n" +
              "Content-Length: " + std::to_string(png.size()) +
              "\r\nExpect: 100-continue\r\n\r\n");
  // It arrives before any of the body is sent (ReadUntil waits for it, up to 5 s).
  const std::string interim = upload.ReadUntil("\r\n\r\n");
  EXPECT_EQ(interim.rfind("HTTP/1.1 100 Continue", 0), 0u) << interim;
  upload.Send(png);
  const std::string created = upload.ReadUntil("\"sha256\"");
  EXPECT_NE(created.find("HTTP/1.1 201"), std::string::npos) << created;
  EXPECT_NE(created.find(storage::Sha256Hex(png)), std::string::npos) << created;
  // Shutdown closes an idle keep-alive connection.
  RawConnection idle(port_);
  ASSERT_TRUE(idle.connected());
  service_.reset();
  EXPECT_EQ(idle.ReadUntil("never sent"), "");
}

TEST_F(ServerApiTest, HealthMetricsAndStaticPage) {
  auto& client = Start();
  const json health = JsonOf(client.Get("/api/v1/health"));
  EXPECT_EQ(health["status"], "ok");
  EXPECT_EQ(health["integrity"], "ok");
  EXPECT_EQ(health["workers"], 2);
  const auto page = client.Get("/");
  ASSERT_EQ(page->status, 200);
  EXPECT_NE(page->body.find("omnirig test page"), std::string::npos);
  ExpectError(client.Get("/api/v1/nothing-here"), 404, "not_found");
  // Requests are counted by httplib's logger, which runs after the response has been written
  // (on another connection's thread), so poll until the earlier requests show up.
  const std::string health_line =
      "omnirig_http_requests_total{route=\"GET /api/v1/health\",status=\"200\"} 1";
  const std::string not_found_line = "route=\"unmatched\",status=\"404\"";
  httplib::Result metrics = client.Get("/metrics");
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (metrics && metrics->status == 200 &&
         (metrics->body.find(health_line) == std::string::npos ||
          metrics->body.find(not_found_line) == std::string::npos) &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    metrics = client.Get("/metrics");
  }
  ASSERT_TRUE(metrics);
  ASSERT_EQ(metrics->status, 200);
  EXPECT_NE(metrics->body.find("omnirig_jobs{state=\"queued\"} 0"), std::string::npos);
  EXPECT_NE(metrics->body.find("omnirig_queue_depth 0"), std::string::npos);
  EXPECT_NE(metrics->body.find(health_line), std::string::npos) << metrics->body;
  EXPECT_NE(metrics->body.find(not_found_line), std::string::npos) << metrics->body;
}

TEST_F(ServerApiTest, DatasetLifecycleAndIdempotentUpload) {
  auto& client = Start();
  const std::string id = CreateDataset(client);
  const std::string png = PngBytes(64, 48);
  const auto first =
      client.Put(("/api/v1/datasets/" + id + "/images/cam0/000001.png").c_str(), png, "image/png");
  ASSERT_EQ(first->status, 201) << first->body;
  const json image = JsonOf(first);
  EXPECT_EQ(image["name"], "cam0/000001.png");
  EXPECT_EQ(image["width"], 64);
  EXPECT_EQ(image["height"], 48);
  EXPECT_EQ(image["sha256"], storage::Sha256Hex(png));
  const auto again =
      client.Put(("/api/v1/datasets/" + id + "/images/cam0/000001.png").c_str(), png, "image/png");
  EXPECT_EQ(again->status, 200);
  const json dataset = JsonOf(client.Get(("/api/v1/datasets/" + id).c_str()));
  EXPECT_EQ(dataset["image_count"], 1);
  EXPECT_EQ(dataset["total_bytes"], png.size());
  ASSERT_EQ(dataset["images"].size(), 1u);
  EXPECT_EQ(dataset["images"][0]["size"], png.size());
  const auto download = client.Get(("/api/v1/datasets/" + id + "/images/cam0/000001.png").c_str());
  ASSERT_EQ(download->status, 200);
  EXPECT_EQ(download->body, png);
  EXPECT_EQ(download->get_header_value("Content-Type"), "image/png");
  const json list = JsonOf(client.Get("/api/v1/datasets"));
  ASSERT_EQ(list.size(), 1u);
  EXPECT_EQ(list[0]["id"], id);
  EXPECT_EQ(client.Delete(("/api/v1/datasets/" + id).c_str())->status, 204);
  ExpectError(client.Get(("/api/v1/datasets/" + id).c_str()), 404, "dataset_not_found");
  EXPECT_FALSE(std::filesystem::exists(dir_.path() / "data" / "datasets" / id));
}

TEST_F(ServerApiTest, ListsImagesAndRemovesOneWhenNoJobUsesTheDataset) {
  auto& client = Start();
  const std::string id = CreateDataset(client);
  const std::string base = "/api/v1/datasets/" + id + "/images";
  const std::string a = PngBytes(64, 48, 1), b = PngBytes(32, 24, 2);
  ASSERT_EQ(client.Put((base + "/cam0/a.png").c_str(), a, "image/png")->status, 201);
  ASSERT_EQ(client.Put((base + "/cam1/a.png").c_str(), b, "image/png")->status, 201);
  ASSERT_EQ(client.Put((base + "/trajectory.tum").c_str(), "1 0 0 0 0 0 0 1\n", "text/plain")
                ->status,
            201);
  const json listed = JsonOf(client.Get(base.c_str()));
  ASSERT_EQ(listed.size(), 3u) << listed.dump();
  EXPECT_EQ(listed[0]["name"], "cam0/a.png");
  EXPECT_EQ(listed[0]["camera"], "cam0");
  EXPECT_EQ(listed[0]["size"], a.size());
  EXPECT_EQ(listed[0]["width"], 64);
  EXPECT_EQ(listed[0]["height"], 48);
  EXPECT_EQ(listed[1]["camera"], "cam1");
  EXPECT_EQ(listed[2]["name"], "trajectory.tum");
  EXPECT_TRUE(listed[2]["camera"].is_null());
  EXPECT_TRUE(listed[2]["width"].is_null());
  ExpectError(client.Get("/api/v1/datasets/0000000000000000/images"), 404, "dataset_not_found");

  // While a job uses the dataset, nothing of it goes.
  const std::string job = SubmitSleep(client, id, {{"steps", 100000}, {"step_ms", 10}})["id"];
  ExpectError(client.Delete((base + "/cam1/a.png").c_str()), 409, "dataset_in_use");
  ExpectError(client.Delete((base + "/cam1/none.png").c_str()), 404, "image_not_found");
  ASSERT_EQ(client.Post(("/api/v1/jobs/" + job + "/cancel").c_str())->status / 100, 2);
  ASSERT_EQ(WaitForJob(port_, job, 20)["state"], "canceled");

  // The camera folder sent URL-encoded, as a browser's encodeURIComponent writes it.
  const auto removed = client.Delete((base + "/cam1%2Fa.png").c_str());
  ASSERT_EQ(removed->status, 204) << removed->body;
  ExpectError(client.Delete((base + "/cam1/a.png").c_str()), 404, "image_not_found");
  ExpectError(client.Get((base + "/cam1/a.png").c_str()), 404, "image_not_found");
  ExpectError(client.Delete((base + "/../x.png").c_str()), 400, "invalid_name");
  const fs::path images = dir_.path() / "data" / "datasets" / id / "images";
  EXPECT_FALSE(fs::exists(images / "cam1" / "a.png"));
  EXPECT_FALSE(fs::exists(images / "cam1"));  // the emptied camera folder
  EXPECT_TRUE(fs::exists(images / "cam0" / "a.png"));
  const json dataset = JsonOf(client.Get(("/api/v1/datasets/" + id).c_str()));
  EXPECT_EQ(dataset["image_count"], 2);
  EXPECT_EQ(dataset["total_bytes"], a.size() + 16);
  ASSERT_EQ(JsonOf(client.Get(base.c_str())).size(), 2u);
  // The name is free again.
  EXPECT_EQ(client.Put((base + "/cam1/a.png").c_str(), b, "image/png")->status, 201);
  EXPECT_EQ(client.Delete((base + "/trajectory.tum").c_str())->status, 204);
  EXPECT_EQ(JsonOf(client.Get(("/api/v1/datasets/" + id).c_str()))["image_count"], 2);
}

TEST_F(ServerApiTest, MultipartUpload) {
  auto& client = Start();
  const std::string id = CreateDataset(client);
  httplib::MultipartFormDataItems items;
  for (int i = 0; i < 3; ++i) {
    items.push_back(
        {"files", PngBytes(32, 32, i), "img" + std::to_string(i) + ".png", "image/png"});
  }
  const auto result = client.Post(("/api/v1/datasets/" + id + "/images").c_str(), items);
  ASSERT_EQ(result->status, 201) << result->body;
  EXPECT_EQ(JsonOf(result)["images"].size(), 3u);
  EXPECT_EQ(JsonOf(client.Get(("/api/v1/datasets/" + id).c_str()))["image_count"], 3);
  ExpectError(client.Post(("/api/v1/datasets/" + id + "/images").c_str(), "x", "text/plain"), 415,
              "unsupported_media_type");
}

TEST_F(ServerApiTest, RefusesBadUploads) {
  auto options = Options();
  options.max_file_bytes = 4096;
  auto& client = Start(options);
  const std::string id = CreateDataset(client);
  const std::string base = "/api/v1/datasets/" + id + "/images/";
  ExpectError(client.Put((base + "a.png").c_str(), "just some text", "image/png"), 415,
              "unsupported_media_type");
  ExpectError(client.Put((base + "b.png").c_str(), PngBytes(8, 8).substr(0, 16), "image/png"), 422,
              "corrupt_image");
  // Whole headers, cut short after them: refused with the reason, nothing stored.
  const std::string png = PngBytes(8, 8);
  const auto cut_png = client.Put((base + "c.png").c_str(), png.substr(0, png.size() - 6),
                                  "image/png");
  ExpectError(cut_png, 422, "corrupt_image");
  EXPECT_NE(cut_png->body.find("truncated"), std::string::npos) << cut_png->body;
  std::vector<uint8_t> jpeg_bytes;
  ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(8, 8, CV_8UC1, cv::Scalar(90)), jpeg_bytes));
  const std::string jpeg(jpeg_bytes.begin(), jpeg_bytes.end());
  const auto cut_jpeg = client.Put((base + "d.jpg").c_str(), jpeg.substr(0, jpeg.size() - 2),
                                   "image/jpeg");
  ExpectError(cut_jpeg, 422, "corrupt_image");
  EXPECT_NE(cut_jpeg->body.find("end-of-image"), std::string::npos) << cut_jpeg->body;
  ExpectError(client.Put((base + "e.pgm").c_str(), "P5\n8 8\n255\n" + std::string(40, 'x'),
                         "image/x-portable-graymap"),
              422, "corrupt_image");
  ExpectError(client.Put((base + "..%2F..%2Fescape.png").c_str(), PngBytes(8, 8), "image/png"), 400,
              "invalid_name");
  ExpectError(client.Put((base + ".hidden.png").c_str(), PngBytes(8, 8), "image/png"), 400,
              "invalid_name");
  ExpectError(client.Put((base + "a/b/c.png").c_str(), PngBytes(8, 8), "image/png"), 400,
              "invalid_name");
  ExpectError(client.Put((base + "big.png").c_str(), std::string(5000, 'x'), "image/png"), 413,
              "payload_too_large");
  ExpectError(client.Put("/api/v1/datasets/missing/images/a.png", PngBytes(8, 8), "image/png"), 404,
              "dataset_not_found");
  EXPECT_EQ(JsonOf(client.Get(("/api/v1/datasets/" + id).c_str()))["image_count"], 0);
  ExpectError(client.Post("/api/v1/datasets", "{\"name\": ", "application/json"), 400,
              "invalid_argument");
  ExpectError(client.Post("/api/v1/datasets", R"({"name": "a", "x": 1})", "application/json"), 400,
              "invalid_argument");
  // Nothing half-written is left behind.
  for (const auto& entry : std::filesystem::recursive_directory_iterator(dir_.path() / "data")) {
    EXPECT_EQ(entry.path().filename().string().find(".part-"), std::string::npos) << entry.path();
  }
}

TEST_F(ServerApiTest, AcceptsATumTrajectoryBesideTheImages) {
  auto& client = Start(Options());
  const std::string id = CreateDataset(client);
  const std::string base = "/api/v1/datasets/" + id + "/images/";
  const auto stored = client.Put((base + "trajectory.tum").c_str(),
                                 "# t tx ty tz qx qy qz qw\n0.0 0 0 0 0 0 0 1\n", "text/plain");
  ASSERT_TRUE(stored);
  EXPECT_EQ(stored->status, 201) << stored->body;
  EXPECT_EQ(JsonOf(stored)["content_type"], "text/plain");
  ExpectError(client.Put((base + "binary.tum").c_str(), std::string("\x89\x01\x02", 3),
                         "text/plain"),
              415, "unsupported_media_type");
  ExpectError(client.Put((base + "notes.txt").c_str(), "text", "text/plain"), 415,
              "unsupported_media_type");
}

TEST_F(ServerApiTest, ImageCountAndMultipartSizeLimits) {
  auto options = Options();
  options.max_images_per_dataset = 2;
  options.max_file_bytes = 4096;
  auto& client = Start(options);
  const std::string id = CreateDataset(client);
  const std::string base = "/api/v1/datasets/" + id + "/images/";
  EXPECT_EQ(client.Put((base + "a.png").c_str(), PngBytes(8, 8), "image/png")->status, 201);
  EXPECT_EQ(client.Put((base + "b.png").c_str(), PngBytes(8, 8), "image/png")->status, 201);
  ExpectError(client.Put((base + "c.png").c_str(), PngBytes(8, 8), "image/png"), 413,
              "payload_too_large");
  // Replacing an image the dataset already holds is still allowed at the limit.
  EXPECT_EQ(client.Put((base + "a.png").c_str(), PngBytes(8, 8, 1), "image/png")->status, 200);
  const std::string other = CreateDataset(client, "other");
  httplib::MultipartFormDataItems items = {
      {"files", std::string(8000, 'x'), "big.png", "image/png"}};
  ExpectError(client.Post(("/api/v1/datasets/" + other + "/images").c_str(), items), 413,
              "payload_too_large");
  EXPECT_EQ(JsonOf(client.Get(("/api/v1/datasets/" + other).c_str()))["image_count"], 0);
  const auto image = client.Get((base + "b.png").c_str());
  ASSERT_EQ(image->status, 200);
  EXPECT_EQ(
      client.Get((base + "b.png").c_str(), {{"If-None-Match", image->get_header_value("ETag")}})
          ->status,
      304);
}

// A multipart upload commits its files together (one transaction for the records); one that
// fails half-way keeps the files that arrived whole before the failure, names them in the
// error's details, and leaves no file without a record, no record without a file and no
// temporary file behind.
TEST_F(ServerApiTest, MultipartFailureKeepsTheFilesCompletedBeforeIt) {
  auto options = Options();
  options.max_images_per_dataset = 4;
  auto& client = Start(options);
  const std::string id = CreateDataset(client);
  const std::string url = "/api/v1/datasets/" + id + "/images";
  const auto listing = [&] {
    std::map<std::string, std::string> sha256_by_name;
    const json dataset = JsonOf(client.Get(("/api/v1/datasets/" + id).c_str()));
    for (const auto& image : dataset["images"]) sha256_by_name[image["name"]] = image["sha256"];
    return sha256_by_name;
  };
  // The third part is not an image: 415, the first two are stored, the fourth is not.
  httplib::MultipartFormDataItems items = {{"files", PngBytes(8, 8, 1), "a.png", "image/png"},
                                           {"note", "a plain form field, ignored", "", ""},
                                           {"files", PngBytes(8, 8, 2), "cam0/b.png", "image/png"},
                                           {"files", "just some text", "c.png", "image/png"},
                                           {"files", PngBytes(8, 8, 4), "d.png", "image/png"}};
  const auto failed = client.Post(url.c_str(), items);
  ExpectError(failed, 415, "unsupported_media_type");
  EXPECT_EQ(JsonOf(failed)["error"]["details"]["stored"], json::array({"a.png", "cam0/b.png"}));
  EXPECT_EQ(JsonOf(failed)["error"]["details"]["name"], "c.png");
  EXPECT_EQ(listing(), (std::map<std::string, std::string>{
                           {"a.png", storage::Sha256Hex(PngBytes(8, 8, 1))},
                           {"cam0/b.png", storage::Sha256Hex(PngBytes(8, 8, 2))}}));

  // The image limit (4): a.png is replaced (no new place), e.png and f.png fit, g.png does not.
  items = {{"files", PngBytes(8, 8, 5), "a.png", "image/png"},
           {"files", PngBytes(8, 8, 6), "e.png", "image/png"},
           {"files", PngBytes(8, 8, 7), "f.png", "image/png"},
           {"files", PngBytes(8, 8, 8), "g.png", "image/png"}};
  const auto over = client.Post(url.c_str(), items);
  ExpectError(over, 413, "payload_too_large");
  EXPECT_EQ(JsonOf(over)["error"]["details"]["stored"], json::array({"a.png", "e.png", "f.png"}));
  EXPECT_EQ(JsonOf(over)["error"]["details"]["over_limit"], json::array({"g.png"}));
  EXPECT_EQ(JsonOf(over)["error"]["details"]["limit_images"], 4);
  EXPECT_EQ(listing().size(), 4u);
  EXPECT_EQ(listing()["a.png"], storage::Sha256Hex(PngBytes(8, 8, 5)));

  // A connection dropped in the middle of the third part of another dataset's upload: the two
  // whole parts are stored, the cut one is not.
  const std::string other = CreateDataset(client, "other");
  const std::string boundary = "omnirigtestboundary";
  const auto part = [&](const std::string& name, const std::string& bytes) {
    return "--" + boundary + "\r\nContent-Disposition: form-data; name=\"files\"; filename=\"" +
           name + "\"\r\nContent-Type: image/png\r\n\r\n" + bytes + "\r\n";
  };
  const std::string whole = part("p0.png", PngBytes(16, 16, 0)) +
                            part("p1.png", PngBytes(16, 16, 1)) +
                            part("p2.png", PngBytes(16, 16, 2)) + "--" + boundary + "--\r\n";
  const size_t p2_bytes_at = whole.find("\r\n\r\n", whole.find("p2.png")) + 4;
  const size_t cut = p2_bytes_at + PngBytes(16, 16, 2).size() / 2;
  {
    RawConnection connection(port_);
    ASSERT_TRUE(connection.connected());
    connection.Send("POST /api/v1/datasets/" + other +
                    "/images HTTP/1.1\r\nHost: test\r\nContent-Type: multipart/form-data; "
                    "boundary=" +
                    boundary + "\r\nContent-Length: " + std::to_string(whole.size()) + "\r\n\r\n" +
                    whole.substr(0, cut));
  }
  // The server sees the drop when it reads on: poll the listing.
  json dataset;
  const auto start = std::chrono::steady_clock::now();
  do {
    dataset = JsonOf(client.Get(("/api/v1/datasets/" + other).c_str()));
  } while (dataset["image_count"] != 2 &&
           std::chrono::steady_clock::now() - start < std::chrono::seconds(10));
  ASSERT_EQ(dataset["image_count"], 2) << dataset.dump();
  EXPECT_EQ(dataset["images"][0]["name"], "p0.png");
  EXPECT_EQ(dataset["images"][1]["name"], "p1.png");
  // Nothing half-written is left behind, and every file has its record.
  const auto root = dir_.path() / "data" / "datasets";
  int files = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(root)) {
    EXPECT_EQ(entry.path().filename().string().find(".part-"), std::string::npos) << entry.path();
    files += entry.is_regular_file() ? 1 : 0;
  }
  EXPECT_EQ(files, 4 + 2);
}

TEST_F(ServerApiTest, ConnectionsBeyondTheCapGet503AndAreCounted) {
  auto options = Options();
  options.max_connections = 2;
  auto& client = Start(options);  // httplib's client closes its connection after each request
  const std::string health = "GET /api/v1/health HTTP/1.1\r\nHost: test\r\n\r\n";
  int refused = 0;
  {
    RawConnection first(port_), second(port_);
    first.Send(health);
    second.Send(health);
    EXPECT_EQ(first.ReadUntil("\r\n\r\n").rfind("HTTP/1.1 200", 0), 0u);
    EXPECT_EQ(second.ReadUntil("\r\n\r\n").rfind("HTTP/1.1 200", 0), 0u);
    RawConnection third(port_);
    third.Send(health);
    const std::string response = third.ReadUntil("}}");
    EXPECT_EQ(response.rfind("HTTP/1.1 503", 0), 0u) << response;
    EXPECT_NE(response.find("too many open connections (2)"), std::string::npos) << response;
    ++refused;
  }
  // Until the server has seen the two closes, the client's requests are refused too.
  int status = 0;
  std::string body;
  const auto counted = [&] {
    return body.find("omnirig_http_connections_refused_total " + std::to_string(refused) +
                     "\n") != std::string::npos;
  };
  const auto start = std::chrono::steady_clock::now();
  do {
    const auto metrics = client.Get("/metrics");
    ASSERT_TRUE(metrics);
    status = metrics->status;
    body = metrics->body;
    if (status == 503) ++refused;
  } while ((status != 200 || !counted()) &&
           std::chrono::steady_clock::now() - start < std::chrono::seconds(5));
  EXPECT_EQ(status, 200);
  EXPECT_TRUE(counted()) << "refused " << refused << "\n" << body;
}

TEST_F(ServerApiTest, RefusesUploadsWhenDiskIsShort) {
  auto options = Options();
  options.min_free_bytes = int64_t{1} << 60;
  auto& client = Start(options);
  const std::string id = CreateDataset(client);
  ExpectError(
      client.Put(("/api/v1/datasets/" + id + "/images/a.png").c_str(), PngBytes(8, 8), "image/png"),
      507, "insufficient_storage");
}

TEST_F(ServerApiTest, JobRunsAndServesResultAndArtifacts) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  client.Put(("/api/v1/datasets/" + dataset + "/images/a.png").c_str(), PngBytes(8, 8),
             "image/png");
  const json created =
      SubmitSleep(client, dataset, {{"steps", 5}, {"step_ms", 20}, {"output_kb", 64}});
  EXPECT_EQ(created["state"], "queued");
  EXPECT_EQ(created["attempts"], 0);
  const std::string id = created["id"];
  const json done = WaitForJob(port_, id, 20);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  EXPECT_EQ(done["attempts"], 1);
  EXPECT_DOUBLE_EQ(done["progress"]["fraction"].get<double>(), 1.0);
  // A succeeded job ends on "done", not on the last stage it reported ("sleep").
  EXPECT_EQ(done["progress"]["stage"], "done");
  EXPECT_TRUE(done["started_at"].is_string());
  EXPECT_TRUE(done["finished_at"].is_string());
  EXPECT_TRUE(done["error"].is_null());
  const json result = JsonOf(client.Get(("/api/v1/jobs/" + id + "/result").c_str()));
  EXPECT_EQ(result["steps"], 5);
  EXPECT_EQ(result["images"], json::array({"a.png"}));
  const json artifacts = JsonOf(client.Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
  std::set<std::string> names;
  for (const auto& artifact : artifacts) names.insert(artifact["name"]);
  EXPECT_EQ(names, (std::set<std::string>{"log.txt", "out.bin", "result.json"}));

  const std::string expected = SleepJobOutput(64);
  const std::string url = "/api/v1/jobs/" + id + "/artifacts/out.bin";
  const auto full = client.Get(url.c_str());
  ASSERT_EQ(full->status, 200);
  EXPECT_EQ(full->body, expected);
  EXPECT_EQ(full->get_header_value("Content-Length"), std::to_string(expected.size()));
  const std::string etag = full->get_header_value("ETag");
  EXPECT_EQ(etag, "\"" + storage::Sha256Hex(expected) + "\"");
  EXPECT_EQ(client.Get(url.c_str(), {{"If-None-Match", etag}})->status, 304);
  const auto part = client.Get(url.c_str(), {{"Range", "bytes=100-199"}});
  ASSERT_EQ(part->status, 206);
  EXPECT_EQ(part->body, expected.substr(100, 100));
  EXPECT_EQ(part->get_header_value("Content-Range"),
            "bytes 100-199/" + std::to_string(expected.size()));
  ExpectError(client.Get(url.c_str(), {{"Range", "bytes=999999-"}}), 416, "range_not_satisfiable");
  ExpectError(client.Get(("/api/v1/jobs/" + id + "/artifacts/none.bin").c_str()), 404,
              "artifact_not_found");
  const auto log = client.Get(("/api/v1/jobs/" + id + "/artifacts/log.txt").c_str());
  EXPECT_NE(log->body.find("slept 5 steps"), std::string::npos) << log->body;
}

// Runs a shell command; returns its stdout and stderr, and its exit status in `status`.
std::string RunCommand(const std::string& command, int* status) {
  std::string output;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  char buffer[4096];
  size_t got;
  while ((got = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, got);
  *status = ::pclose(pipe);
  return output;
}

TEST_F(ServerApiTest, ArtifactsZipHoldsEveryArtifactAsRecorded) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  client.Put(("/api/v1/datasets/" + dataset + "/images/a.png").c_str(), PngBytes(8, 8),
             "image/png");
  const std::string id = SubmitSleep(client, dataset, {{"steps", 2}, {"step_ms", 5}, {"output_kb", 700}})["id"];
  ASSERT_EQ(WaitForJob(port_, id, 20)["state"], "succeeded");
  const auto zip = client.Get(("/api/v1/jobs/" + id + "/artifacts.zip").c_str());
  ASSERT_EQ(zip->status, 200) << zip->body;
  EXPECT_EQ(zip->get_header_value("Content-Type"), "application/zip");
  EXPECT_EQ(zip->get_header_value("Content-Disposition"),
            "attachment; filename=\"test_sleep-" + id + ".zip\"");
  EXPECT_EQ(zip->get_header_value("Transfer-Encoding"), "chunked");  // streamed, not buffered
  const fs::path archive = dir_.path() / "artifacts.zip";
  std::ofstream(archive, std::ios::binary) << zip->body;
  int status = 0;
  const std::string tested = RunCommand("unzip -t " + archive.string(), &status);
  ASSERT_EQ(status, 0) << tested;
  EXPECT_NE(tested.find("No errors detected"), std::string::npos) << tested;

  const json artifacts = JsonOf(client.Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
  std::set<std::string> recorded, archived;
  for (const auto& artifact : artifacts) recorded.insert(artifact["name"].get<std::string>());
  std::istringstream names(RunCommand("unzip -Z1 " + archive.string(), &status));
  for (std::string line; std::getline(names, line);) archived.insert(line);
  EXPECT_EQ(archived, recorded);
  for (const auto& artifact : artifacts) {
    const std::string name = artifact["name"];
    const std::string bytes = RunCommand("unzip -p " + archive.string() + " " + name, &status);
    EXPECT_EQ(storage::Sha256Hex(bytes), artifact["sha256"]) << name;
  }

  // A job that has not ended has no recorded artifacts yet.
  const std::string running =
      SubmitSleep(client, dataset, {{"steps", 100000}, {"step_ms", 10}})["id"];
  ExpectError(client.Get(("/api/v1/jobs/" + running + "/artifacts.zip").c_str()), 409,
              "job_not_finished");
  client.Post(("/api/v1/jobs/" + running + "/cancel").c_str());
  ExpectError(client.Get("/api/v1/jobs/0000000000000000/artifacts.zip"), 404, "job_not_found");
}

// The server's own stderr, from a child process that ran requests and jobs and then stopped.
TEST_F(ServerApiTest, LogsOneLinePerRequestAndPerJobStateChange) {
  const fs::path log = dir_.path() / "server.log";
  ServerProcess server;
  const int port =
      server.Start({"--port", "0", "--data", (dir_.path() / "data").string(), "--workers", "1",
                    "--threads-per-job", "1", "--web", ""},
                   log);
  auto client = MakeClient(port);
  ASSERT_EQ(client->Get("/api/v1/health")->status, 200);
  ASSERT_EQ(client->Get("/api/v1/jobs/0000000000000000")->status, 404);
  const std::string dataset = CreateDataset(*client);
  client->Put(("/api/v1/datasets/" + dataset + "/images/a b.png").c_str(), PngBytes(8, 8),
              "image/png");
  client->Put(("/api/v1/datasets/" + dataset + "/images/a.png").c_str(), PngBytes(8, 8),
              "image/png");
  const std::string done = SubmitSleep(*client, dataset, {{"steps", 2}, {"step_ms", 5}})["id"];
  ASSERT_EQ(WaitForJob(port, done, 20)["state"], "succeeded");
  const std::string failed =
      SubmitSleep(*client, dataset, {{"steps", 1}, {"step_ms", 5}, {"fail", true}})["id"];
  ASSERT_EQ(WaitForJob(port, failed, 20)["state"], "failed");
  server.Kill(SIGTERM);
  ASSERT_EQ(server.Wait(), 0);  // every line written before it exits

  std::ifstream in(log);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  const auto count = [&lines](const std::string& pattern) {
    const std::regex re(pattern);
    return std::count_if(lines.begin(), lines.end(),
                         [&re](const std::string& line) { return std::regex_search(line, re); });
  };
  const std::string ts = R"(^omnirig: ts=\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z )";
  EXPECT_EQ(count(ts + R"(event=request method=GET path=/api/v1/health status=200 )"
                       R"(duration_ms=\d+\.\d{3} route="GET /api/v1/health" remote=127\.0\.0\.1$)"),
            1);
  EXPECT_EQ(count(ts + R"(event=request method=GET path=/api/v1/jobs/0000000000000000 status=404 )"),
            1);
  // A value with a space is quoted (and the name refused).
  EXPECT_EQ(count(ts + R"(event=request method=PUT path="/api/v1/datasets/\w+/images/a b\.png" )"
                       R"(status=400 )"),
            1);
  const std::string job = "event=job job=" + done + " type=test_sleep ";
  EXPECT_EQ(count(ts + job + "state=queued attempt=0 dataset=" + dataset + "$"), 1);
  EXPECT_EQ(count(ts + job + R"(state=running attempt=1 worker=\S+:\d+$)"), 1);
  EXPECT_EQ(count(ts + job + R"(state=succeeded attempt=1 duration_s=\d+\.\d{3}$)"), 1);
  EXPECT_EQ(count(ts + "event=job job=" + failed +
                  R"( type=test_sleep state=failed attempt=1 duration_s=\S+ error_code=\w+$)"),
            1);
  // One line per change: progress writes log nothing.
  EXPECT_EQ(count("event=job job=" + done + " "), 3);
  for (const std::string& line : lines) EXPECT_EQ(line.find('\r'), std::string::npos);
}

// A Kalibr target file goes up beside the images and names the board of a calibration; one the
// dataset lacks is refused at submission with the .yaml files it has.
TEST_F(ServerApiTest, AcceptsAKalibrTargetAndRefusesAMissingOne) {
  auto& client = Start(Options());
  const std::string id = CreateDataset(client);
  const std::string base = "/api/v1/datasets/" + id + "/images/";
  const auto stored = client.Put((base + "april_6x6.yaml").c_str(),
                                 "target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\n"
                                 "tagSize: 0.088\ntagSpacing: 0.3\n",
                                 "application/yaml");
  ASSERT_TRUE(stored);
  EXPECT_EQ(stored->status, 201) << stored->body;
  EXPECT_EQ(JsonOf(stored)["content_type"], "application/yaml");
  ASSERT_EQ(client.Put((base + "view_0.png").c_str(), PngBytes(64, 48), "image/png")->status, 201);
  const auto missing = client.Post(
      "/api/v1/jobs",
      R"({"type": "calibration", "dataset": ")" + id + R"(", "params": {"board": "april.yaml"}})",
      "application/json");
  ExpectError(missing, 422, "invalid_input");
  EXPECT_NE(missing->body.find("its .yaml files: april_6x6.yaml"), std::string::npos)
      << missing->body;
  const auto named = client.Post(
      "/api/v1/jobs",
      R"({"type": "calibration", "dataset": ")" + id +
          R"(", "params": {"board": "april_6x6.yaml"}})",
      "application/json");
  ASSERT_TRUE(named);
  EXPECT_EQ(named->status, 202) << named->body;
}

TEST_F(ServerApiTest, RefusesBadJobs) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  const auto post = [&](const std::string& body) {
    return client.Post("/api/v1/jobs", body, "application/json");
  };
  ExpectError(post("{\"type\": "), 400, "invalid_argument");
  ExpectError(post(R"({"type": "test_sleep", "dataset": ")" + dataset + R"(", "colour": 1})"), 400,
              "invalid_argument");
  ExpectError(post(R"({"type": 7, "dataset": "x"})"), 400, "invalid_argument");
  const auto unknown = post(R"({"type": "teleport", "dataset": ")" + dataset + R"("})");
  ExpectError(unknown, 400, "unknown_job_type");
  EXPECT_NE(unknown->body.find("test_sleep"), std::string::npos);  // lists the known types
  ExpectError(post(R"({"type": "test_sleep", "dataset": "missing"})"), 404, "dataset_not_found");
  const auto bad_params =
      post(R"({"type": "test_sleep", "dataset": ")" + dataset + R"(", "params": {"steps": "x"}})");
  ExpectError(bad_params, 400, "invalid_params");
  EXPECT_NE(bad_params->body.find("params.steps"), std::string::npos);
  ExpectError(post(R"({"type": "test_sleep", "dataset": ")" + dataset +
                   R"(", "params": {"after": "nope"}})"),
              404, "job_not_found");
  ExpectError(client.Get("/api/v1/jobs/missing"), 404, "job_not_found");
  ExpectError(client.Get("/api/v1/jobs?state=bogus"), 400, "invalid_argument");
  // A job that reads images is refused on an empty dataset rather than queued to fail.
  const auto empty = post(R"({"type": "calibration", "dataset": ")" + dataset +
                          R"(", "params": {"board": {"type": "checkerboard", "cols": 9, )"
                          R"("rows": 6, "square_size_mm": 30}}})");
  ExpectError(empty, 422, "dataset_empty");
  EXPECT_NE(empty->body.find(dataset), std::string::npos);
}

// The first-run sample data: a "sample" job renders a preset into its (empty) dataset, whose
// images then carry the records an upload would give them.
TEST_F(ServerApiTest, SampleJobRendersAPresetIntoItsDataset) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client, "sample: one camera");
  const auto post = [&](const json& params) {
    return client.Post("/api/v1/jobs",
                       json{{"type", "sample"}, {"dataset", dataset}, {"params", params}}.dump(),
                       "application/json");
  };
  ExpectError(post({{"preset", "teapot"}}), 400, "invalid_params");
  ExpectError(post({{"preset", "mono-calib"}, {"views", 3}}), 400, "invalid_params");
  const auto created = post({{"preset", "mono-calib"}});
  ASSERT_EQ(created->status, 202) << created->body;
  const json job = WaitForJob(port_, JsonOf(created)["id"], 120);
  ASSERT_EQ(job["state"], "succeeded") << job.dump();
  EXPECT_EQ(job["progress"]["stage"], "done");
  EXPECT_NE(job["progress"]["message"].get<std::string>().find("8 files"), std::string::npos);
  const json listing = JsonOf(client.Get(("/api/v1/datasets/" + dataset).c_str()));
  ASSERT_EQ(listing["images"].size(), 8u) << listing.dump();
  EXPECT_EQ(listing["images"][0]["name"], "view_000.png");
  EXPECT_EQ(listing["images"][0]["width"], 640);
  EXPECT_EQ(listing["images"][0]["content_type"], "image/png");
  const auto image = client.Get(("/api/v1/datasets/" + dataset + "/images/view_000.png").c_str());
  ASSERT_EQ(image->status, 200);
  EXPECT_EQ(image->body.size(), listing["images"][0]["size"].get<size_t>());
  const json artifacts = JsonOf(client.Get(
      ("/api/v1/jobs/" + JsonOf(created)["id"].get<std::string>() + "/artifacts").c_str()));
  std::set<std::string> names;
  for (const auto& artifact : artifacts) names.insert(artifact["name"]);
  EXPECT_TRUE(names.count("sample/ground_truth.json")) << artifacts.dump();
}

TEST_F(ServerApiTest, ResultIs409UntilSucceededAndProgressIsStored) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  const std::string id = SubmitSleep(client, dataset, {{"steps", 50}, {"step_ms", 20}})["id"];
  ExpectError(client.Get(("/api/v1/jobs/" + id + "/result").c_str()), 409, "job_not_succeeded");
  // A dependent job is refused while its reference has not succeeded: 422, with the reason.
  const auto not_ready = client.Post(
      "/api/v1/jobs",
      json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", {{"after", id}}}}.dump(),
      "application/json");
  ExpectError(not_ready, 422, "dependency_not_ready");
  EXPECT_NE(not_ready->body.find("needs a succeeded"), std::string::npos) << not_ready->body;
  // Progress as events tell it, and as a poll then shows it.
  const auto progressed = [](const json& job) {
    return job["progress"]["fraction"].get<double>() > 0.1;
  };
  ASSERT_TRUE(FollowEvents(
      port_, id, 20, [&] { return progressed(JsonOf(client.Get(("/api/v1/jobs/" + id).c_str()))); },
      [&](const std::string&, const json& data) { return progressed(data); }));
  const json job = JsonOf(client.Get(("/api/v1/jobs/" + id).c_str()));
  EXPECT_EQ(job["state"], "running");
  EXPECT_EQ(job["progress"]["stage"], "sleep");
  EXPECT_GT(job["progress"]["fraction"].get<double>(), 0.1);
  EXPECT_TRUE(job["progress"]["eta_s"].is_number());
  const json done = WaitForJob(port_, id, 20);
  ASSERT_EQ(done["state"], "succeeded");
  // A reference of the wrong type (here a test_sleep job given as a slam job's rig) is refused
  // at submission, naming the type it needs, even though it succeeded.
  ASSERT_NE(service_->state().job_types.Find("slam"), nullptr);  // registered by the service
  const auto wrong = client.Post(
      "/api/v1/jobs",
      json{{"type", "slam"}, {"dataset", dataset}, {"params", {{"rig", id}}}}.dump(),
      "application/json");
  ExpectError(wrong, 422, "wrong_job_type");
  EXPECT_NE(wrong->body.find("is a test_sleep job"), std::string::npos) << wrong->body;
  EXPECT_NE(wrong->body.find("succeeded relative_pose job"), std::string::npos) << wrong->body;
  const json after = SubmitSleep(client, dataset, {{"after", id}});
  const json dependent = WaitForJob(port_, after["id"], 20);
  ASSERT_EQ(dependent["state"], "succeeded");
  EXPECT_EQ(JsonOf(client.Get(("/api/v1/jobs/" + after["id"].get<std::string>() + "/result")
                                  .c_str()))["after"]["steps"],
            50);
}

TEST_F(ServerApiTest, CancelStopsARunningJob) {
  auto options = Options();
  options.workers.num_workers = 1;
  auto& client = Start(options);
  const std::string dataset = CreateDataset(client);
  const std::string running =
      SubmitSleep(client, dataset, {{"steps", 1000}, {"step_ms", 50}})["id"];
  const std::string queued = SubmitSleep(client, dataset, {{"steps", 1}})["id"];
  ASSERT_EQ(WaitForJob(port_, running, 10, "running")["state"], "running");
  const auto queued_cancel = client.Post(("/api/v1/jobs/" + queued + "/cancel").c_str());
  ASSERT_EQ(queued_cancel->status, 200) << queued_cancel->body;
  EXPECT_EQ(JsonOf(queued_cancel)["state"], "canceled");

  const auto cancel = client.Post(("/api/v1/jobs/" + running + "/cancel").c_str());
  ASSERT_EQ(cancel->status, 202) << cancel->body;
  EXPECT_TRUE(JsonOf(cancel)["cancel_requested"].get<bool>());
  // The job had 50 s left; it ends long before that (how fast is bench/load_bench.sh's).
  const json canceled = WaitForJob(port_, running, 30);
  EXPECT_EQ(canceled["state"], "canceled");
  ExpectError(client.Post(("/api/v1/jobs/" + running + "/cancel").c_str()), 409, "job_finished");
  // The log of a canceled job is still an artifact.
  const json artifacts = JsonOf(client.Get(("/api/v1/jobs/" + running + "/artifacts").c_str()));
  ASSERT_EQ(artifacts.size(), 1u);
  EXPECT_EQ(artifacts[0]["name"], "log.txt");
}

// A multi-machine deployment cancels through the shared store: a cancel written there by
// another process (a second store on the same database file) stops the job.
TEST_F(ServerApiTest, CancelWrittenToTheStoreByAnotherProcessStopsTheJob) {
  auto options = Options();
  options.workers.num_workers = 1;
  auto& client = Start(options);
  const std::string dataset = CreateDataset(client);
  const std::string running =
      SubmitSleep(client, dataset, {{"steps", 1000}, {"step_ms", 50}})["id"];
  ASSERT_EQ(WaitForJob(port_, running, 10, "running")["state"], "running");
  storage::SqliteJobStore other_process(service_->state().data_dir->DatabasePath().string(), 1);
  ASSERT_EQ(other_process.RequestCancel(running), storage::JobState::kRunning);
  const json canceled = WaitForJob(port_, running, 30);
  EXPECT_EQ(canceled["state"], "canceled");
  EXPECT_EQ(other_process.GetJob(running)->state, storage::JobState::kCanceled);
}

// The log of a running job is downloadable as it grows; it becomes a hashed artifact at the end.
TEST_F(ServerApiTest, LogOfARunningJobIsDownloadable) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  const std::string id = SubmitSleep(client, dataset, {{"steps", 1000}, {"step_ms", 20}})["id"];
  const std::string log_url = "/api/v1/jobs/" + id + "/artifacts/log.txt";
  int status = 0;
  std::string body;
  std::string content_type;
  std::string cache_control;
  for (int i = 0; i < 500; ++i) {
    const auto log = client.Get(log_url.c_str());
    ASSERT_TRUE(log);
    status = log->status;
    body = log->body;
    content_type = log->get_header_value("Content-Type");
    cache_control = log->get_header_value("Cache-Control");
    if (status == 200 && body.find("stage sleep") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(status, 200) << body;
  EXPECT_NE(body.find("job " + id + " (test_sleep) attempt 1"), std::string::npos) << body;
  EXPECT_NE(body.find("stage sleep"), std::string::npos) << body;
  EXPECT_EQ(content_type.rfind("text/plain", 0), 0u) << content_type;
  EXPECT_EQ(cache_control, "no-store");
  EXPECT_EQ(JsonOf(client.Get(("/api/v1/jobs/" + id).c_str()))["state"], "running");
  // Other artifacts do not exist before the job ends.
  ExpectError(client.Get(("/api/v1/jobs/" + id + "/artifacts/out.bin").c_str()), 404,
              "artifact_not_found");
  client.Post(("/api/v1/jobs/" + id + "/cancel").c_str());
  ASSERT_EQ(WaitForJob(port_, id, 5)["state"], "canceled");
  const auto final_log = client.Get(log_url.c_str());
  ASSERT_EQ(final_log->status, 200);
  EXPECT_EQ(final_log->body.rfind(body, 0), 0u) << "the final log extends the live one";
  EXPECT_NE(final_log->body.find("finished: canceled"), std::string::npos) << final_log->body;
  EXPECT_FALSE(final_log->get_header_value("ETag").empty());
}

TEST_F(ServerApiTest, RetryDeleteAndFilters) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  const std::string failing = SubmitSleep(client, dataset, {{"fail", true}})["id"];
  const json failed = WaitForJob(port_, failing, 10);
  ASSERT_EQ(failed["state"], "failed");
  EXPECT_EQ(failed["error"]["code"], "invalid_input");
  EXPECT_EQ(failed["error"]["message"], "asked to fail");
  const auto retry = client.Post(("/api/v1/jobs/" + failing + "/retry").c_str());
  ASSERT_EQ(retry->status, 202);
  // Back in the queue; an idle worker may already have claimed it (the reply is the store's).
  const std::string retried_state = JsonOf(retry)["state"];
  EXPECT_TRUE(retried_state == "queued" || retried_state == "running") << retried_state;
  EXPECT_EQ(WaitForJob(port_, failing, 10)["state"], "failed");

  const std::string good = SubmitSleep(client, dataset, {{"steps", 1}})["id"];
  ASSERT_EQ(WaitForJob(port_, good, 10)["state"], "succeeded");
  ExpectError(client.Post(("/api/v1/jobs/" + good + "/retry").c_str()), 409, "job_not_retryable");
  EXPECT_EQ(JsonOf(client.Get("/api/v1/jobs?state=succeeded")).size(), 1u);
  EXPECT_EQ(JsonOf(client.Get("/api/v1/jobs?state=failed&type=test_sleep")).size(), 1u);
  EXPECT_EQ(JsonOf(client.Get("/api/v1/jobs?type=other")).size(), 0u);
  EXPECT_EQ(JsonOf(client.Get(("/api/v1/jobs?dataset=" + dataset).c_str())).size(), 2u);

  const std::string slow = SubmitSleep(client, dataset, {{"steps", 1000}, {"step_ms", 20}})["id"];
  WaitForJob(port_, slow, 10, "running");
  ExpectError(client.Delete(("/api/v1/jobs/" + slow).c_str()), 409, "job_running");
  ExpectError(client.Delete(("/api/v1/datasets/" + dataset).c_str()), 409, "dataset_in_use");
  client.Post(("/api/v1/jobs/" + slow + "/cancel").c_str());
  WaitForJob(port_, slow, 5);
  EXPECT_EQ(client.Delete(("/api/v1/jobs/" + good).c_str())->status, 204);
  ExpectError(client.Get(("/api/v1/jobs/" + good).c_str()), 404, "job_not_found");
  EXPECT_FALSE(std::filesystem::exists(dir_.path() / "data" / "jobs" / good));
}

TEST_F(ServerApiTest, QueueLimitGives503) {
  auto options = Options();
  options.workers.num_workers = 1;
  options.max_queued_jobs = 2;
  auto& client = Start(options);
  const std::string dataset = CreateDataset(client);
  const std::string blocker =
      SubmitSleep(client, dataset, {{"steps", 1000}, {"step_ms", 20}})["id"];
  WaitForJob(port_, blocker, 10, "running");
  SubmitSleep(client, dataset, json::object());
  SubmitSleep(client, dataset, json::object());
  const auto full =
      client.Post("/api/v1/jobs", json{{"type", "test_sleep"}, {"dataset", dataset}}.dump(),
                  "application/json");
  ExpectError(full, 503, "queue_full");
  client.Post(("/api/v1/jobs/" + blocker + "/cancel").c_str());
}

TEST_F(ServerApiTest, BearerToken) {
  auto options = Options();
  options.token = "s3cret";
  Start(options);
  auto anonymous = MakeClient(port_);
  ExpectError(anonymous->Get("/api/v1/health"), 401, "unauthorized");
  ExpectError(anonymous->Get("/metrics"), 401, "unauthorized");
  auto wrong = MakeClient(port_, "guess");
  ExpectError(wrong->Get("/api/v1/datasets"), 401, "unauthorized");
  EXPECT_EQ(client_->Get("/api/v1/datasets")->status, 200);
  EXPECT_EQ(anonymous->Get("/")->status, 200);  // the page itself is public; its API calls are not
}

TEST_F(ServerApiTest, RefusesNonLoopbackWithoutToken) {
  auto options = Options();
  options.host = "0.0.0.0";
  EXPECT_THROW({ server::Service service(options); }, omnirig::InvalidArgument);
  options.token = "t";
  EXPECT_NO_THROW({ server::Service service(options); });
}

TEST_F(ServerApiTest, DrainHandsRunningJobsBackAndRestartFinishesThem) {
  auto options = Options();
  options.workers.num_workers = 1;
  auto& client = Start(options);
  const std::string dataset = CreateDataset(client);
  const std::string id = SubmitSleep(client, dataset, {{"steps", 20}, {"step_ms", 25}})["id"];
  ASSERT_EQ(WaitForJob(port_, id, 10, "running")["state"], "running");
  EXPECT_EQ(service_->Drain(0.0), 1);
  client_.reset();
  service_.reset();
  Start(options);
  const json job = WaitForJob(port_, id, 20);
  EXPECT_EQ(job["state"], "succeeded");
  EXPECT_EQ(job["attempts"], 1);  // a drain does not count as an attempt
}

TEST_F(ServerApiTest, EpipolarRouteRefusesWrongJobs) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  const std::string id = SubmitSleep(client, dataset, {{"steps", 1}})["id"];
  WaitForJob(port_, id, 10);
  ExpectError(client.Get("/api/v1/jobs/missing/epipolar?from=cam0&u=1&v=2"), 404, "job_not_found");
  ExpectError(client.Get(("/api/v1/jobs/" + id + "/epipolar?from=cam0&u=1&v=2").c_str()), 400,
              "invalid_argument");
}

// The epipolar route on a relative_pose result, of a stand-in relative_pose job (the route's
// contract is the result JSON, not the solver).
TEST_F(ServerApiTest, EpipolarCurveOfARelativePoseResult) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  const std::string id = SubmitFakeRelativePose(service_->state().job_types, client, port_, dataset,
                                                api::RigToJson(TinyTestRig(640, 480)));
  const std::string url = "/api/v1/jobs/" + id + "/epipolar";
  const auto curve = client.Get((url + "?from=cam0&u=400&v=250").c_str());
  ASSERT_EQ(curve->status, 200) << curve->body;
  const json body = JsonOf(curve);
  EXPECT_EQ(body["from"], "cam0");
  EXPECT_EQ(body["to"], "cam1");
  ASSERT_TRUE(body["polylines"].is_array());
  EXPECT_FALSE(body["polylines"].empty());
  ExpectError(client.Get((url + "?from=cam2&u=1&v=2").c_str()), 400, "invalid_argument");
  ExpectError(client.Get((url + "?from=cam1&u=1").c_str()), 400, "invalid_argument");
  ExpectError(client.Get((url + "?from=cam1&u=abc&v=2").c_str()), 400, "invalid_argument");

  // Jobs that read this rig are refused at submission when the images are not of the size the
  // cameras were calibrated for (the sizes come from the upload's header check).
  for (const char* name : {"cam0/a.png", "cam1/a.png"}) {
    const auto put = client.Put(("/api/v1/datasets/" + dataset + "/images/" + name).c_str(),
                                PngBytes(320, 240), "image/png");
    ASSERT_EQ(put->status, 201) << put->body;
  }
  for (const char* type : {"stereo_reconstruct", "slam"}) {
    const auto refused = client.Post(
        "/api/v1/jobs",
        json{{"type", type}, {"dataset", dataset}, {"params", {{"rig", id}}}}.dump(),
        "application/json");
    ExpectError(refused, 422, "invalid_input");
    EXPECT_NE(refused->body.find("cam0/a.png is 320x240 but the rig's cam0 is calibrated for "
                                 "640x480"),
              std::string::npos)
        << refused->body;
  }
}

// Live progress is pushed: GET /api/v1/events streams every job's changes (state and progress)
// as Server-Sent Events, and a poll of a job that has not changed since gets 304 by its ETag.
TEST_F(ServerApiTest, EventsPushJobChangesAndPollsRevalidateByETag) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  std::string id;
  std::vector<std::string> states;
  std::vector<double> fractions;
  ASSERT_TRUE(FollowEvents(
      port_, "", 30,
      [&] {
        id = SubmitSleep(client, dataset, {{"steps", 5}, {"step_ms", 10}})["id"];
        return false;
      },
      [&](const std::string& type, const json& data) {
        EXPECT_EQ(type, "job");
        EXPECT_EQ(data["id"], id);
        states.push_back(data["state"]);
        fractions.push_back(data["progress"]["fraction"]);
        return data["state"] == "succeeded";
      }));
  ASSERT_GE(states.size(), 3u);
  EXPECT_EQ(states.front(), "queued");
  EXPECT_NE(std::find(states.begin(), states.end(), "running"), states.end());
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_EQ(fractions.back(), 1.0);
  // ETag: 304 while the job is as it was, 200 with the job once it changed.
  const std::string url = "/api/v1/jobs/" + id;
  const auto first = client.Get(url.c_str());
  ASSERT_EQ(first->status, 200);
  const std::string etag = first->get_header_value("ETag");
  ASSERT_FALSE(etag.empty());
  const auto again = client.Get(url.c_str(), {{"If-None-Match", etag}});
  EXPECT_EQ(again->status, 304);
  EXPECT_EQ(again->body, "");
  EXPECT_EQ(client.Get(url.c_str(), {{"If-None-Match", "\"other\""}})->status, 200);
  ASSERT_EQ(client.Post((url + "/retry").c_str())->status, 409);  // succeeded: unchanged
  EXPECT_EQ(client.Get(url.c_str(), {{"If-None-Match", etag}})->status, 304);
  ASSERT_EQ(client.Delete(url.c_str())->status, 204);
  ExpectError(client.Get(url.c_str(), {{"If-None-Match", etag}}), 404, "job_not_found");
}

// A caller's mistake is a 400 whose message names the problem and no source file; a broken
// invariant (a stored result that is not what its job type writes) is a 500.
TEST_F(ServerApiTest, ErrorsCarryNoSourceLocations) {
  auto& client = Start();
  const std::string dataset = CreateDataset(client);
  const auto bad = client.Post(
      "/api/v1/jobs",
      json{{"type", "calibration"}, {"dataset", dataset}, {"params", {{"x", 1}}}}.dump(),
      "application/json");
  ASSERT_TRUE(bad);
  ASSERT_NE(service_->state().job_types.Find("calibration"), nullptr);  // registered by the service
  ExpectError(bad, 400, "invalid_params");
  const std::string message = JsonOf(bad)["error"]["message"];
  EXPECT_EQ(message.find(".cc:"), std::string::npos) << message;
  EXPECT_FALSE(message.empty());
  api::JobType fake;
  fake.name = "relative_pose";
  fake.validate = [](const json&) {};
  fake.reads_images = false;
  fake.run = [](const json&, const api::JobContext&) { return json{{"not", "a rig"}}; };
  service_->state().job_types.Add(fake);
  const std::string id = JsonOf(
      client.Post("/api/v1/jobs", json{{"type", "relative_pose"}, {"dataset", dataset}}.dump(),
                  "application/json"))["id"];
  ASSERT_EQ(WaitForJob(port_, id, 30)["state"], "succeeded");
  const auto broken = client.Get(("/api/v1/jobs/" + id + "/epipolar?from=cam0&u=1&v=2").c_str());
  ExpectError(broken, 500, "internal");
  EXPECT_EQ(broken->body.find(".cc:"), std::string::npos) << broken->body;
}

// The real `calibration` job type through the service, on real catadioptric images, when both
// the job type and the data are present.
TEST_F(ServerApiTest, RealCalibrationJob) {
  auto options = Options();
  options.workers.num_workers = 1;
  options.workers.threads_per_job = 2;
  auto& client = Start(options);
  ASSERT_NE(service_->state().job_types.Find("calibration"), nullptr);  // registered by the service
  const char* source = std::getenv("OMNIRIG_SOURCE_DIR");
  const std::filesystem::path data = std::filesystem::path(source ? source : ".") / ".." /
                                     "shared" / "data" / "real" / "ocamcalib-vmr";
  if (!std::filesystem::exists(data)) GTEST_SKIP() << "real data absent: " << data;
  const std::string dataset = CreateDataset(client, "vmr");
  httplib::MultipartFormDataItems items;
  for (const auto& entry : std::filesystem::directory_iterator(data)) {
    if (entry.path().extension() != ".jpg") continue;
    std::ifstream in(entry.path(), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    items.push_back({"files", bytes, entry.path().filename().string(), "image/jpeg"});
  }
  const auto upload = client.Post(("/api/v1/datasets/" + dataset + "/images").c_str(), items);
  ASSERT_EQ(upload->status, 201) << upload->body;
  ASSERT_EQ(JsonOf(upload)["images"].size(), 10u);
  EXPECT_EQ(JsonOf(upload)["images"][0]["width"], 1024);
  const json board = {{"type", "checkerboard"}, {"cols", 6}, {"rows", 7}, {"square_size_mm", 30}};
  const auto created = client.Post(
      "/api/v1/jobs",
      json{{"type", "calibration"}, {"dataset", dataset}, {"params", {{"board", board}}}}.dump(),
      "application/json");
  ASSERT_EQ(created->status, 202) << created->body;
  const std::string id = JsonOf(created)["id"];
  const json job = WaitForJob(port_, id, 240);
  ASSERT_EQ(job["state"], "succeeded") << job.dump();
  const json result = JsonOf(client.Get(("/api/v1/jobs/" + id + "/result").c_str()));
  EXPECT_TRUE(result.contains("camera")) << result.dump().substr(0, 500);
  const json artifacts = JsonOf(client.Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
  std::set<std::string> names;
  for (const auto& artifact : artifacts) names.insert(artifact["name"]);
  EXPECT_TRUE(names.count("log.txt") && names.count("result.json"));
}

}  // namespace
}  // namespace omnirig::testing

int main(int argc, char** argv) {
  int exit_code = 0;
  if (omnirig::testing::ServeIfRequested(argc, argv, exit_code)) return exit_code;
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
