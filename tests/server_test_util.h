#pragma once
// Shared by the server integration tests: a test-only job type, temporary folders, real PNG
// bytes, HTTP clients and a server subprocess.
//
// The "test_sleep" job type exists only inside the test binaries (never in the shipped
// server): it sleeps in small steps, checking cancellation every 10 ms and reporting progress
// per step, then writes a deterministic `out.bin` artifact. It exercises the queue, progress,
// cancel, retry and crash recovery without depending on the computer-vision job types.
// params: {"steps": int, "step_ms": int, "output_kb": int, "fail": bool, "after": job id}

#include <httplib.h>
#include <sys/types.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace omnirig::testing {

void RegisterSleepJobType();
// The bytes test_sleep writes to out.bin for `output_kb`.
std::string SleepJobOutput(int output_kb);

class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// A real PNG (OpenCV-encoded gradient) of the given size.
std::string PngBytes(int width, int height, int seed = 0);

std::unique_ptr<httplib::Client> MakeClient(int port, const std::string& token = "");
nlohmann::json JsonOf(const httplib::Result& result);
// Polls GET /jobs/{id} until the state is terminal or `timeout_s` passes; returns the job.
nlohmann::json WaitForJob(httplib::Client& client, const std::string& id, double timeout_s,
                          const std::string& until_state = "");

// `omnirig serve` in a child process: this test binary re-executed with "--serve ARGS..."
// (see ServeIfRequested), so the child has the test job type registered.
class ServerProcess {
 public:
  ~ServerProcess();
  // Starts and waits for the "listening" line; returns the port.
  int Start(const std::vector<std::string>& serve_args, const std::filesystem::path& log_path);
  void Kill(int signal);
  // Waits for exit; returns the exit status (128 + signal when killed).
  int Wait();
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
};

// Call first in main(): when argv[1] == "--serve", registers test_sleep, runs the server with
// the remaining arguments and returns true with its exit code in `exit_code`.
bool ServeIfRequested(int argc, char** argv, int& exit_code);

}  // namespace omnirig::testing
