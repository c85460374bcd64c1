// Datasets and their files (images, videos, recordings, .tum trajectories): create, list, get,
// delete;
// idempotent PUT of one file, resumable PUT of a large one in chunks (Content-Range), and
// multipart POST of many, streamed to disk with limits checked before the body is read.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <set>

#include "api/service_json.h"
#include "server/content_range.h"
#include "server/dataset_recordings.h"
#include "server/json_views.h"
#include "server/service.h"
#include "server/upload_check.h"
#include "storage/atomic_file.h"
#include "storage/image_header.h"
#include "storage/names.h"
#include "storage/recording.h"
#include "storage/upload_part.h"
#include "storage/video_container.h"

namespace omnirig::server {
namespace {

storage::DatasetRecord RequireDataset(ServiceState& state, const std::string& id) {
  auto dataset = state.store->GetDataset(id);
  if (!dataset) throw HttpError(404, "dataset_not_found", "no dataset " + id);
  return *dataset;
}

std::string CheckedName(const std::string& name) {
  try {
    return storage::CheckSafeName(name);
  } catch (const std::invalid_argument& e) {
    throw HttpError(400, "invalid_name", e.what(), {{"name", name}});
  }
}

// Declared body size from Content-Length; nullopt for chunked bodies.
std::optional<int64_t> DeclaredLength(const HttpRequest& request) {
  const std::string value = request.header("Content-Length");
  if (value.empty()) return std::nullopt;
  return std::strtoll(value.c_str(), nullptr, 10);
}

[[noreturn]] void TooLarge(const std::string& message, int64_t limit) {
  throw HttpError(413, "payload_too_large", message, {{"limit_bytes", limit}});
}

// Refuses, before reading, a body that cannot fit the dataset or the disk.
void CheckRoom(ServiceState& state, const storage::DatasetRecord& dataset, int64_t incoming) {
  const auto& options = state.options;
  if (dataset.total_bytes + incoming > options.max_dataset_bytes) {
    TooLarge("the dataset would exceed " + std::to_string(options.max_dataset_bytes) + " bytes",
             options.max_dataset_bytes);
  }
  if (state.data_dir->FreeBytes() - incoming < options.min_free_bytes) {
    throw HttpError(
        507, "insufficient_storage", "not enough free disk space for this upload",
        {{"free_bytes", state.data_dir->FreeBytes()}, {"reserve_bytes", options.min_free_bytes}});
  }
}

[[noreturn]] void TooManyImages(const storage::DatasetRecord& dataset, int64_t limit,
                                nlohmann::json details = nlohmann::json::object()) {
  details["limit_images"] = limit;
  throw HttpError(413, "payload_too_large",
                  "the dataset already holds " + std::to_string(dataset.image_count) +
                      " images, the most it may hold",
                  details);
}

// The dataset as it is now, under files_mutex: 404 when it was deleted during the upload.
storage::DatasetRecord CurrentDataset(ServiceState& state, const std::string& id) {
  auto dataset = state.store->GetDataset(id);
  if (!dataset) throw HttpError(404, "dataset_not_found", "dataset " + id + " was deleted");
  return *dataset;
}

// Videos and recordings: files that take no place among the dataset's images.
bool IsStreamName(const std::string& name) {
  return storage::IsVideoName(name) || storage::IsRecordingName(name);
}

// The largest upload of a file of this name: videos and recordings (gigabytes) have their own.
int64_t MaxFileBytes(const ServiceState& state, const std::string& name) {
  return IsStreamName(name) ? state.options.max_video_bytes : state.options.max_file_bytes;
}

// The record of a video whose bytes are at `path` (415 when it is no container omnirig reads,
// 422 when its structure is incomplete; storage/video_container.h). Width and height stay 0:
// only the job's decoder knows them.
storage::ImageRecord VideoRecord(const std::string& name, const std::filesystem::path& path,
                                 const storage::FileDigest& digest) {
  const storage::VideoContainer video = storage::CheckVideoContainer(path);
  if (video.status == storage::VideoContainer::Status::kNotAVideo) {
    throw HttpError(415, "unsupported_media_type", name + ": " + video.problem, {{"name", name}});
  }
  if (video.status == storage::VideoContainer::Status::kCorrupt) {
    throw HttpError(422, "corrupt_video", name + ": " + video.problem, {{"name", name}});
  }
  return storage::ImageRecord{name, digest.size, digest.sha256, 0, 0, video.content_type};
}

// Under files_mutex: 413 when a new image would exceed the dataset's image limit (videos,
// recordings and files replacing one of the same name take no new place).
void CheckImageLimit(ServiceState& state, const std::string& dataset_id, const std::string& name) {
  const storage::DatasetRecord current = CurrentDataset(state, dataset_id);
  if (!IsStreamName(name) && current.image_count >= state.options.max_images_per_dataset &&
      !state.store->GetImage(dataset_id, name)) {
    TooManyImages(current, state.options.max_images_per_dataset);
  }
}

// One image on its way to disk: streamed into an atomic temporary file while the first bytes
// are kept for the header check; sealed (fsynced under its temporary name) once it passed, and
// put into place (rename) with its record only when everything passed.
class ImageUpload {
 public:
  ImageUpload(ServiceState& state, const storage::DatasetRecord& dataset, std::string name)
      : state_(state),
        dataset_(dataset),
        name_(CheckedName(name)),
        writer_(state.data_dir->ImagesDir(dataset.id) / name_) {}

  void Append(const char* data, size_t size) {
    const int64_t limit = MaxFileBytes(state_, name_);
    if (writer_.bytes_written() + static_cast<int64_t>(size) > limit) {
      TooLarge(name_ + " is larger than " + std::to_string(limit) + " bytes", limit);
    }
    writer_.Append(data, size);
    if (!video_ && !recording_) check_.Append(data, size);
  }

  // Checks the header (415 or 422 for what is not an image) and seals the file: written and
  // fsynced under its temporary name, holding no descriptor. Returns the record it will have.
  const storage::ImageRecord& Seal() {
    if (recording_) {
      const storage::FileDigest digest = writer_.Seal();
      checked_recording_ = CheckRecordingUpload(name_, writer_.temp_path(), digest);
      record_ = checked_recording_.record;
      return record_;
    }
    if (video_) {
      const storage::FileDigest digest = writer_.Seal();
      record_ = VideoRecord(name_, writer_.temp_path(), digest);
      return record_;
    }
    const storage::ImageHeader header = check_.Finish(name_);
    const storage::FileDigest digest = writer_.Seal();
    record_ = {name_, digest.size, digest.sha256, header.width, header.height, header.content_type};
    return record_;
  }
  // Renames the sealed file into place; `sync_folder` false when the caller fsyncs the folder.
  void Publish(bool sync_folder) { writer_.Commit(sync_folder); }

  // PUT: seal, then under files_mutex check the dataset and its image limit, put the file into
  // place and write its record.
  storage::ImageRecord Commit() {
    Seal();
    std::lock_guard<std::mutex> lock(state_.files_mutex);
    CheckImageLimit(state_, dataset_.id, name_);
    Publish(/*sync_folder=*/true);
    state_.store->PutImage(dataset_.id, record_);
    KeepIndex();
    return record_;
  }
  // After the record is stored: a recording's index (under files_mutex).
  void KeepIndex() {
    if (recording_) KeepRecordingIndex(state_, dataset_.id, name_, checked_recording_);
  }

  const std::string& name() const { return name_; }
  const storage::ImageRecord& record() const { return record_; }
  const std::filesystem::path& final_path() const { return writer_.final_path(); }

 private:
  ServiceState& state_;
  storage::DatasetRecord dataset_;
  std::string name_;
  storage::AtomicFileWriter writer_;
  bool video_ = storage::IsVideoName(name_);
  bool recording_ = storage::IsRecordingName(name_);
  CheckedRecording checked_recording_;  // set by Seal() for recordings
  ImageCheck check_;
  storage::ImageRecord record_;  // set by Seal()
};

// The files of one multipart request: each sealed when its part ends, all committed together
// by Commit(). Whatever is not committed is removed (temporary files) when the batch ends.
class ImageBatch {
 public:
  ImageBatch(ServiceState& state, const storage::DatasetRecord& dataset)
      : state_(state), dataset_(dataset) {}

  // A part with a file name starts; the previous one ended whole.
  void Begin(const std::string& file_name) {
    End();
    current_ = std::make_unique<ImageUpload>(state_, dataset_, file_name);
  }
  void Append(const char* data, size_t size) {
    if (current_) current_->Append(data, size);
  }
  // The current part ended whole: sealed into the batch (or it throws and is dropped).
  void End() {
    if (!current_) return;
    std::unique_ptr<ImageUpload> upload = std::move(current_);
    upload->Seal();
    sealed_.push_back(std::move(upload));
  }
  // The current part was cut short: dropped.
  void Abandon() { current_.reset(); }

  // Puts the sealed files into place, in order, as many as the dataset's image limit allows
  // (the names of the rest go to `over_limit`), fsyncs each folder once and writes their
  // records in one transaction. Returns the records stored.
  std::vector<storage::ImageRecord> Commit(std::vector<std::string>& over_limit);

 private:
  // Drops from sealed_ what exceeds the image limit; returns the names without a record yet.
  std::set<std::string> KeepWhatFits(std::vector<std::string>& over_limit);

  ServiceState& state_;
  storage::DatasetRecord dataset_;
  std::unique_ptr<ImageUpload> current_;
  std::vector<std::unique_ptr<ImageUpload>> sealed_;
};

std::set<std::string> ImageBatch::KeepWhatFits(std::vector<std::string>& over_limit) {
  const storage::DatasetRecord current = CurrentDataset(state_, dataset_.id);
  // A name stored before, or earlier in the batch, takes no new place in the dataset.
  std::set<std::string> new_names;
  int64_t count = current.image_count;
  size_t fitting = 0;
  for (; fitting < sealed_.size(); ++fitting) {
    const std::string& name = sealed_[fitting]->name();
    if (new_names.count(name) || state_.store->GetImage(dataset_.id, name)) continue;
    if (!IsStreamName(name)) {
      if (count >= state_.options.max_images_per_dataset) break;
      ++count;
    }
    new_names.insert(name);
  }
  for (size_t i = fitting; i < sealed_.size(); ++i) over_limit.push_back(sealed_[i]->name());
  sealed_.resize(fitting);  // removes the temporary files of the rest
  return new_names;
}

std::vector<storage::ImageRecord> ImageBatch::Commit(std::vector<std::string>& over_limit) {
  std::vector<storage::ImageRecord> records;
  if (sealed_.empty()) return records;
  // Deletion of the dataset waits for this lock: the files and records land in a live dataset.
  std::lock_guard<std::mutex> lock(state_.files_mutex);
  const std::set<std::string> new_names = KeepWhatFits(over_limit);
  size_t published = 0;
  try {
    std::set<std::filesystem::path> folders;
    for (; published < sealed_.size(); ++published) {
      sealed_[published]->Publish(/*sync_folder=*/false);
      folders.insert(sealed_[published]->final_path().parent_path());
      records.push_back(sealed_[published]->record());
    }
    for (const auto& folder : folders) storage::FsyncPath(folder);
    state_.store->PutImages(dataset_.id, records);
    for (const auto& upload : sealed_) upload->KeepIndex();
  } catch (...) {
    // No record may describe another file than its own: the new files go, and the records of
    // the files this batch replaced go with them (the client uploads those again).
    for (size_t i = 0; i < published; ++i) {
      const std::string& name = sealed_[i]->name();
      std::error_code ignored;
      if (new_names.count(name)) {
        std::filesystem::remove(sealed_[i]->final_path(), ignored);
      } else {
        try {
          state_.store->DeleteImage(dataset_.id, name);
        } catch (const std::exception&) {
          // The start-up consistency check drops a record whose file has another size.
        }
      }
    }
    throw;
  }
  return records;
}

// ---- resumable uploads (PUT with Content-Range; storage/upload_part.h) -----------------------

std::filesystem::path UploadsDir(const ServiceState& state, const std::string& dataset_id) {
  return state.data_dir->DatasetDir(dataset_id) / "uploads";
}

// What the server holds of an upload, as JSON (and its Upload-Offset header).
nlohmann::json UploadStatusJson(const std::string& name, const storage::UploadPartStatus& part,
                                const std::optional<storage::ImageRecord>& stored) {
  return {{"name", name},
          {"received_bytes", part.received_bytes},
          {"total_bytes", part.total_bytes ? nlohmann::json(*part.total_bytes) : nullptr},
          {"stored", stored ? ImageJson(*stored) : nlohmann::json(nullptr)}};
}

}  // namespace

// Read once, in blocks.
storage::ImageRecord CheckCompleteFile(const std::string& name, const std::filesystem::path& path) {
  const storage::FileDigest digest = storage::DigestFile(path);
  if (storage::IsVideoName(name)) return VideoRecord(name, path, digest);
  if (storage::IsRecordingName(name)) return CheckRecordingUpload(name, path, digest).record;
  std::ifstream in(path, std::ios::binary);
  std::string block(1 << 20, '\0');
  ImageCheck check;
  while (in.read(block.data(), static_cast<std::streamsize>(block.size())) || in.gcount() > 0) {
    check.Append(block.data(), static_cast<size_t>(in.gcount()));
  }
  const storage::ImageHeader header = check.Finish(name);
  return {name, digest.size, digest.sha256, header.width, header.height, header.content_type};
}

namespace {

// The checks of a chunk before its body is read: sizes (413 with the limit), the declared
// length, the dataset's room.
void CheckChunk(ServiceState& state, const storage::DatasetRecord& dataset, const std::string& name,
                const ContentRange& range, const HttpRequest& request) {
  const int64_t limit = MaxFileBytes(state, name);
  if (range.total > limit)
    TooLarge(name + " is larger than " + std::to_string(limit) + " bytes", limit);
  if (range.length() > state.options.max_chunk_bytes) {
    TooLarge("a chunk of " + std::to_string(range.length()) + " bytes is larger than the " +
                 std::to_string(state.options.max_chunk_bytes) +
                 " bytes this server takes at once: send the file in smaller chunks",
             state.options.max_chunk_bytes);
  }
  const auto length = DeclaredLength(request);
  if (length && *length != range.length()) {
    throw HttpError(400, "invalid_argument",
                    "Content-Length " + std::to_string(*length) + " differs from the " +
                        std::to_string(range.length()) + " bytes of the Content-Range");
  }
  CheckRoom(state, dataset, range.total - range.first);
}

[[noreturn]] void OffsetMismatch(const std::string& name, int64_t have, int64_t total,
                                 int64_t first) {
  HttpError error(409, "upload_offset_mismatch",
                  "the server has " + std::to_string(have) + " bytes of " + name +
                      ", but this chunk starts at byte " + std::to_string(first) +
                      ": send the chunk that starts at " + std::to_string(have),
                  {{"name", name}, {"received_bytes", have}, {"total_bytes", total}});
  error.headers.emplace("Upload-Offset", std::to_string(have));
  throw error;
}

// The part is whole: check it, rename it into the images folder and record it.
void CompleteUpload(ServiceState& state, const std::string& dataset_id, const std::string& name,
                    storage::UploadPartWriter& part, HttpResponse& response) {
  part.Sync();
  CheckedRecording checked;
  storage::ImageRecord record;
  try {
    if (storage::IsRecordingName(name)) {
      checked = CheckRecordingUpload(name, part.path(), storage::DigestFile(part.path()));
      record = checked.record;
    } else {
      record = CheckCompleteFile(name, part.path());
    }
  } catch (const HttpError&) {
    part.Remove();  // refused content: the client starts over
    throw;
  }
  std::lock_guard<std::mutex> lock(state.files_mutex);
  CheckImageLimit(state, dataset_id, name);
  const bool replaced = state.store->GetImage(dataset_id, name).has_value();
  part.Publish(state.data_dir->ImagesDir(dataset_id) / name);
  state.store->PutImage(dataset_id, record);
  if (storage::IsRecordingName(name)) KeepRecordingIndex(state, dataset_id, name, checked);
  response.Json(replaced ? 200 : 201, ImageJson(record));
}

// PUT .../images/{name} with Content-Range: appends the chunk to the upload's part when it
// starts where the part ends (409 with the part's size otherwise); 202 with the size while
// incomplete; the last chunk publishes the file (201/200 as a plain PUT, or its 415/422).
// A chunk at byte 0 starts the upload over. A body cut short keeps what arrived.
void PutChunk(ServiceState& state, const storage::DatasetRecord& dataset, const std::string& name,
              const HttpRequest& request, HttpResponse& response) {
  const ContentRange range = ParseContentRange(request.header("Content-Range"));
  CheckChunk(state, dataset, name, range, request);
  const std::filesystem::path uploads = UploadsDir(state, dataset.id);
  if (range.first == 0) {
    storage::RemoveUploadParts(uploads, name, range.total);
  } else if (const auto held = storage::FindUploadPart(uploads, name);
             held.total_bytes && *held.total_bytes != range.total) {
    OffsetMismatch(name, 0, range.total, range.first);  // another file's part: start over
  }
  std::optional<storage::UploadPartWriter> part;
  try {
    part.emplace(uploads, name, range.total);
  } catch (const storage::UploadBusy& e) {
    throw HttpError(409, "upload_busy", e.what(), {{"name", name}});
  }
  if (range.first == 0) part->Truncate();
  if (part->size() != range.first) OffsetMismatch(name, part->size(), range.total, range.first);
  bool whole = false;
  try {
    whole = request.read_body([&](const char* data, size_t size) {
      if (part->size() + static_cast<int64_t>(size) > range.last + 1) {
        throw HttpError(400, "invalid_argument", "the body is longer than its Content-Range");
      }
      part->Append(data, size);
      return true;
    });
  } catch (...) {
    part->Sync();  // what arrived before the failure stays
    throw;
  }
  part->Sync();
  if (!whole || part->size() != range.last + 1) {
    throw HttpError(400, "incomplete_body",
                    "the chunk ended after " + std::to_string(part->size() - range.first) + " of " +
                        std::to_string(range.length()) + " bytes; the server keeps them",
                    {{"received_bytes", part->size()}});
  }
  if (part->size() == range.total) return CompleteUpload(state, dataset.id, name, *part, response);
  response.headers.emplace("Upload-Offset", std::to_string(part->size()));
  response.Json(202, UploadStatusJson(name, {part->size(), range.total}, std::nullopt));
}

void GetUpload(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  const std::string name = CheckedName(request.Param("name"));
  const storage::UploadPartStatus part =
      storage::FindUploadPart(UploadsDir(state, dataset.id), name);
  response.headers.emplace("Upload-Offset", std::to_string(part.received_bytes));
  response.headers.emplace("Cache-Control", "no-store");
  response.Json(200, UploadStatusJson(name, part, state.store->GetImage(dataset.id, name)));
}

void DeleteUpload(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  const std::string name = CheckedName(request.Param("name"));
  if (storage::RemoveUploadParts(UploadsDir(state, dataset.id), name) == 0) {
    throw HttpError(404, "upload_not_found", "no upload of " + name + " in progress");
  }
  response.status = 204;
}

void PutImage(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  const std::string name = CheckedName(request.Param("name"));
  if (!request.header("Content-Range").empty())
    return PutChunk(state, dataset, name, request, response);
  const auto length = DeclaredLength(request);
  if (length && *length > MaxFileBytes(state, name)) {
    TooLarge(name + " is larger than " + std::to_string(MaxFileBytes(state, name)) + " bytes",
             MaxFileBytes(state, name));
  }
  const auto previous = state.store->GetImage(dataset.id, name);
  CheckRoom(state, dataset, length.value_or(0) - (previous ? previous->size : 0));
  ImageUpload upload(state, dataset, name);
  request.read_body([&](const char* data, size_t size) {
    upload.Append(data, size);
    return true;
  });
  const storage::ImageRecord image = upload.Commit();
  response.Json(previous ? 200 : 201, ImageJson(image));
}

// Rethrows the failure of a multipart upload as an HttpError whose details name the files
// that were stored all the same.
[[noreturn]] void RethrowWithStored(const std::exception_ptr& failure,
                                    const nlohmann::json& stored_names) {
  try {
    std::rethrow_exception(failure);
  } catch (HttpError& e) {
    e.details["stored"] = stored_names;
    throw;
  } catch (const storage::StoreUnavailable&) {
    throw;  // 503: the client sends the request again, as a whole
  } catch (const std::exception& e) {
    if (storage::IsDiskFull(e)) {
      throw HttpError(507, "insufficient_storage",
                      "the disk holding the data folder is full; free some space and send the "
                      "files not stored again",
                      {{"stored", stored_names}, {"reason", e.what()}});
    }
    throw HttpError(500, "internal", e.what(), {{"stored", stored_names}});
  }
}

// POST .../images, multipart/form-data, one image per part (the filename is the name). Each
// part streams to a temporary file, sealed (fsynced) when the part ends whole; then all the
// request's files are committed together: renamed into place, each folder fsynced once, and
// their records written in one transaction (JobStore::PutImages). A file and its record are
// never stored one without the other. A request that fails half-way keeps what it completed,
// as PUTs one by one would (and as this route did when it committed file by file): the files
// whose parts ended whole and passed their checks before the failure are stored, the failed
// part and everything after it are not, and the error's details name the stored files
// ("stored"), so that the client sends the rest, as it resumes from the dataset's listing. The
// failures: a bad name (400), not an image (415, 422), a file too large (413), the image limit
// (413 with "over_limit": the files beyond it), a body that ends early (400 "incomplete_body"; a
// dropped connection hears nothing, its listing shows what was stored).
void PostImages(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  if (!request.is_multipart) {
    throw HttpError(415, "unsupported_media_type",
                    "POST .../images takes multipart/form-data; PUT .../images/{name} takes "
                    "one raw image");
  }
  CheckRoom(state, dataset, DeclaredLength(request).value_or(0));
  ImageBatch batch(state, dataset);
  std::exception_ptr failure;
  bool whole = false;
  try {
    whole = request.read_multipart(
        [&](const MultipartPart& part) {
          batch.End();
          if (!part.filename.empty()) batch.Begin(part.filename);  // else a form field: ignored
          return true;
        },
        [&](const char* data, size_t size) {
          batch.Append(data, size);
          return true;
        });
    if (whole) batch.End();
  } catch (...) {
    failure = std::current_exception();
  }
  if (!whole || failure) batch.Abandon();
  std::vector<std::string> over_limit;
  const std::vector<storage::ImageRecord> stored = batch.Commit(over_limit);
  nlohmann::json stored_names = nlohmann::json::array();
  nlohmann::json images = nlohmann::json::array();
  for (const auto& image : stored) {
    stored_names.push_back(image.name);
    images.push_back(ImageJson(image));
  }
  if (failure) RethrowWithStored(failure, stored_names);
  if (!whole) {
    throw HttpError(400, "incomplete_body", "the multipart body ended before its last boundary",
                    {{"stored", stored_names}});
  }
  if (!over_limit.empty()) {
    TooManyImages(CurrentDataset(state, dataset.id), state.options.max_images_per_dataset,
                  {{"stored", stored_names}, {"over_limit", over_limit}});
  }
  response.Json(201, {{"images", images}});
}

void GetImage(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  const auto image = state.store->GetImage(id, request.Param("name"));
  if (!image) throw HttpError(404, "image_not_found", "no image " + request.Param("name"));
  response.headers.emplace("ETag", "\"" + image->sha256 + "\"");
  if (request.header("If-None-Match") == "\"" + image->sha256 + "\"") {
    response.status = 304;
    return;
  }
  response.headers.emplace("Cache-Control", "private, max-age=60");
  response.content_type = image->content_type;
  response.file = state.data_dir->ImagesDir(id) / image->name;
  response.file_size = image->size;
}

// GET .../images: every file of the dataset by name, with its camera folder.
void ListImages(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  nlohmann::json list = nlohmann::json::array();
  for (const auto& image : state.store->ListImages(dataset.id)) list.push_back(ImageJson(image));
  response.Json(200, list);
}

// DELETE .../images/{name} (a name may hold its camera folder: cam0/x.png): the record goes
// first, so that no listing or job sees a record without its file; a crash before the file
// goes leaves a file no record names, which an upload of that name replaces. 409 while a
// queued or running job uses the dataset (it reads the images it listed when it started).
void DeleteImage(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  const std::string name = CheckedName(request.Param("name"));
  // Uploads commit under this lock: none lands between the checks and the removal.
  std::lock_guard<std::mutex> lock(state.files_mutex);
  if (!state.store->GetImage(dataset.id, name)) {
    throw HttpError(404, "image_not_found", "dataset " + dataset.id + " has no file " + name,
                    {{"dataset", dataset.id}, {"name", name}});
  }
  if (const int64_t active = state.store->CountActiveJobs(dataset.id); active > 0) {
    throw HttpError(409, "dataset_in_use",
                    "dataset " + dataset.id + " has " + std::to_string(active) +
                        " queued or running job(s): remove " + name + " once they ended",
                    {{"active_jobs", active}, {"name", name}});
  }
  state.store->DeleteImage(dataset.id, name);
  const std::filesystem::path images = state.data_dir->ImagesDir(dataset.id);
  std::error_code ignored;
  std::filesystem::remove(images / name, ignored);
  // An emptied camera folder goes too (remove() leaves a folder that still holds files).
  if (const auto folder = (images / name).parent_path(); folder != images) {
    std::filesystem::remove(folder, ignored);
  }
  response.status = 204;
}

void DeleteDataset(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const std::string& id = request.Param("id");
  RequireDataset(state, id);
  if (const int64_t active = state.store->CountActiveJobs(id); active > 0) {
    throw HttpError(
        409, "dataset_in_use",
        "dataset " + id + " has " + std::to_string(active) + " queued or running job(s)",
        {{"active_jobs", active}});
  }
  std::lock_guard<std::mutex> lock(state.files_mutex);
  state.store->DeleteDataset(id);
  std::error_code ignored;
  std::filesystem::remove_all(state.data_dir->DatasetDir(id), ignored);
  response.status = 204;
  response.body.clear();
}

}  // namespace

void AddDatasetRoutes(HttpServer& http, ServiceState& state) {
  http.Route(
      "POST", "/api/v1/datasets", [&state](const HttpRequest& request, HttpResponse& response) {
        const api::CreateDatasetRequest parsed = api::ParseCreateDatasetRequest(request.body);
        const storage::DatasetRecord dataset = state.store->CreateDataset(parsed.name);
        response.headers.emplace("Location", "/api/v1/datasets/" + dataset.id);
        response.Json(201, DatasetJson(dataset, {}));
      });
  http.Route("GET", "/api/v1/datasets", [&state](const HttpRequest&, HttpResponse& response) {
    nlohmann::json list = nlohmann::json::array();
    for (const auto& dataset : state.store->ListDatasets()) list.push_back(DatasetJson(dataset));
    response.Json(200, list);
  });
  http.Route("GET", "/api/v1/datasets/{id}",
             [&state](const HttpRequest& request, HttpResponse& response) {
               const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
               const auto images = state.store->ListImages(dataset.id);
               nlohmann::json json = DatasetJson(dataset, images);
               json["recordings"] = RecordingsJson(state, dataset.id, images);
               response.Json(200, json);
             });
  http.Route("DELETE", "/api/v1/datasets/{id}", WithState(state, DeleteDataset));
  http.Route("PUT", "/api/v1/datasets/{id}/images/{name+}", WithState(state, PutImage),
             /*streaming=*/true);
  http.Route("POST", "/api/v1/datasets/{id}/images", WithState(state, PostImages),
             /*streaming=*/true);
  http.Route("GET", "/api/v1/datasets/{id}/uploads/{name+}", WithState(state, GetUpload));
  http.Route("DELETE", "/api/v1/datasets/{id}/uploads/{name+}", WithState(state, DeleteUpload));
  http.Route("GET", "/api/v1/datasets/{id}/images", WithState(state, ListImages));
  http.Route("GET", "/api/v1/datasets/{id}/images/{name+}", WithState(state, GetImage));
  http.Route("DELETE", "/api/v1/datasets/{id}/images/{name+}", WithState(state, DeleteImage));
}

}  // namespace omnirig::server
