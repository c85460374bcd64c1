// A whole HTTP request (request line, headers, body) as cpp-httplib's server reads it, routed to
// a handler that reads a multipart/form-data body the way POST /api/v1/datasets/{id}/images
// does (server/routes_datasets.cc PostImages): each part with a file name is checked as an
// upload (its name by storage::CheckSafeName, its bytes by server::ImageCheck), part by part
// as httplib hands them over. Any input gets an answer, never a crash: the failures a client
// can cause are HttpError 415/422 of a part or a bad name, and end the reading as the route
// does. The same server also answers a PUT with a Content-Range (server::ParseContentRange).
//
// httplib::Server::process_request is protected for exactly this use (cpp-httplib's own
// server fuzzer drives it the same way): the request comes from memory, the answer is dropped.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include <httplib.h>

#include "fuzz/fuzz_check.h"
#include "server/content_range.h"
#include "server/http.h"
#include "server/upload_check.h"
#include "storage/names.h"
#include "storage/video_container.h"

namespace {

class MemoryStream : public httplib::Stream {
 public:
  MemoryStream(const uint8_t* data, size_t size)
      : data_(reinterpret_cast<const char*>(data)), size_(size) {}
  bool is_readable() const override { return true; }
  bool is_writable() const override { return true; }
  ssize_t read(char* ptr, size_t size) override {
    const size_t n = std::min(size, size_ - offset_);
    std::copy(data_ + offset_, data_ + offset_ + n, ptr);
    offset_ += n;
    return static_cast<ssize_t>(n);
  }
  ssize_t write(const char*, size_t size) override { return static_cast<ssize_t>(size); }
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    ip = "127.0.0.1";
    port = 40000;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    ip = "127.0.0.1";
    port = 8080;
  }
  socket_t socket() const override { return 0; }

 private:
  const char* data_;
  size_t size_;
  size_t offset_ = 0;
};

// The upload route's reading of one part (videos are checked whole, from their file, after
// the body: not here).
class PartCheck {
 public:
  explicit PartCheck(const std::string& filename)
      : name_(omnirig::storage::CheckSafeName(filename)),
        video_(omnirig::storage::IsVideoName(name_)) {}
  void Append(const char* data, size_t size) {
    if (!video_) check_.Append(data, size);
  }
  void End() {
    if (!video_) check_.Finish(name_);
  }

 private:
  std::string name_;
  bool video_;
  omnirig::server::ImageCheck check_;
};

void ReadMultipart(const httplib::ContentReader& reader) {
  std::unique_ptr<PartCheck> part;
  bool failed = false;
  // As server/http.cc's streaming routes: an exception stops the reading and is answered after.
  const auto guarded = [&failed](const auto& callback) {
    try {
      callback();
      return true;
    } catch (const omnirig::server::HttpError& e) {
      FUZZ_CHECK(e.status == 415 || e.status == 422);
    } catch (const std::invalid_argument&) {  // a bad name: 400
    }
    failed = true;
    return false;
  };
  const bool whole = reader(
      [&](const httplib::MultipartFormData& form) {
        return guarded([&] {
          if (part) part->End();
          part.reset();
          if (!form.filename.empty()) part = std::make_unique<PartCheck>(form.filename);
        });
      },
      [&](const char* data, size_t size) {
        return guarded([&] {
          if (part) part->Append(data, size);
        });
      });
  if (whole && !failed && part) guarded([&] { part->End(); });
}

class FuzzServer : public httplib::Server {
 public:
  FuzzServer() {
    Post("/api/v1/datasets/d/images", [](const httplib::Request& req, httplib::Response& res,
                                         const httplib::ContentReader& reader) {
      if (req.is_multipart_form_data()) ReadMultipart(reader);
      res.status = 201;
    });
    Put("/api/v1/datasets/d/images/a.png", [](const httplib::Request& req, httplib::Response& res,
                                              const httplib::ContentReader& reader) {
      try {
        const omnirig::server::ContentRange range =
            omnirig::server::ParseContentRange(req.get_header_value("Content-Range"));
        FUZZ_CHECK(range.length() >= 1);
      } catch (const omnirig::server::HttpError& e) {
        FUZZ_CHECK(e.status == 400);
      }
      reader([](const char*, size_t) { return true; });
      res.status = 200;
    });
  }
  void Process(httplib::Stream& stream) {
    bool closed = false;
    process_request(stream, /*close_connection=*/true, closed, nullptr);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static FuzzServer* server = new FuzzServer;
  MemoryStream stream(data, size);
  server->Process(stream);
  return 0;
}
