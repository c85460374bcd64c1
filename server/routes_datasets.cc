// Datasets and their images: create, list, get, delete; idempotent PUT of one image and
// multipart POST of many, streamed to disk with limits checked before the body is read.

#include <algorithm>
#include <cstdlib>

#include "api/service_json.h"
#include "server/json_views.h"
#include "server/service.h"
#include "storage/atomic_file.h"
#include "storage/image_header.h"
#include "storage/names.h"

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

// One image on its way to disk: streamed into an atomic temporary file while the first bytes
// are kept for the header check; committed (rename + record) only when everything passed.
class ImageUpload {
 public:
  ImageUpload(ServiceState& state, const storage::DatasetRecord& dataset, std::string name)
      : state_(state),
        dataset_(dataset),
        name_(CheckedName(name)),
        writer_(state.data_dir->ImagesDir(dataset.id) / name_) {}

  void Append(const char* data, size_t size) {
    if (writer_.bytes_written() + static_cast<int64_t>(size) > state_.options.max_file_bytes) {
      TooLarge("image " + name_ + " is larger than " +
                   std::to_string(state_.options.max_file_bytes) + " bytes",
               state_.options.max_file_bytes);
    }
    if (head_.size() < storage::kImageProbeBytes) {
      head_.append(data, std::min(size, storage::kImageProbeBytes - head_.size()));
    }
    writer_.Append(data, size);
  }

  storage::ImageRecord Commit() {
    const storage::ImageHeader header = ProbeUpload();
    if (header.status == storage::ImageHeader::Status::kNotAnImage) {
      throw HttpError(415, "unsupported_media_type", name_ + ": " + header.problem,
                      {{"name", name_}});
    }
    if (header.status == storage::ImageHeader::Status::kCorrupt) {
      throw HttpError(422, "corrupt_image", name_ + ": " + header.problem, {{"name", name_}});
    }
    std::lock_guard<std::mutex> lock(state_.files_mutex);
    CheckCount();
    if (!state_.store->GetDataset(dataset_.id)) {
      throw HttpError(404, "dataset_not_found", "dataset " + dataset_.id + " was deleted");
    }
    const storage::FileDigest digest = writer_.Commit();
    storage::ImageRecord image{name_,        digest.size,   digest.sha256,
                               header.width, header.height, header.content_type};
    state_.store->PutImage(dataset_.id, image);
    return image;
  }

 private:
  // Images, and one kind of text file: a ground-truth trajectory in TUM format (NAME.tum) that a
  // slam job can evaluate against; the job parses it and names any bad line.
  storage::ImageHeader ProbeUpload() const {
    const std::string suffix = ".tum";
    if (name_.size() > suffix.size() &&
        name_.compare(name_.size() - suffix.size(), suffix.size(), suffix) == 0) {
      storage::ImageHeader header;
      const bool text = std::all_of(head_.begin(), head_.end(), [](char c) {
        return c == '\n' || c == '\r' || c == '\t' || (c >= 32 && c < 127);
      });
      header.status = text ? storage::ImageHeader::Status::kOk
                           : storage::ImageHeader::Status::kNotAnImage;
      header.format = "tum";
      header.content_type = "text/plain";
      header.problem = text ? "" : "a .tum trajectory must be plain text";
      return header;
    }
    return storage::ProbeImageHeader(head_);
  }

  void CheckCount() {
    const auto current = state_.store->GetDataset(dataset_.id);
    if (current && current->image_count >= state_.options.max_images_per_dataset &&
        !state_.store->GetImage(dataset_.id, name_)) {
      TooLarge("the dataset already holds " + std::to_string(current->image_count) + " images",
               state_.options.max_images_per_dataset);
    }
  }

  ServiceState& state_;
  storage::DatasetRecord dataset_;
  std::string name_;
  storage::AtomicFileWriter writer_;
  std::string head_;
};

void PutImage(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  const std::string name = CheckedName(request.Param("name"));
  const auto length = DeclaredLength(request);
  if (length && *length > state.options.max_file_bytes) {
    TooLarge("image " + name + " is larger than " + std::to_string(state.options.max_file_bytes) +
                 " bytes",
             state.options.max_file_bytes);
  }
  const auto previous = state.store->GetImage(dataset.id, name);
  CheckRoom(state, dataset, length.value_or(0) - (previous ? previous->size : 0));
  ImageUpload upload(state, dataset, name);
  std::exception_ptr failure;
  request.read_body([&](const char* data, size_t size) {
    try {
      upload.Append(data, size);
      return true;
    } catch (...) {
      failure = std::current_exception();
      return false;
    }
  });
  if (failure) std::rethrow_exception(failure);
  const storage::ImageRecord image = upload.Commit();
  response.Json(previous ? 200 : 201, ImageJson(image));
}

void PostImages(ServiceState& state, const HttpRequest& request, HttpResponse& response) {
  const storage::DatasetRecord dataset = RequireDataset(state, request.Param("id"));
  if (!request.is_multipart) {
    throw HttpError(415, "unsupported_media_type",
                    "POST .../images takes multipart/form-data; PUT .../images/{name} takes "
                    "one raw image");
  }
  CheckRoom(state, dataset, DeclaredLength(request).value_or(0));
  std::unique_ptr<ImageUpload> upload;
  std::exception_ptr failure;
  nlohmann::json stored = nlohmann::json::array();
  const auto finish = [&] {
    if (upload) stored.push_back(ImageJson(upload->Commit()));
    upload.reset();
  };
  request.read_multipart(
      [&](const MultipartPart& part) {
        try {
          finish();
          if (part.filename.empty()) return true;  // a plain form field: ignored
          upload = std::make_unique<ImageUpload>(state, dataset, part.filename);
          return true;
        } catch (...) {
          failure = std::current_exception();
          return false;
        }
      },
      [&](const char* data, size_t size) {
        try {
          if (upload) upload->Append(data, size);
          return true;
        } catch (...) {
          failure = std::current_exception();
          return false;
        }
      });
  if (failure) std::rethrow_exception(failure);
  finish();
  response.Json(201, {{"images", stored}});
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
               response.Json(200, DatasetJson(dataset, state.store->ListImages(dataset.id)));
             });
  http.Route("DELETE", "/api/v1/datasets/{id}",
             [&state](const HttpRequest& request, HttpResponse& response) {
               DeleteDataset(state, request, response);
             });
  http.Route(
      "PUT", "/api/v1/datasets/{id}/images/{name+}",
      [&state](const HttpRequest& request, HttpResponse& response) {
        PutImage(state, request, response);
      },
      /*streaming=*/true);
  http.Route(
      "POST", "/api/v1/datasets/{id}/images",
      [&state](const HttpRequest& request, HttpResponse& response) {
        PostImages(state, request, response);
      },
      /*streaming=*/true);
  http.Route("GET", "/api/v1/datasets/{id}/images/{name+}",
             [&state](const HttpRequest& request, HttpResponse& response) {
               GetImage(state, request, response);
             });
}

}  // namespace omnirig::server
