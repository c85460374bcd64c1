// `omnirig submit`: the scripting client. Uploads a folder of images and videos (skipping those
// the server already holds with the same size and SHA-256, so an interrupted upload resumes),
// creates a job, shows a progress bar, and downloads the result and every artifact. Videos and
// files larger than a chunk go up in chunks (PUT with Content-Range), resuming where the server's
// part ends: after a dropped connection, or a later run of the same command.

#include <httplib.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <thread>

#include <nlohmann/json.hpp>

#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/cli/commands.h"
#include "storage/atomic_file.h"
#include "storage/recording.h"
#include "storage/video_container.h"

namespace omnirig::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string Extension(const fs::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

bool IsUploadFile(const fs::path& path) {
  const std::string ext = Extension(path);
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".pgm" ||
         ext == ".ppm" || ext == ".tum" || storage::IsVideoName(path.string()) ||
         storage::IsRecordingName(path.string());
}

// Image, video and recording files (and .tum trajectories, a slam job's ground truth) of `folder` and of
// its direct sub-folders (e.g. cam0/, cam1/), by upload name.
std::map<std::string, fs::path> CollectImages(const fs::path& folder) {
  if (!fs::is_directory(folder)) throw InvalidArgument(folder.string() + " is not a folder");
  std::map<std::string, fs::path> images;
  for (auto it = fs::recursive_directory_iterator(folder); it != fs::recursive_directory_iterator();
       ++it) {
    const std::string leaf = it->path().filename().string();
    if (!leaf.empty() && leaf[0] == '.') {
      if (it->is_directory()) it.disable_recursion_pending();
      continue;
    }
    if (it->is_directory() && it.depth() >= 1) it.disable_recursion_pending();
    if (it->is_regular_file() && IsUploadFile(it->path())) {
      images[fs::relative(it->path(), folder).generic_string()] = it->path();
    }
  }
  return images;
}

// Throws with the server's error message unless the status is one of `ok`.
json Expect(const httplib::Result& result, std::initializer_list<int> ok, const std::string& what) {
  if (!result) throw std::runtime_error(what + ": " + httplib::to_string(result.error()));
  for (int status : ok) {
    if (result->status == status) {
      return result->body.empty() ? json() : json::parse(result->body, nullptr, false);
    }
  }
  const json body = json::parse(result->body, nullptr, false);
  const std::string message = body.is_object() && body.contains("error")
                                  ? body["error"].value("message", result->body)
                                  : result->body;
  throw std::runtime_error(what + ": HTTP " + std::to_string(result->status) + ": " + message);
}

void UploadFile(httplib::Client& client, const std::string& url, const fs::path& path) {
  const auto size = fs::file_size(path);
  auto stream = std::make_shared<std::ifstream>(path, std::ios::binary);
  const auto result = client.Put(
      url.c_str(), size,
      [stream](size_t offset, size_t length, httplib::DataSink& sink) {
        std::vector<char> buffer(std::min<size_t>(length, 1 << 20));
        stream->seekg(static_cast<std::streamoff>(offset));
        stream->read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
        return sink.write(buffer.data(), static_cast<size_t>(stream->gcount()));
      },
      "application/octet-stream");
  Expect(result, {200, 201}, "upload of " + path.string());
}

// One PUT of the whole file, tried 3 times unless the server refuses it (4xx).
void UploadWithRetries(httplib::Client& client, const std::string& url, const fs::path& path) {
  for (int attempt = 1;; ++attempt) {
    try {
      UploadFile(client, url, path);
      return;
    } catch (const std::runtime_error& e) {
      if (attempt == 3 || std::string(e.what()).find("HTTP 4") != std::string::npos) throw;
      std::cerr << "\n" << e.what() << "; retrying\n";
    }
  }
}

// The bytes of `name` the server already holds towards a file of `total` bytes (0 when its
// part is of another size or there is none).
int64_t ReceivedBytes(httplib::Client& client, const std::string& dataset, const std::string& name,
                      int64_t total) {
  const json status =
      Expect(client.Get(("/api/v1/datasets/" + dataset + "/uploads/" + name).c_str()), {200},
             "upload status of " + name);
  const bool same = status["total_bytes"].is_number() && status["total_bytes"] == total;
  return same ? status["received_bytes"].get<int64_t>() : 0;
}

// PUT with Content-Range, chunk by chunk from where the server's part ends. A dropped connection
// or a server error asks the server where it stands and goes on from there (5 times in a row at
// most); a 409 says where the server's part ends.
void UploadInChunks(httplib::Client& client, const std::string& dataset, const std::string& name,
                    const fs::path& path, int64_t chunk_bytes) {
  const int64_t total = static_cast<int64_t>(fs::file_size(path));
  const std::string url = "/api/v1/datasets/" + dataset + "/images/" + name;
  int64_t offset = ReceivedBytes(client, dataset, name, total);
  if (offset > 0) std::cerr << "\rresuming " << name << " at byte " << offset << "\n";
  std::ifstream in(path, std::ios::binary);
  std::string chunk;
  for (int failures = 0;;) {
    const int64_t size = std::min(chunk_bytes, total - offset);
    chunk.resize(static_cast<size_t>(size));
    in.clear();
    in.seekg(static_cast<std::streamoff>(offset));
    in.read(chunk.data(), static_cast<std::streamsize>(size));
    const httplib::Headers range = {{"Content-Range", "bytes " + std::to_string(offset) + "-" +
                                                          std::to_string(offset + size - 1) + "/" +
                                                          std::to_string(total)}};
    const auto result = client.Put(url.c_str(), range, chunk, "application/octet-stream");
    const bool retry = !result || result->status >= 500 || result->status == 409;
    if (retry && ++failures > 5) Expect(result, {202}, "upload of " + path.string());
    if (!result || result->status >= 500) {
      std::this_thread::sleep_for(std::chrono::seconds(1));
      offset = ReceivedBytes(client, dataset, name, total);
      continue;
    }
    if (result->status == 409) {
      const json error = json::parse(result->body, nullptr, false);
      const json& details = error["error"]["details"];
      if (details.contains("received_bytes")) {
        offset = details["received_bytes"].get<int64_t>();
      } else {
        std::this_thread::sleep_for(std::chrono::seconds(1));  // another request holds it
      }
      continue;
    }
    const json body = Expect(result, {200, 201, 202}, "upload of " + path.string());
    if (result->status != 202) return;
    offset = body["received_bytes"].get<int64_t>();
    failures = 0;
  }
}

// Uploads what the server lacks; returns the number of files sent.
int SyncImages(httplib::Client& client, const std::string& dataset,
               const std::map<std::string, fs::path>& images, int64_t chunk_bytes) {
  const json listing =
      Expect(client.Get(("/api/v1/datasets/" + dataset).c_str()), {200}, "dataset " + dataset);
  std::map<std::string, std::pair<int64_t, std::string>> remote;
  for (const json& image : listing["images"]) {
    remote[image["name"]] = {image["size"].get<int64_t>(), image["sha256"]};
  }
  int sent = 0, index = 0;
  int64_t bytes = 0;
  const auto start = std::chrono::steady_clock::now();
  for (const auto& [name, path] : images) {
    ++index;
    const auto it = remote.find(name);
    if (it != remote.end()) {
      const storage::FileDigest local = storage::DigestFile(path);
      if (local.size == it->second.first && local.sha256 == it->second.second) continue;
    }
    const std::string url = "/api/v1/datasets/" + dataset + "/images/" + name;
    if (storage::IsVideoName(path.string()) || storage::IsRecordingName(path.string()) ||
        static_cast<int64_t>(fs::file_size(path)) > chunk_bytes) {
      UploadInChunks(client, dataset, name, path, chunk_bytes);
    } else {
      UploadWithRetries(client, url, path);
    }
    ++sent;
    bytes += static_cast<int64_t>(fs::file_size(path));
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cerr << "\rupload " << index << "/" << images.size() << "  " << sent << " sent, "
              << static_cast<int>(bytes / 1e6 / std::max(seconds, 1e-3)) << " MB/s   "
              << std::flush;
  }
  std::cerr << "\rupload done: " << sent << " sent, " << images.size() - sent
            << " already on the server            \n";
  return sent;
}

void DrawProgress(const json& job) {
  const json& progress = job["progress"];
  const double fraction = progress.value("fraction", 0.0);
  const int filled = static_cast<int>(fraction * 30);
  std::cerr << "\r[" << std::string(filled, '#') << std::string(30 - filled, '.') << "] "
            << static_cast<int>(fraction * 100) << "% " << job["state"].get<std::string>() << " "
            << progress.value("stage", "");
  if (progress["eta_s"].is_number()) {
    std::cerr << " eta " << static_cast<int>(progress["eta_s"].get<double>()) << " s";
  }
  std::cerr << "          " << std::flush;
}

json WaitForJob(httplib::Client& client, const std::string& id) {
  while (true) {
    const json job = Expect(client.Get(("/api/v1/jobs/" + id).c_str()), {200}, "job " + id);
    DrawProgress(job);
    const std::string state = job["state"];
    if (state == "succeeded" || state == "failed" || state == "canceled") {
      std::cerr << "\n";
      return job;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
}

void DownloadArtifacts(httplib::Client& client, const std::string& id, const fs::path& out) {
  const json artifacts =
      Expect(client.Get(("/api/v1/jobs/" + id + "/artifacts").c_str()), {200}, "artifacts");
  for (const json& artifact : artifacts) {
    const std::string name = artifact["name"];
    const auto result = client.Get(("/api/v1/jobs/" + id + "/artifacts/" + name).c_str());
    Expect(result, {200}, "artifact " + name);
    const storage::FileDigest digest = storage::WriteFileAtomically(out / name, result->body);
    if (digest.sha256 != artifact["sha256"]) {
      throw std::runtime_error("artifact " + name + " arrived corrupted (SHA-256 mismatch)");
    }
    std::cerr << "  " << (out / name).string() << " (" << digest.size << " bytes)\n";
  }
}

json ReadParams(const std::string& text) {
  std::string content = text;
  if (!text.empty() && text[0] == '@') {
    std::ifstream in(text.substr(1));
    if (!in) throw InvalidArgument("cannot read params file " + text.substr(1));
    content.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const json params = json::parse(content, nullptr, false);
  if (!params.is_object()) throw InvalidArgument("--params must be a JSON object (or @FILE)");
  return params;
}

void DeclareOptions(ArgParser* parser) {
  parser->SetPositional("FOLDER",
                        "images, at top level or one folder deep (cam0/, cam1/), and "
                        "videos (cam0.mp4 and cam1.mp4, or stacked.mp4)");
  parser->AddOption("chunk-mb", "16",
                    "videos and larger files go up in chunks of this size, resumable (at most "
                    "the server's --max-chunk-mb)");
  parser->AddOption("server", "http://127.0.0.1:8080", "server URL");
  parser->AddOption("token", "", "bearer token (default: $OMNIRIG_TOKEN)");
  parser->AddOption("type", "", "job type: calibration, relative_pose, stereo_reconstruct, slam");
  parser->AddOption("params", "{}", "job params as JSON, or @FILE holding them");
  parser->AddOption("dataset", "", "upload into this existing dataset id instead of a new one");
  parser->AddOption("name", "", "name of the new dataset (default: the folder's name)");
  parser->AddOption("out", "", "folder for result.json and artifacts (default: ./omnirig-JOB)");
  parser->AddFlag("no-wait", "print the job id and return once the job is queued");
}

void Authenticate(const ArgParser& parser, httplib::Client* client) {
  std::string token = parser.Get("token");
  if (token.empty() && std::getenv("OMNIRIG_TOKEN")) token = std::getenv("OMNIRIG_TOKEN");
  if (!token.empty()) client->set_bearer_token_auth(token.c_str());
}

// --dataset, or a new dataset named --name (default: the folder's name).
std::string DatasetId(const ArgParser& parser, const fs::path& folder, httplib::Client& client) {
  if (!parser.Get("dataset").empty()) return parser.Get("dataset");
  std::string name = parser.Get("name");
  if (name.empty()) name = fs::absolute(folder).lexically_normal().filename().string();
  if (name.empty()) name = "dataset";
  return Expect(client.Post("/api/v1/datasets", json{{"name", name}}.dump(), "application/json"),
                {201}, "create dataset")["id"];
}

// The exit code of a finished job, its outcome on stderr.
int ReportOutcome(const json& job, const std::string& id, const fs::path& out) {
  if (job["state"] == "succeeded") {
    std::cerr << "job " << id << " succeeded; results in " << out.string() << "\n";
    return 0;
  }
  std::cerr << "job " << id << " " << job["state"].get<std::string>();
  if (job["error"].is_object()) {
    std::cerr << ": " << job["error"]["code"].get<std::string>() << ": "
              << job["error"]["message"].get<std::string>();
  }
  std::cerr << "\n";
  return 1;
}

}  // namespace

int RunSubmit(const Args& args) {
  ArgParser parser("submit",
                   "Uploads a folder of images or videos to a running omnirig server (resuming: "
                   "files the server already holds are skipped, a video's upload goes on where "
                   "it stopped), runs a job on it, shows its progress and "
                   "downloads the result and artifacts.");
  DeclareOptions(&parser);
  if (!parser.Parse(args)) return parser.exit_code();
  if (parser.positional().size() != 1) throw InvalidArgument("expected one FOLDER (see --help)");
  if (parser.Get("type").empty()) throw InvalidArgument("--type is required");
  const fs::path folder = parser.positional()[0];
  const json params = ReadParams(parser.Get("params"));
  const auto images = CollectImages(folder);

  httplib::Client client(parser.Get("server"));
  client.set_read_timeout(120);
  Authenticate(parser, &client);
  const std::string dataset = DatasetId(parser, folder, client);
  std::cerr << "dataset " << dataset << ": " << images.size() << " image(s) in " << folder << "\n";
  const auto chunk_bytes = static_cast<int64_t>(parser.GetDouble("chunk-mb") * (1 << 20));
  if (chunk_bytes < 1) throw InvalidArgument("--chunk-mb must be positive");
  SyncImages(client, dataset, images, chunk_bytes);
  const json job = Expect(
      client.Post(
          "/api/v1/jobs",
          json{{"type", parser.Get("type")}, {"dataset", dataset}, {"params", params}}.dump(),
          "application/json"),
      {202}, "create job");
  const std::string id = job["id"];
  std::cout << id << std::endl;
  if (parser.Has("no-wait")) return 0;
  const json done = WaitForJob(client, id);
  const fs::path out =
      parser.Get("out").empty() ? fs::path("omnirig-" + id) : fs::path(parser.Get("out"));
  fs::create_directories(out);
  DownloadArtifacts(client, id, out);
  return ReportOutcome(done, id, out);
}

}  // namespace omnirig::cli
