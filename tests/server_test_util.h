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
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "api/job_types.h"

namespace omnirig::testing {

// The test_sleep job type (add it with ServiceOptions::extra_job_types).
api::JobType SleepJobType();
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
// Follows GET /api/v1/events (of job `job` alone when not empty) on the server at `port`:
// once the stream is open calls `on_open` (a true result ends there), then `on_event` with each
// event's type and data until it returns true. False when the stream ends or is silent for
// `timeout_s` first.
bool FollowEvents(
    int port, const std::string& job, double timeout_s, const std::function<bool()>& on_open,
    const std::function<bool(const std::string& type, const nlohmann::json& data)>& on_event);
// Waits, on the job's events, until its state is terminal (or `until_state`), or until no event
// came for `timeout_s`; returns the job as GET /jobs/{id} then shows it.
nlohmann::json WaitForJob(int port, const std::string& id, double timeout_s,
                          const std::string& until_state = "");

// Adds to `job_types` (a running service's) a relative_pose job type whose result is
// `rig_json` (api::RigToJson; it replaces the real type: what reads a rig job depends on its
// JSON, not on the solver), submits one on `dataset` and waits for it to succeed; returns the
// job's id.
std::string SubmitFakeRelativePose(api::JobTypes& job_types, httplib::Client& client, int port,
                                   const std::string& dataset, const nlohmann::json& rig_json);

// `omnirig serve` in a child process: this test binary re-executed with "--serve ARGS..."
// (see ServeIfRequested), so the child has the test job type registered.
class ServerProcess {
 public:
  ~ServerProcess();
  // Starts and waits for the "listening" line; returns the port.
  int Start(const std::vector<std::string>& serve_args, const std::filesystem::path& log_path);
  // This test binary re-executed as `/proc/self/exe MODE ARGS...` (e.g. "--worker"), stderr
  // appended to `log_path`; returns the first line it prints (empty when it exits first).
  std::string StartChild(const std::string& mode, const std::vector<std::string>& args,
                         const std::filesystem::path& log_path);
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
