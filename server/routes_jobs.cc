// Jobs: create (validated by the job type), list, get (with ETag), cancel, delete, retry, result
// and artifacts (with Content-Length, ETag and Range), and their changes as Server-Sent Events.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "api/job_types.h"
#include "api/service_json.h"
#include "api/stereo_job.h"
#include "engine/util/check.h"
#include "server/dataset_recordings.h"
#include "server/json_views.h"
#include "server/live_jobs.h"
#include "server/log_line.h"
#include "server/service.h"
#include "server/zip_stream.h"
#include "storage/image_header.h"

namespace omnirig::server {
namespace {

storage::JobRecord RequireJob(ServiceState& state, const std::string& id) {
  auto job = state.store->GetJob(id);
  if (!job) throw HttpError(404, "job_not_found", "no job " + id);
  return std::move(*job);
}

// The result of a succeeded job; 409 for a job in any other state.
std::string RequireResult(ServiceState& state, const storage::JobRecord& job) {
  auto result =
      job.state == storage::JobState::kSucceeded ? state.store->GetResult(job.id) : std::nullopt;
  if (!result) {
    throw HttpError(409, "job_not_succeeded",
                    "job " + job.id + " has no result: it is " + storage::JobStateName(job.state),
                    {{"state", storage::JobStateName(job.state)}});
  }
  return std::move(*result);
}

// The job type's own check of the inputs (e.g. images of another size than the rig's
// calibration, videos that do not pair), on what the files' headers tell: no decoding here.
void CheckInputs(ServiceState& state, const api::JobType& type,
                 const api::CreateJobRequest& request) {
  if (!type.check_inputs) return;
  api::SubmissionInputs inputs;
  inputs.dataset_id = request.dataset;
  inputs.dataset_dir = state.data_dir->ImagesDir(request.dataset);
  for (const storage::ImageRecord& image : state.store->ListImages(request.dataset)) {
    inputs.images.push_back({image.name, image.width, image.height});
  }
  std::sort(inputs.images.begin(), inputs.images.end(),
            [](const auto& a, const auto& b) { return a.name < b.name; });
  inputs.load_result = [&state](const std::string& id) {
    const auto result = state.store->GetResult(id);
    if (!result) throw InvalidArgument("job " + id + " has no result");
    return nlohmann::json::parse(*result);
  };
  inputs.open_recording = [&inputs](const std::string& name) {
    return OpenDatasetRecording(inputs.dataset_dir, inputs.file_names(), name);
  };
  try {
    type.check_inputs(request.params, inputs);
  } catch (const InvalidArgument& e) {
    throw HttpError(422, "invalid_input", e.what(), {{"dataset", request.dataset}});
  }
}

void CreateJob(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  if (CreateLiveJob(state, request, response)) return;  // runs here, fed by its frames route
  const api::CreateJobRequest parsed = api::ParseCreateJobRequest(request.body);
  const api::JobType* type = state.job_types.Find(parsed.type);
  if (!type) {
    const auto known = state.job_types.Names();
    std::string list;
    for (const auto& name : known) list += (list.empty() ? "" : ", ") + name;
    throw HttpError(
        400, "unknown_job_type",
        "unknown job type '" + parsed.type + "' (known: " + (list.empty() ? "none" : list) + ")",
        {{"known_types", known}});
  }
  const auto dataset = state.store->GetDataset(parsed.dataset);
  if (!dataset) {
    throw HttpError(404, "dataset_not_found", "no dataset " + parsed.dataset,
                    {{"dataset", parsed.dataset}});
  }
  try {
    if (type->validate) type->validate(parsed.params);
  } catch (const InvalidArgument& e) {
    throw HttpError(400, "invalid_params", e.what());
  }
  CheckReferencedJobs(state, *type, parsed.params);
  // A job on an empty dataset would be queued only to fail once it ran (a job naming a
  // recording or its topics finds out whether the dataset holds them in its own check).
  const bool names_recording =
      parsed.params.is_object() && (parsed.params.contains("recording") ||
                                    parsed.params.contains("topic") || parsed.params.contains("topics"));
  if (type->reads_images && dataset->image_count + dataset->video_count == 0 && !names_recording) {
    std::vector<std::string> file_names;
    for (const auto& image : state.store->ListImages(parsed.dataset)) file_names.push_back(image.name);
    const std::vector<std::string> recordings = RecordingNames(file_names);
    std::string message = "dataset " + parsed.dataset + " has no images: upload them before creating a job";
    if (!recordings.empty()) {
      message = "dataset " + parsed.dataset + " has no images but the recording " + recordings[0] +
                ": name it with \"recording\" and its image topics (\"topic\" for a calibration, "
                "\"topics\": {\"cam0\": ..., \"cam1\": ...} for the stereo jobs)";
    }
    throw HttpError(422, "dataset_empty", message, {{"dataset", parsed.dataset}});
  }
  CheckInputs(state, *type, parsed);
  const int64_t queued = state.store->CountJobsByState().at(storage::JobState::kQueued);
  if (queued >= state.options.max_queued_jobs) {
    response.headers.emplace("Retry-After", "10");
    throw HttpError(503, "queue_full",
                    "the queue already holds " + std::to_string(queued) + " jobs",
                    {{"limit", state.options.max_queued_jobs}});
  }
  const storage::JobRecord job =
      state.store->CreateJob(parsed.type, parsed.dataset, parsed.params.dump());
  LogJobState(job, {{"dataset", job.dataset_id}});
  state.workers->Notify();
  state.events->Changed(job.id);
  response.headers.emplace("Location", "/api/v1/jobs/" + job.id);
  response.Json(202, JobJson(job));
}

void ListJobs(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  storage::JobFilter filter;
  if (const auto state_name = request.Query("state")) {
    filter.state = storage::ParseJobState(*state_name);
    if (!filter.state) {
      throw HttpError(
          400, "invalid_argument",
          "unknown state '" + *state_name + "' (queued, running, succeeded, failed, canceled)");
    }
  }
  filter.type = request.Query("type");
  filter.dataset_id = request.Query("dataset");
  if (const auto limit = request.Query("limit")) {
    char* end = nullptr;
    const long value = std::strtol(limit->c_str(), &end, 10);
    if (end == limit->c_str() || *end != '\0' || value < 1 || value > 10000) {
      throw HttpError(400, "invalid_argument", "limit must be an integer in [1, 10000]");
    }
    filter.limit = static_cast<int>(value);
  }
  nlohmann::json list = nlohmann::json::array();
  for (const storage::JobRecord& job : state.store->ListJobs(filter)) list.push_back(JobJson(job));
  response.Json(200, list);
}

void CancelJob(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const storage::JobRecord before = RequireJob(state, id);
  if (storage::IsTerminal(before.state)) {
    throw HttpError(409, "job_finished",
                    "job " + id + " already " + storage::JobStateName(before.state),
                    {{"state", storage::JobStateName(before.state)}});
  }
  const auto after = state.store->RequestCancel(id);
  if (after == storage::JobState::kRunning) state.workers->Cancel(id);
  if (after == storage::JobState::kCanceled) {
    LogJobState(id, before.type, "canceled", before.attempts, {{"reason", "canceled while queued"}});
  }
  state.events->Changed(id);
  response.Json(after == storage::JobState::kRunning ? 202 : 200, JobJson(RequireJob(state, id)));
}

void DeleteJob(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const storage::JobRecord job = RequireJob(state, id);
  if (job.state == storage::JobState::kRunning || !state.store->DeleteJob(id)) {
    throw HttpError(409, "job_running", "job " + id + " is running: cancel it first");
  }
  std::error_code ignored;
  std::filesystem::remove_all(state.data_dir->JobDir(id), ignored);
  LogJobState(id, job.type, "deleted", job.attempts);
  state.events->Changed(id);
  response.status = 204;
}

void RetryJob(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const storage::JobRecord job = RequireJob(state, id);
  if (!state.store->GetDataset(job.dataset_id)) {
    throw HttpError(
        409, "dataset_not_found",
        "job " + id + " cannot run again: its dataset " + job.dataset_id + " was deleted");
  }
  if (!state.store->RetryJob(id)) {
    throw HttpError(409, "job_not_retryable",
                    "only failed or canceled jobs are retried; job " + id + " is " +
                        storage::JobStateName(job.state),
                    {{"state", storage::JobStateName(job.state)}});
  }
  // Read before the workers are told: the reply shows the job back in the queue (a worker of
  // another process, or one polling, may still claim it first: then it says "running").
  const storage::JobRecord requeued = RequireJob(state, id);
  LogJobState(id, requeued.type, "queued", requeued.attempts, {{"reason", "retry"}});
  state.workers->Notify();
  state.events->Changed(id);
  response.Json(202, JobJson(requeued));
}

void GetResult(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const std::string result = RequireResult(state, RequireJob(state, id));
  response.content_type = "application/json";
  response.body = result;
}

// The log of a job that has not ended yet: the running attempt's log.txt as written so far
// (JobLog flushes every line). It becomes a recorded artifact, with a hash, when the job ends.
bool ServeLiveLog(ServiceState& state, const storage::JobRecord& job, HttpResponse& response) {
  if (storage::IsTerminal(job.state) || job.attempts < 1) return false;
  const std::filesystem::path path = state.data_dir->AttemptDir(job.id, job.attempts) / "log.txt";
  std::error_code error;
  const auto size = std::filesystem::file_size(path, error);
  if (error) return false;
  response.headers.emplace("Cache-Control", "no-store");
  response.headers.emplace("Accept-Ranges", "bytes");
  response.content_type = storage::ContentTypeForName("log.txt");
  response.file = path;
  response.file_size = static_cast<int64_t>(size);
  return true;
}

void GetArtifact(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const storage::JobRecord job = RequireJob(state, id);
  const std::string& name = request.Param("name");
  for (const storage::ArtifactRecord& artifact : state.store->ListArtifacts(id)) {
    if (artifact.name != name) continue;
    const std::string etag = "\"" + artifact.sha256 + "\"";
    response.headers.emplace("ETag", etag);
    response.headers.emplace("Accept-Ranges", "bytes");
    if (request.header("If-None-Match") == etag) {
      response.status = 304;
      return;
    }
    response.content_type = artifact.content_type;
    response.file = state.data_dir->root() / artifact.path;
    response.file_size = artifact.size;
    return;
  }
  if (name == "log.txt" && ServeLiveLog(state, job, response)) return;
  if (state.live->ServeArtifact(id, name, response)) return;  // a live job's map so far
  throw HttpError(404, "artifact_not_found", "job " + id + " has no artifact " + name);
}

// GET .../artifacts.zip: every artifact of a job that ended, in one archive streamed as it is
// read from disk (server/zip_stream.h); 409 while the job has not ended (its artifacts are
// recorded when it does).
void GetArtifactsZip(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::JobRecord job = RequireJob(state, request.Param("id"));
  if (!storage::IsTerminal(job.state)) {
    throw HttpError(409, "job_not_finished",
                    "job " + job.id + " is " + storage::JobStateName(job.state) +
                        ": its artifacts are recorded when it ends",
                    {{"state", storage::JobStateName(job.state)}});
  }
  std::vector<ZipEntry> entries;
  for (const storage::ArtifactRecord& artifact : state.store->ListArtifacts(job.id)) {
    entries.push_back(
        {artifact.name, state.data_dir->root() / artifact.path, artifact.size, artifact.sha256});
  }
  auto zip = std::make_shared<ZipStream>(std::move(entries));
  response.content_type = "application/zip";
  response.headers.emplace("Content-Disposition",
                           "attachment; filename=\"" + job.type + "-" + job.id + ".zip\"");
  response.headers.emplace("Cache-Control", "no-store");
  response.stream = [zip](std::string& chunk) { return zip->Next(chunk); };
}

double RequiredNumber(const HttpRequest& request, const std::string& name) {
  const auto text = request.Query(name);
  if (!text) throw HttpError(400, "invalid_argument", "missing query parameter '" + name + "'");
  char* end = nullptr;
  const double value = std::strtod(text->c_str(), &end);
  if (end == text->c_str() || *end != '\0' || !std::isfinite(value)) {
    throw HttpError(400, "invalid_argument", "query parameter '" + name + "' must be a number");
  }
  return value;
}

// The epipolar curve of a pixel, for a succeeded relative_pose job (api/stereo_job.h).
void GetEpipolar(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const storage::JobRecord job = RequireJob(state, id);
  if (job.type != "relative_pose") {
    throw HttpError(400, "invalid_argument",
                    "epipolar curves need a relative_pose job; job " + id + " is " + job.type);
  }
  const std::string result = RequireResult(state, job);
  const std::string from = request.Query("from").value_or("cam0");
  if (from != "cam0" && from != "cam1") {
    throw HttpError(400, "invalid_argument", "query parameter 'from' must be cam0 or cam1");
  }
  const double u = RequiredNumber(request, "u");
  const double v = RequiredNumber(request, "v");
  try {
    response.Json(
        200, api::EpipolarCurveJson(nlohmann::json::parse(result), from == "cam0" ? 0 : 1, u, v));
  } catch (const InvalidArgument& e) {
    // The request was checked above: what is left is the stored result, a broken invariant.
    throw std::runtime_error("the result of job " + id + " holds no usable rig: " + e.what());
  }
}

// 64-bit FNV-1a of the text, as a strong ETag.
std::string ETagOf(const std::string& text) {
  uint64_t hash = 14695981039346656037ULL;
  for (const char c : text) hash = (hash ^ static_cast<unsigned char>(c)) * 1099511628211ULL;
  char tag[24];
  std::snprintf(tag, sizeof(tag), "\"%016llx\"", static_cast<unsigned long long>(hash));
  return tag;
}

// A job poll: with If-None-Match holding the ETag of the job as it is now, 304 and no body.
void GetJob(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  response.Json(200, JobJson(RequireJob(state, request.Param("id"))));
  const std::string etag = ETagOf(response.body);
  response.headers.emplace("ETag", etag);
  response.headers.emplace("Cache-Control", "no-cache");
  if (request.header("If-None-Match").find(etag) != std::string::npos) {
    response.status = 304;
    response.body.clear();
  }
}

// Server-Sent Events: every job's changes, or one job's with ?job=ID (server/events.h). A
// comment line every 15 s keeps proxies from closing a quiet stream and finds closed clients.
void StreamEvents(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  auto stream = std::make_shared<JobEvents::Stream>(*state.events, request.Query("job"));
  auto quiet_ms = std::make_shared<int>(0);
  response.content_type = "text/event-stream";
  response.headers.emplace("Cache-Control", "no-cache");
  response.headers.emplace("X-Accel-Buffering", "no");
  // The first chunk goes out at once: the client sees the stream open.
  auto opened = std::make_shared<bool>(false);
  response.stream = [stream, quiet_ms, opened](std::string& chunk) {
    if (!*opened) {
      *opened = true;
      chunk = "retry: 1000\n\n";
      return true;
    }
    constexpr int kWaitMs = 1000, kHeartbeatMs = 15000;
    if (!stream->Next(chunk, kWaitMs)) return false;
    *quiet_ms = chunk.empty() ? *quiet_ms + kWaitMs : 0;
    if (*quiet_ms >= kHeartbeatMs) {
      chunk = ": keep-alive\n\n";
      *quiet_ms = 0;
    }
    return true;
  };
}

}  // namespace

// A job that reads an earlier job's result is refused at submission (422, with the reason)
// unless that job exists, is of the type it reads and has succeeded: queued, it could only fail.
void CheckReferencedJobs(ServiceState& state, const api::JobType& type,
                         const nlohmann::json& params) {
  if (!type.referenced_jobs) return;
  for (const api::JobReference& reference : type.referenced_jobs(params)) {
    const std::string& id = reference.id;
    const auto job = state.store->GetJob(id);
    if (!job) {
      throw HttpError(404, "job_not_found", "referenced job " + id + " does not exist",
                      {{"job", id}, {"field", reference.field}});
    }
    const std::string& wanted = reference.type;
    const std::string there = " job in '" + reference.field + "'";
    if (!wanted.empty() && job->type != wanted) {
      throw HttpError(422, "wrong_job_type",
                      "job " + id + " is a " + job->type + " job, but a " + type.name +
                          " job needs a succeeded " + wanted + there,
                      {{"job", id},
                       {"type", job->type},
                       {"expected_type", wanted},
                       {"field", reference.field}});
    }
    if (job->state != storage::JobState::kSucceeded) {
      throw HttpError(
          422, "dependency_not_ready",
          "job " + id + " is " + storage::JobStateName(job->state) + ", but a " + type.name +
              " job needs a succeeded " + (wanted.empty() ? job->type : wanted) + there,
          {{"job", id}, {"state", storage::JobStateName(job->state)}, {"field", reference.field}});
    }
  }
}

void AddJobRoutes(HttpServer& http, ServiceState& state) {
  http.Route("POST", "/api/v1/jobs", WithState(state, CreateJob));
  http.Route("GET", "/api/v1/jobs", WithState(state, ListJobs));
  http.Route("GET", "/api/v1/jobs/{id}", WithState(state, GetJob));
  http.Route("GET", "/api/v1/events", WithState(state, StreamEvents));
  http.Route("POST", "/api/v1/jobs/{id}/cancel", WithState(state, CancelJob));
  http.Route("DELETE", "/api/v1/jobs/{id}", WithState(state, DeleteJob));
  http.Route("POST", "/api/v1/jobs/{id}/retry", WithState(state, RetryJob));
  http.Route("GET", "/api/v1/jobs/{id}/result", WithState(state, GetResult));
  http.Route("GET", "/api/v1/jobs/{id}/artifacts",
             [&state](const HttpRequest& request, HttpResponse& response) {
               RequireJob(state, request.Param("id"));
               nlohmann::json list = nlohmann::json::array();
               for (const auto& artifact : state.store->ListArtifacts(request.Param("id"))) {
                 list.push_back(ArtifactJson(artifact));
               }
               response.Json(200, list);
             });
  http.Route("GET", "/api/v1/jobs/{id}/artifacts.zip", WithState(state, GetArtifactsZip));
  http.Route("GET", "/api/v1/jobs/{id}/artifacts/{name+}", WithState(state, GetArtifact));
  http.Route("GET", "/api/v1/jobs/{id}/epipolar", WithState(state, GetEpipolar));
}

}  // namespace omnirig::server
