// `omnirig submit` against a real server: uploads a folder, resumes (sends only what the
// server lacks), runs a job, downloads result and artifacts, and reports failure by exit code.
// The server is this test binary re-executed with the test-only job type (server_test_util.h);
// the client is the shipped `omnirig` executable.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream content;
  content << in.rdbuf();
  return content.str();
}

void WriteFile(const fs::path& path, const std::string& content) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << content;
}

class SubmitTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* binary_dir = std::getenv("OMNIRIG_BINARY_DIR");
    if (!binary_dir) GTEST_SKIP() << "OMNIRIG_BINARY_DIR not set (run through ctest)";
    omnirig_ = fs::path(binary_dir) / "server" / "omnirig";
    ASSERT_TRUE(fs::exists(omnirig_)) << omnirig_;
    port_ = server_.Start({"--port", "0", "--data", (dir_.path() / "data").string(), "--web", ""},
                          dir_.path() / "server.log");
    client_ = MakeClient(port_);
  }

  // Runs `omnirig submit ARGS`; returns the exit code, stdout and stderr in the out-params.
  int Submit(const std::string& args, std::string* out, std::string* err) {
    const fs::path out_file = dir_.path() / "submit.out", err_file = dir_.path() / "submit.err";
    const std::string command = omnirig_.string() +
                                " submit --server http://127.0.0.1:" + std::to_string(port_) + " " +
                                args + " > " + out_file.string() + " 2> " + err_file.string();
    const int status = std::system(command.c_str());
    *out = ReadFile(out_file);
    *err = ReadFile(err_file);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

  TempDir dir_;
  fs::path omnirig_;
  ServerProcess server_;
  std::unique_ptr<httplib::Client> client_;
  int port_ = 0;
};

TEST_F(SubmitTest, UploadsResumesRunsAndDownloads) {
  const fs::path folder = dir_.path() / "rig";
  WriteFile(folder / "cam0" / "a.png", PngBytes(20, 10, 1));
  WriteFile(folder / "cam0" / "b.png", PngBytes(20, 10, 2));
  WriteFile(folder / "cam1" / "a.png", PngBytes(20, 10, 3));
  WriteFile(folder / ".hidden.png", PngBytes(4, 4));
  WriteFile(folder / "notes.txt", "not an image");
  const fs::path out = dir_.path() / "out";
  std::string stdout_text, stderr_text;
  ASSERT_EQ(Submit("--type test_sleep --params '{\"steps\": 2, \"output_kb\": 8}' --out " +
                       out.string() + " " + folder.string(),
                   &stdout_text, &stderr_text),
            0)
      << stderr_text;
  const std::string job_id = stdout_text.substr(0, stdout_text.find('\n'));
  EXPECT_NE(stderr_text.find("3 sent, 0 already"), std::string::npos) << stderr_text;
  EXPECT_EQ(ReadFile(out / "out.bin"), SleepJobOutput(8));
  const json result = json::parse(ReadFile(out / "result.json"));
  EXPECT_EQ(result["images"], json::array({"cam0/a.png", "cam0/b.png", "cam1/a.png"}));
  EXPECT_TRUE(fs::exists(out / "log.txt"));

  const std::string dataset = JsonOf(client_->Get(("/api/v1/jobs/" + job_id).c_str()))["dataset"];
  WriteFile(folder / "cam1" / "b.png", PngBytes(20, 10, 4));
  ASSERT_EQ(Submit("--type test_sleep --no-wait --dataset " + dataset + " " + folder.string(),
                   &stdout_text, &stderr_text),
            0)
      << stderr_text;
  EXPECT_NE(stderr_text.find("1 sent, 3 already"), std::string::npos) << stderr_text;
  EXPECT_EQ(JsonOf(client_->Get(("/api/v1/datasets/" + dataset).c_str()))["image_count"], 4);
}

// An MP4 whose boxes are whole (the upload check reads no further): ftyp, a random mdat, moov.
std::string Mp4Bytes(size_t payload, unsigned seed) {
  const auto box = [](const std::string& type, const std::string& content) {
    const auto size = static_cast<uint32_t>(8 + content.size());
    return std::string{static_cast<char>(size >> 24), static_cast<char>(size >> 16),
                       static_cast<char>(size >> 8), static_cast<char>(size)} +
           type + content;
  };
  std::string data(payload, '\0');
  for (size_t i = 0; i < payload; ++i) data[i] = static_cast<char>((i * 2654435761u + seed) >> 13);
  return box("ftyp", std::string("isom\0\0\0\0", 8)) + box("mdat", data) +
         box("moov", std::string(64, 'm'));
}

// Videos go up in chunks (a .tum beside them whole); a run after an interrupted one goes on where
// the server's part ends.
TEST_F(SubmitTest, UploadsVideosInChunksAndResumes) {
  const fs::path folder = dir_.path() / "recording";
  const std::string cam0 = Mp4Bytes(300000, 1), cam1 = Mp4Bytes(300000, 2);
  WriteFile(folder / "cam0.mp4", cam0);
  WriteFile(folder / "cam1.mp4", cam1);
  WriteFile(folder / "trajectory.tum", "0 0 0 0 0 0 0 1\n");  // a slam job's ground truth
  const std::string dataset =
      JsonOf(client_->Post("/api/v1/datasets", R"({"name": "rec"})", "application/json"))["id"];
  // An earlier run sent the first 100000 bytes of cam0.mp4, then stopped.
  const auto first =
      client_->Put(("/api/v1/datasets/" + dataset + "/images/cam0.mp4").c_str(),
                   {{"Content-Range", "bytes 0-99999/" + std::to_string(cam0.size())}},
                   cam0.substr(0, 100000), "application/octet-stream");
  ASSERT_EQ(first->status, 202) << first->body;
  std::string stdout_text, stderr_text;
  ASSERT_EQ(Submit("--type test_sleep --no-wait --chunk-mb 0.0625 --dataset " + dataset + " " +
                       folder.string(),
                   &stdout_text, &stderr_text),
            0)
      << stderr_text;
  EXPECT_NE(stderr_text.find("resuming cam0.mp4 at byte 100000"), std::string::npos) << stderr_text;
  EXPECT_NE(stderr_text.find("3 sent, 0 already"), std::string::npos) << stderr_text;
  const json listed = JsonOf(client_->Get(("/api/v1/datasets/" + dataset).c_str()));
  EXPECT_EQ(listed["video_count"], 2);
  EXPECT_EQ(listed["image_count"], 1);  // the .tum
  EXPECT_EQ(client_->Get(("/api/v1/datasets/" + dataset + "/images/cam0.mp4").c_str())->body, cam0);
  EXPECT_EQ(client_->Get(("/api/v1/datasets/" + dataset + "/images/cam1.mp4").c_str())->body, cam1);
}

TEST_F(SubmitTest, FailedJobGivesExitCode1AndItsLog) {
  const fs::path folder = dir_.path() / "one";
  WriteFile(folder / "a.png", PngBytes(8, 8));
  const fs::path out = dir_.path() / "failed";
  std::string stdout_text, stderr_text;
  EXPECT_EQ(Submit("--type test_sleep --params '{\"fail\": true}' --out " + out.string() + " " +
                       folder.string(),
                   &stdout_text, &stderr_text),
            1);
  EXPECT_NE(stderr_text.find("invalid_input: asked to fail"), std::string::npos) << stderr_text;
  EXPECT_TRUE(fs::exists(out / "log.txt"));
  EXPECT_NE(Submit("--type teleport " + folder.string(), &stdout_text, &stderr_text), 0);
  EXPECT_NE(stderr_text.find("unknown job type"), std::string::npos) << stderr_text;
}

}  // namespace
}  // namespace omnirig::testing

int main(int argc, char** argv) {
  int exit_code = 0;
  if (omnirig::testing::ServeIfRequested(argc, argv, exit_code)) return exit_code;
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
