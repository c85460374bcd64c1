// Live slam jobs' routes (live_jobs.h): creation (from POST /api/v1/jobs), frames, finish.

#include <cmath>
#include <cstdlib>
#include <ctime>
#include <future>
#include <set>

#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "api/live_slam.h"
#include "api/service_json.h"
#include "api/slam_job.h"
#include "engine/features/image.h"
#include "engine/slam/video_source.h"
#include "engine/util/check.h"
#include "server/json_views.h"
#include "server/live_jobs.h"
#include "server/service.h"
#include "storage/atomic_file.h"
#include "storage/data_dir.h"
#include "storage/image_header.h"

namespace omnirig::server {
namespace {

using nlohmann::json;

std::string SizeText(int width, int height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

// The rig of a live job: `rig` must name a succeeded relative_pose job (404 / 422 otherwise,
// as for any job that reads one).
StereoRig RequireRig(ServiceState& state, const std::string& rig_job) {
  const auto job = state.store->GetJob(rig_job);
  if (!job) {
    throw HttpError(404, "job_not_found", "referenced job " + rig_job + " does not exist",
                    {{"job", rig_job}, {"field", "rig"}});
  }
  if (job->type != "relative_pose" || job->state != storage::JobState::kSucceeded) {
    throw HttpError(422, job->type != "relative_pose" ? "wrong_job_type" : "dependency_not_ready",
                    "job " + rig_job + " is a " + storage::JobStateName(job->state) + " " +
                        job->type +
                        " job, but a slam job needs a succeeded relative_pose job "
                        "in 'rig'",
                    {{"job", rig_job}, {"field", "rig"}});
  }
  try {
    return api::LoadRig(
        [&state](const std::string& id) {
          const auto result = state.store->GetResult(id);
          if (!result) throw InvalidArgument("job " + id + " has no result");
          return json::parse(*result);
        },
        rig_job);
  } catch (const InvalidArgument& e) {
    throw HttpError(422, "invalid_input", e.what(), {{"job", rig_job}, {"field", "rig"}});
  }
}

// One part of a frame's multipart body, whole in memory (a frame is a few MB at most).
struct FramePart {
  std::string field, filename, bytes;
};

std::map<std::string, FramePart> ReadFrameParts(ServiceState& state, const HttpRequest& request) {
  if (!request.is_multipart) {
    throw HttpError(415, "unsupported_media_type",
                    "frames are multipart/form-data: parts cam0 and cam1 (or stacked) and stamp");
  }
  std::map<std::string, FramePart> parts;
  FramePart* current = nullptr;
  const int64_t limit = state.options.max_file_bytes;
  const bool whole = request.read_multipart(
      [&](const MultipartPart& part) {
        const std::set<std::string> known = {"cam0", "cam1", "stacked", "stamp"};
        if (!known.count(part.field)) {
          throw HttpError(400, "invalid_argument",
                          "unknown part '" + part.field + "' (cam0, cam1, stacked, stamp)");
        }
        current = &parts[part.field];
        current->field = part.field;
        current->filename = part.filename;
        current->bytes.clear();
        return true;
      },
      [&](const char* data, size_t size) {
        if (!current) return true;
        if (static_cast<int64_t>(current->bytes.size() + size) > limit) {
          throw HttpError(
              413, "payload_too_large",
              "part " + current->field + " is larger than " + std::to_string(limit) + " bytes",
              {{"limit_bytes", limit}});
        }
        current->bytes.append(data, size);
        return true;
      });
  if (!whole) throw HttpError(400, "incomplete_body", "the multipart body ended early");
  return parts;
}

double ParseStamp(const std::map<std::string, FramePart>& parts) {
  const auto it = parts.find("stamp");
  if (it == parts.end()) {
    throw HttpError(400, "invalid_argument", "missing part 'stamp' (capture time in seconds)");
  }
  const std::string& text = it->second.bytes;
  char* end = nullptr;
  const double stamp = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(stamp) || stamp < 0) {
    throw HttpError(400, "invalid_argument",
                    "part 'stamp' must be a non-negative number of seconds, not '" + text + "'");
  }
  return stamp;
}

// The header of an image part: PNG, JPEG or PGM/PPM, whole (415 / 422 otherwise).
storage::ImageHeader CheckImagePart(const FramePart& part) {
  const std::string& bytes = part.bytes;
  const storage::ImageHeader header = storage::ProbeImageHeader(
      std::string_view(bytes).substr(0, std::min(bytes.size(), storage::kImageProbeBytes)));
  if (header.status == storage::ImageHeader::Status::kNotAnImage ||
      (header.format != "png" && header.format != "jpeg" && header.format != "pnm")) {
    throw HttpError(415, "unsupported_media_type",
                    "part " + part.field + " is not a PNG, JPEG or PGM/PPM image" +
                        (header.problem.empty() ? "" : ": " + header.problem),
                    {{"part", part.field}});
  }
  std::string problem =
      header.status == storage::ImageHeader::Status::kCorrupt ? header.problem : "";
  if (problem.empty()) {
    storage::ImageCompletenessCheck check;
    check.Append(bytes.data(), bytes.size());
    problem = check.Finish(header, bytes);
  }
  if (!problem.empty()) {
    throw HttpError(422, "corrupt_image", "part " + part.field + ": " + problem,
                    {{"part", part.field}});
  }
  return header;
}

[[noreturn]] void WrongSize(const std::string& what, int width, int height,
                            const std::string& expected_what, int expected_width,
                            int expected_height) {
  throw HttpError(
      422, "frame_size_mismatch",
      what + " is " + SizeText(width, height) + " but " + expected_what + " is " +
          SizeText(expected_width, expected_height),
      {{"size", {width, height}}, {"expected_size", {expected_width, expected_height}}});
}

std::string Extension(const storage::ImageHeader& header, int channels_hint) {
  if (header.format == "png") return ".png";
  if (header.format == "jpeg") return ".jpg";
  return channels_hint == 1 ? ".pgm" : ".ppm";
}

// A frame ready for the job: its files (name in the dataset, bytes) and the mailbox's frame.
struct PreparedFrame {
  std::vector<std::pair<std::string, std::string>> files;
  std::shared_ptr<api::LiveFrame> frame;
};

// Checks the parts against the rig and prepares the files: cam0/NAME.EXT and cam1/NAME.EXT as
// sent, or a stacked image split into two PNGs (decoded here: the dataset holds camera pairs).
PreparedFrame PrepareFrame(const std::map<std::string, FramePart>& parts, const StereoRig& rig,
                           const std::string& stem) {
  PreparedFrame prepared;
  prepared.frame = std::make_shared<api::LiveFrame>();
  const CameraModel* camera[2] = {&rig.cam0, &rig.cam1};
  const bool stacked = parts.count("stacked") > 0;
  if (stacked == (parts.count("cam0") > 0 || parts.count("cam1") > 0) ||
      (!stacked && (!parts.count("cam0") || !parts.count("cam1")))) {
    throw HttpError(400, "invalid_argument",
                    "a frame is parts cam0 and cam1, or one part stacked (cam0 on top)");
  }
  if (!stacked) {
    std::string extension[2];
    for (int c = 0; c < 2; ++c) {
      const FramePart& part = parts.at("cam" + std::to_string(c));
      const storage::ImageHeader header = CheckImagePart(part);
      if (header.width != camera[c]->width || header.height != camera[c]->height) {
        WrongSize("cam" + std::to_string(c) + "'s image", header.width, header.height,
                  "the rig's cam" + std::to_string(c) + " calibration", camera[c]->width,
                  camera[c]->height);
      }
      const bool grey = part.bytes.size() > 1 && part.bytes[0] == 'P' &&
                        (part.bytes[1] == '5' || part.bytes[1] == '2');
      extension[c] = Extension(header, grey ? 1 : 3);
      prepared.files.push_back({"cam" + std::to_string(c) + "/" + stem + extension[c], part.bytes});
      prepared.frame->encoded[c] = part.bytes;
    }
    // The dataset pairs cam0/NAME with cam1/NAME: one name, one format.
    if (extension[0] != extension[1]) {
      throw HttpError(400, "invalid_argument",
                      "cam0 and cam1 must be of one format (got " + extension[0] + " and " +
                          extension[1] + ")");
    }
    prepared.frame->name = stem + extension[0];
    // Not decoded here: the job decodes the frames it tracks, in the front end that runs beside
    // the back end of the frame before, so a frame skipped for a newer one costs its storing
    // only. One that does not decode is refused there (422 invalid_frame) after it is stored,
    // as any frame the job cannot track.
    return prepared;
  }
  const FramePart& part = parts.at("stacked");
  const storage::ImageHeader header = CheckImagePart(part);
  const int width = rig.cam0.width, height = rig.cam0.height + rig.cam1.height;
  if (rig.cam0.width != rig.cam1.width || header.width != width || header.height != height) {
    WrongSize("the stacked image", header.width, header.height,
              "the rig's cam0 above cam1 (calibrations " +
                  SizeText(rig.cam0.width, rig.cam0.height) + " and " +
                  SizeText(rig.cam1.width, rig.cam1.height) + ")",
              width, height);
  }
  const cv::Mat buffer(1, static_cast<int>(part.bytes.size()), CV_8U,
                       const_cast<char*>(part.bytes.data()));
  const cv::Mat image = cv::imdecode(buffer, cv::IMREAD_COLOR);
  if (image.empty()) {
    throw HttpError(422, "corrupt_image", "part stacked cannot be decoded", {{"part", "stacked"}});
  }
  for (int c = 0; c < 2; ++c) {
    const cv::Mat half =
        image.rowRange(c == 0 ? 0 : rig.cam0.height, c == 0 ? rig.cam0.height : height).clone();
    std::vector<uchar> png;
    cv::imencode(".png", half, png);
    prepared.files.push_back(
        {"cam" + std::to_string(c) + "/" + stem + ".png", std::string(png.begin(), png.end())});
    prepared.frame->decoded[c] = half;
  }
  prepared.frame->name = stem + ".png";
  return prepared;
}

// Refuses, before anything is written, a frame the disk cannot hold above the reserve the
// server keeps (507, as an upload gets): the job goes on and takes frames again once space
// returns.
void CheckFrameRoom(ServiceState& state, int64_t incoming) {
  const int64_t free_bytes = state.data_dir->FreeBytes();
  if (free_bytes - incoming < state.options.min_free_bytes) {
    throw HttpError(507, "insufficient_storage",
                    "not enough free disk space to store this frame: free some space and send "
                    "the next frames; the job goes on",
                    {{"free_bytes", free_bytes},
                     {"reserve_bytes", state.options.min_free_bytes},
                     {"frame_bytes", incoming}});
  }
}

int64_t FrameBytes(const std::vector<std::pair<std::string, std::string>>& files) {
  int64_t bytes = 0;
  for (const auto& file : files) bytes += static_cast<int64_t>(file.second.size());
  return bytes;
}

// Stores the frame's files in the dataset (written, fsynced, renamed, recorded together): a
// frame that cannot be stored whole leaves nothing behind.
void StoreFrame(ServiceState& state, const std::string& dataset_id,
                const std::vector<std::pair<std::string, std::string>>& files) {
  CheckFrameRoom(state, FrameBytes(files));
  std::vector<std::unique_ptr<storage::AtomicFileWriter>> writers;
  std::vector<storage::ImageRecord> records;
  std::vector<std::filesystem::path> committed;
  try {
    for (const auto& [name, bytes] : files) {
      writers.push_back(std::make_unique<storage::AtomicFileWriter>(
          state.data_dir->ImagesDir(dataset_id) / name));
      writers.back()->Append(bytes);
      const storage::FileDigest digest = writers.back()->Seal();
      const storage::ImageHeader header = storage::ProbeImageHeader(
          std::string_view(bytes).substr(0, std::min(bytes.size(), storage::kImageProbeBytes)));
      records.push_back(
          {name, digest.size, digest.sha256, header.width, header.height, header.content_type});
    }
    std::lock_guard<std::mutex> lock(state.files_mutex);
    const auto dataset = state.store->GetDataset(dataset_id);
    if (!dataset) {
      throw HttpError(409, "dataset_not_found",
                      "the live job's dataset " + dataset_id + " was deleted");
    }
    if (dataset->image_count + 2 > state.options.max_images_per_dataset) {
      throw HttpError(413, "too_many_images",
                      "dataset " + dataset_id + " holds the most images a dataset may hold (" +
                          std::to_string(state.options.max_images_per_dataset) + ")",
                      {{"limit", state.options.max_images_per_dataset}});
    }
    for (size_t i = 0; i < writers.size(); ++i) {
      writers[i]->Commit(/*sync_folder=*/true);
      committed.push_back(state.data_dir->ImagesDir(dataset_id) / files[i].first);
    }
    state.store->PutImages(dataset_id, records);
  } catch (const std::exception& e) {
    // Neither camera's file stays without the other and its record.
    std::error_code ignored;
    for (const auto& path : committed) std::filesystem::remove(path, ignored);
    if (dynamic_cast<const HttpError*>(&e) || !storage::IsDiskFull(e)) throw;
    throw HttpError(507, "insufficient_storage",
                    "the disk holding the data folder is full: the frame was not stored; free "
                    "some space and send the next frames; the job goes on",
                    {{"reason", e.what()}});
  }
}

bool IsLiveRecord(const storage::JobRecord& record) {
  if (record.type != "slam") return false;
  const nlohmann::json params = nlohmann::json::parse(record.params, nullptr, false);
  return params.is_object() && params.contains("live") && params["live"] == true;
}

std::shared_ptr<LiveJob> RequireLiveJob(ServiceState& state, const std::string& id) {
  const auto record = state.store->GetJob(id);
  if (!record) throw HttpError(404, "job_not_found", "no job " + id);
  std::shared_ptr<LiveJob> job = state.live->Find(id);
  if (!job && record->state != storage::JobState::kRunning && IsLiveRecord(*record)) {
    // A live job that ended here and was forgotten (LiveJobs::Start), or ended in another process.
    throw HttpError(409, "job_finished",
                    "live job " + id + " has ended (" + storage::JobStateName(record->state) +
                        "): it takes no more frames",
                    {{"state", storage::JobStateName(record->state)}});
  }
  if (!job) {
    throw HttpError(409, "job_not_live",
                    "job " + id + " is not a live job running in this server (it is a " +
                        storage::JobStateName(record->state) + " " + record->type + " job)",
                    {{"state", storage::JobStateName(record->state)}});
  }
  if (job->ended || record->state != storage::JobState::kRunning) {
    throw HttpError(409, "job_finished",
                    "live job " + id + " has ended (" + storage::JobStateName(record->state) +
                        "): it takes no more frames",
                    {{"state", storage::JobStateName(record->state)}});
  }
  return job;
}

void PostFrame(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const auto received = std::chrono::steady_clock::now();
  const std::shared_ptr<LiveJob> job = RequireLiveJob(state, request.Param("id"));
  const std::map<std::string, FramePart> parts = ReadFrameParts(state, request);
  const double stamp_s = ParseStamp(parts);
  std::future<api::LiveAnswer> answer;
  {
    std::lock_guard<std::mutex> lock(job->frames_mutex);
    const std::string name = slam::FrameName(stamp_s);
    if (job->last_stamp_s && (stamp_s <= *job->last_stamp_s || name == job->last_name)) {
      throw HttpError(409, "stamp_not_increasing",
                      "stamp " + std::to_string(stamp_s) + " s is not after the last frame's, " +
                          std::to_string(*job->last_stamp_s) +
                          " s (frames are named by their stamp to the millisecond)",
                      {{"stamp_s", stamp_s},
                       {"last_stamp_s", *job->last_stamp_s},
                       {"last_name", job->last_name}});
    }
    PreparedFrame prepared = PrepareFrame(parts, job->rig, name);
    if (job->ended) {
      throw HttpError(409, "job_finished", "live job " + job->record.id + " has ended");
    }
    // A frame the disk cannot hold is refused before the job sees it.
    CheckFrameRoom(state, FrameBytes(prepared.files));
    prepared.frame->stamp_s = stamp_s;
    prepared.frame->received = received;
    answer = prepared.frame->answer.get_future();
    // The job takes the frame at once and runs its front end (decoding, features) while the
    // files are written and synced here; it tracks the frame only once they are stored.
    std::promise<void> stored;
    prepared.frame->stored = stored.get_future().share();
    const bool handed_over = job->mailbox.Put(prepared.frame);
    try {
      StoreFrame(state, job->record.dataset_id, prepared.files);
      stored.set_value();
    } catch (...) {
      stored.set_exception(std::current_exception());
      throw;
    }
    job->last_stamp_s = stamp_s;
    job->last_name = name;
    if (!handed_over) {
      throw HttpError(409, "job_finished",
                      "live job " + job->record.id +
                          " is finishing: the frame was stored in "
                          "its dataset but not tracked");
    }
  }
  // The job's thread answers: tracked, skipped for a newer frame, or refused. A job that ends
  // without answering (it should not) leaves the sender a 409, not an error of the server.
  try {
    const api::LiveAnswer result = answer.get();
    response.Json(result.status, result.body);
  } catch (const std::future_error&) {
    throw HttpError(409, "job_finished",
                    "live job " + job->record.id +
                        " ended before this frame was tracked: the frame is stored in its dataset",
                    {{"job", job->record.id}});
  }
}

void FinishLiveJob(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const std::shared_ptr<LiveJob> job = RequireLiveJob(state, id);
  job->mailbox.RequestFinish();
  const auto record = state.store->GetJob(id);
  response.Json(202, JobJson(*record));
}

}  // namespace

bool CreateLiveJob(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const api::CreateJobRequest parsed = api::ParseCreateJobRequest(request.body);
  if (parsed.type != "slam") return false;
  try {
    if (!api::IsLiveSlam(parsed.params)) return false;
    api::LiveSlamParamsFromJson(parsed.params);
  } catch (const InvalidArgument& e) {
    throw HttpError(400, "invalid_params", e.what());
  }
  const StereoRig rig = RequireRig(state, parsed.params.at("rig").get<std::string>());
  // A saved map to localise in ("map"), refused as a batch job refuses it.
  if (const api::JobType* type = state.job_types.Find("slam")) {
    CheckReferencedJobs(state, *type, parsed.params);
  }
  try {
    api::CheckSlamMap(parsed.params, [&state](const std::string& id) {
      const auto result = state.store->GetResult(id);
      if (!result) throw InvalidArgument("job " + id + " has no result");
      return nlohmann::json::parse(*result);
    });
  } catch (const InvalidArgument& e) {
    throw HttpError(422, "invalid_input", e.what(), {{"field", "map"}});
  }
  std::string dataset_id = parsed.dataset;
  if (dataset_id.empty()) {
    // The robot's recording: a dataset of its own, named by the start time.
    const std::time_t now = std::time(nullptr);
    std::tm utc{};
    gmtime_r(&now, &utc);
    char name[64];
    std::strftime(name, sizeof(name), "live %Y-%m-%d %H:%M:%S", &utc);
    dataset_id = state.store->CreateDataset(name).id;
  } else if (!state.store->GetDataset(dataset_id)) {
    throw HttpError(404, "dataset_not_found", "no dataset " + dataset_id,
                    {{"dataset", dataset_id}});
  }
  const storage::JobRecord job = state.live->Start(dataset_id, parsed.params, rig);
  state.events->Changed(job.id);
  response.headers.emplace("Location", "/api/v1/jobs/" + job.id);
  response.Json(202, JobJson(job));
  return true;
}

void AddLiveRoutes(HttpServer& http, ServiceState& state) {
  http.Route("POST", "/api/v1/jobs/{id}/frames", WithState(state, PostFrame),
             /*streaming=*/true);
  http.Route("POST", "/api/v1/jobs/{id}/finish", WithState(state, FinishLiveJob));
}

}  // namespace omnirig::server
