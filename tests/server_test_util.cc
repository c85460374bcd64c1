#include "tests/server_test_util.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "api/job_types.h"
#include "engine/util/check.h"
#include "server/commands.h"

namespace omnirig::testing {
namespace fs = std::filesystem;

namespace {

int IntParam(const nlohmann::json& params, const std::string& name, int low, int high,
             int fallback) {
  if (!params.contains(name)) return fallback;
  const auto& value = params[name];
  if (!value.is_number_integer()) throw InvalidArgument("params." + name + " must be an integer");
  const int number = value.get<int>();
  if (number < low || number > high) {
    throw InvalidArgument("params." + name + " must be in [" + std::to_string(low) + ", " +
                          std::to_string(high) + "]");
  }
  return number;
}

void ValidateSleep(const nlohmann::json& params) {
  for (const auto& [key, value] : params.items()) {
    if (key != "steps" && key != "step_ms" && key != "output_kb" && key != "fail" &&
        key != "after") {
      throw InvalidArgument("unknown field params." + key);
    }
  }
  IntParam(params, "steps", 1, 100000, 1);
  IntParam(params, "step_ms", 0, 60000, 0);
  IntParam(params, "output_kb", 0, 100000, 0);
  if (params.contains("fail") && !params["fail"].is_boolean()) {
    throw InvalidArgument("params.fail must be a boolean");
  }
  if (params.contains("after") && !params["after"].is_string()) {
    throw InvalidArgument("params.after must be a job id string");
  }
}

nlohmann::json RunSleep(const nlohmann::json& params, const api::JobContext& context) {
  const int steps = IntParam(params, "steps", 1, 100000, 1);
  const int step_ms = IntParam(params, "step_ms", 0, 60000, 0);
  nlohmann::json result = {{"steps", steps}, {"images", context.image_names}};
  if (params.contains("after")) result["after"] = context.load_result(params["after"]);
  for (int step = 0; step < steps; ++step) {
    for (int slept = 0; slept < step_ms; slept += 10) {
      context.progress.ThrowIfCancelled();
      std::this_thread::sleep_for(std::chrono::milliseconds(std::min(10, step_ms - slept)));
    }
    context.progress.ThrowIfCancelled();
    context.progress.Report(static_cast<double>(step + 1) / steps, "sleep",
                            "step " + std::to_string(step + 1) + " of " + std::to_string(steps));
  }
  context.log("slept " + std::to_string(steps) + " steps");
  if (params.value("fail", false)) throw InvalidArgument("asked to fail");
  const std::string output = SleepJobOutput(IntParam(params, "output_kb", 0, 100000, 0));
  FILE* file = std::fopen((context.output_dir / "out.bin").c_str(), "wb");
  std::fwrite(output.data(), 1, output.size(), file);
  std::fclose(file);
  result["output_bytes"] = output.size();
  result["threads"] = context.num_threads;
  return result;
}

}  // namespace

api::JobType SleepJobType() {
  api::JobType type;
  type.name = "test_sleep";
  type.validate = ValidateSleep;
  type.referenced_jobs = [](const nlohmann::json& params) {
    std::vector<api::JobReference> references;
    if (params.contains("after")) {
      references.push_back({params["after"].get<std::string>(), "", "after"});
    }
    return references;
  };
  type.run = RunSleep;
  type.reads_images = false;  // the service's tests queue sleeps on empty datasets
  return type;
}

std::string SleepJobOutput(int output_kb) {
  std::string output(static_cast<size_t>(output_kb) * 1024, '\0');
  for (size_t i = 0; i < output.size(); ++i)
    output[i] = static_cast<char>((i * 7 + i / 1024) & 255);
  return output;
}

TempDir::TempDir() {
  std::random_device seed;
  path_ = fs::temp_directory_path() /
          ("omnirig-server-test-" + std::to_string(::getpid()) + "-" + std::to_string(seed()));
  fs::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ignored;
  fs::remove_all(path_, ignored);
}

std::string PngBytes(int width, int height, int seed) {
  cv::Mat image(height, width, CV_8UC1);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) image.at<uint8_t>(y, x) = static_cast<uint8_t>(x + y + seed);
  }
  std::vector<uint8_t> bytes;
  cv::imencode(".png", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

std::unique_ptr<httplib::Client> MakeClient(int port, const std::string& token) {
  auto client = std::make_unique<httplib::Client>("127.0.0.1", port);
  client->set_connection_timeout(5);
  client->set_read_timeout(30);
  if (!token.empty()) client->set_bearer_token_auth(token.c_str());
  return client;
}

nlohmann::json JsonOf(const httplib::Result& result) {
  if (!result)
    throw std::runtime_error("HTTP request failed: " + httplib::to_string(result.error()));
  return nlohmann::json::parse(result->body);
}

bool FollowEvents(int port, const std::string& job, double timeout_s,
                  const std::function<bool()>& on_open,
                  const std::function<bool(const std::string&, const nlohmann::json&)>& on_event) {
  httplib::Client client("127.0.0.1", port);
  const auto micros = static_cast<int64_t>(timeout_s * 1e6);
  client.set_read_timeout(micros / 1000000, micros % 1000000);
  bool opened = false;
  bool done = false;
  std::string buffer;
  const auto result =
      client.Get(("/api/v1/events" + (job.empty() ? "" : "?job=" + job)).c_str(),
                 [&](const char* data, size_t size) {
                   if (!opened) {  // the server's first chunk says the stream is open
                     opened = true;
                     if (on_open()) return !(done = true);
                   }
                   buffer.append(data, size);
                   for (size_t end = buffer.find("\n\n"); end != std::string::npos;
                        end = buffer.find("\n\n")) {
                     const std::string block = buffer.substr(0, end);
                     buffer.erase(0, end + 2);
                     const size_t type_at = block.find("event: ");
                     const size_t data_at = block.find("data: ");
                     if (type_at == std::string::npos || data_at == std::string::npos) continue;
                     const std::string type =
                         block.substr(type_at + 7, block.find('\n', type_at) - type_at - 7);
                     if (on_event(type, nlohmann::json::parse(block.substr(data_at + 6)))) {
                       return !(done = true);
                     }
                   }
                   return true;
                 });
  (void)result;
  return done;
}

nlohmann::json WaitForJob(int port, const std::string& id, double timeout_s,
                          const std::string& until_state) {
  const auto reached = [&](const nlohmann::json& job) {
    const std::string state = job.value("state", "");
    return until_state.empty() ? (state == "succeeded" || state == "failed" || state == "canceled")
                               : state == until_state;
  };
  auto client = MakeClient(port);
  const auto current = [&] { return JsonOf(client->Get(("/api/v1/jobs/" + id).c_str())); };
  nlohmann::json job;
  // Opened first, then the job read: a change between the two is not missed.
  FollowEvents(
      port, id, timeout_s,
      [&] {
        job = current();
        return reached(job);
      },
      [&](const std::string& type, const nlohmann::json& data) {
        // A live job's tracked frame or refreshed files say nothing of its state: the wait goes
        // on.
        if (type == "frame" || type == "artifacts") return false;
        if (type == "job") job = data;
        return type != "job" || reached(job);
      });
  return job.value("state", "") == "" ? current() : job;
}

std::string SubmitFakeRelativePose(api::JobTypes& job_types, httplib::Client& client, int port,
                                   const std::string& dataset, const nlohmann::json& rig_json) {
  api::JobType fake;
  fake.name = "relative_pose";
  fake.validate = [](const nlohmann::json&) {};
  fake.reads_images = false;
  fake.run = [rig_json](const nlohmann::json&, const api::JobContext&) { return rig_json; };
  job_types.Add(fake);
  const auto created = client.Post(
      "/api/v1/jobs", nlohmann::json{{"type", "relative_pose"}, {"dataset", dataset}}.dump(),
      "application/json");
  if (!created || created->status != 202) {
    throw std::runtime_error("the fake relative_pose job was refused: " +
                             (created ? created->body : std::string("no answer")));
  }
  const std::string id = JsonOf(created)["id"];
  if (WaitForJob(port, id, 30)["state"] != "succeeded") {
    throw std::runtime_error("the fake relative_pose job " + id + " did not succeed");
  }
  return id;
}

ServerProcess::~ServerProcess() {
  if (pid_ > 0) {
    Kill(SIGKILL);
    Wait();
  }
}

std::string ServerProcess::StartChild(const std::string& mode,
                                      const std::vector<std::string>& child_args,
                                      const fs::path& log_path) {
  int out[2];
  if (::pipe(out) != 0) throw std::runtime_error("pipe failed");
  pid_ = ::fork();
  if (pid_ == 0) {
    ::dup2(out[1], STDOUT_FILENO);
    FILE* log = std::fopen(log_path.c_str(), "a");
    if (log) ::dup2(fileno(log), STDERR_FILENO);
    ::close(out[0]);
    std::vector<std::string> args = {"/proc/self/exe", mode};
    args.insert(args.end(), child_args.begin(), child_args.end());
    std::vector<char*> argv;
    for (auto& arg : args) argv.push_back(arg.data());
    argv.push_back(nullptr);
    ::execv("/proc/self/exe", argv.data());
    ::_exit(127);
  }
  ::close(out[1]);
  std::string line;
  char c;
  while (::read(out[0], &c, 1) == 1 && c != '\n') line.push_back(c);
  ::close(out[0]);
  return line;
}

int ServerProcess::Start(const std::vector<std::string>& serve_args, const fs::path& log_path) {
  const std::string line = StartChild("--serve", serve_args, log_path);
  const size_t colon = line.rfind(':');
  if (line.rfind("omnirig listening on http://", 0) != 0 || colon == std::string::npos) {
    throw std::runtime_error("server did not start: '" + line + "' (see " + log_path.string() +
                             ")");
  }
  return std::stoi(line.substr(colon + 1));
}

void ServerProcess::Kill(int signal) {
  if (pid_ > 0) ::kill(pid_, signal);
}

int ServerProcess::Wait() {
  int status = 0;
  if (pid_ <= 0) return -1;
  ::waitpid(pid_, &status, 0);
  pid_ = -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

bool ServeIfRequested(int argc, char** argv, int& exit_code) {
  if (argc < 2 || std::string(argv[1]) != "--serve") return false;
  exit_code =
      server::ServeCommand(std::vector<std::string>(argv + 2, argv + argc), {SleepJobType()});
  return true;
}

}  // namespace omnirig::testing
