#pragma once
// A thin wrapper over cpp-httplib, so that routes never see httplib types and every handler
// runs inside one exception wrapper: whatever a handler throws, the client gets a real status
// code and {"error": {"code", "message", "details"}}. It also checks the bearer token and
// counts requests by route and status for /metrics.

#include <atomic>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

namespace omnirig::server {

// Thrown by handlers for an error response: status 4xx/5xx, a machine-friendly code.
class HttpError : public std::runtime_error {
 public:
  HttpError(int status, std::string code, const std::string& message,
            nlohmann::json details = nlohmann::json::object())
      : std::runtime_error(message),
        status(status),
        code(std::move(code)),
        details(std::move(details)) {}
  int status;
  std::string code;
  nlohmann::json details;
};

// One part of a multipart/form-data body, as announced before its bytes arrive.
struct MultipartPart {
  std::string field;
  std::string filename;
  std::string content_type;
};

struct HttpRequest {
  std::string method;
  std::string path;
  std::map<std::string, std::string> path_params;  // "{id}" -> value
  std::multimap<std::string, std::string> query;
  std::string body;                                       // empty for streaming routes
  std::function<std::string(const std::string&)> header;  // "" when absent
  // Streaming routes only: reads the body chunk by chunk (return false to stop).
  std::function<bool(const std::function<bool(const char*, size_t)>&)> read_body;
  // Streaming routes only: multipart bodies part by part.
  std::function<bool(const std::function<bool(const MultipartPart&)>&,
                     const std::function<bool(const char*, size_t)>&)>
      read_multipart;
  bool is_multipart = false;

  const std::string& Param(const std::string& name) const { return path_params.at(name); }
  std::optional<std::string> Query(const std::string& name) const;
};

struct HttpResponse {
  int status = 200;
  std::multimap<std::string, std::string> headers;
  std::string body;
  std::string content_type = "application/json";
  // When set, the file is streamed instead of `body` (Range requests served by the library).
  std::optional<std::filesystem::path> file;
  int64_t file_size = 0;

  void Json(int status_code, const nlohmann::json& json);
  // A body that is JSON text already (e.g. server/job_json.h).
  void JsonText(int status_code, std::string json_text);
};

using HttpHandler = std::function<void(const HttpRequest&, HttpResponse&)>;

struct HttpServerOptions {
  // Requests served at once. With `event_loop`, a fixed pool of this many threads serves all
  // open connections; without, one thread per open keep-alive connection (connections beyond
  // the threads wait for one; max_connections bounds them all).
  int num_threads = 64;
  // true: idle keep-alive connections wait in one epoll set, not on a thread each (see http.cc).
  bool event_loop = true;
  int keep_alive_timeout_ms = 5000;  // idle keep-alive connections are closed after this
  int read_timeout_ms = 5000;        // a request whose bytes stall this long is dropped
  // After a response to a request whose body the handler left unread ("Connection: close"),
  // what the client still sends is discarded for at most this long (and never beyond the read
  // timeout) before the socket closes, so the client reads the response rather than a reset.
  // The serving thread waits meanwhile: a client that ignores the close must not hold it long.
  int unread_body_linger_ms = 1000;
  int64_t max_body_bytes = 1LL << 30;  // larger bodies are refused (413) before reading
  std::string token;                   // bearer token required under /api/ and /metrics when set
  // Open connections at most (0: no cap), in both loops. A connection beyond it gets a 503
  // (code "unavailable", Retry-After) at once and is closed; the open ones are unaffected. The
  // file descriptors left over stay for SQLite, uploads and artifacts (DefaultMaxConnections).
  int max_connections = 0;
};

// Request counters by (route pattern, status), rendered by Metrics. A connection refused beyond
// max_connections counts as route kRefusedRoute, status 503.
using RequestCounter = std::function<void(const std::string& route, int status, double seconds)>;
inline constexpr const char* kRefusedRoute = "refused";

// Raises the soft limit on open files (RLIMIT_NOFILE) to the hard limit, as far as the kernel
// allows; returns the soft limit in force afterwards.
int64_t RaiseOpenFileLimit();
// The default max_connections under a limit on open files: the limit less a reserve for what
// else the process opens (SQLite's database, WAL and readers, an upload's temporary file or a
// download per request in flight, artifacts written by jobs), at least 16 and at most 4096
// (each open connection also holds a 64 KiB read buffer).
int DefaultMaxConnections(int64_t open_file_limit, int http_threads);

class HttpServer {
 public:
  explicit HttpServer(const HttpServerOptions& options, RequestCounter counter);
  ~HttpServer();

  // Pattern: literal segments and "{name}" (one segment) or "{name+}" (the rest, with '/').
  // `streaming`: the body is not buffered; the handler reads it via read_body/read_multipart.
  void Route(const std::string& method, const std::string& pattern, HttpHandler handler,
             bool streaming = false);
  // Serves files of `dir` under `prefix` ("/" -> index.html); false when dir does not exist.
  bool MountStatic(const std::string& prefix, const std::filesystem::path& dir);

  // Binds (port 0 picks a free one) and returns the bound port; throws on failure.
  int Bind(const std::string& host, int port);
  // Serves on a background thread until Stop().
  void Start();
  void Stop();
  // Connections accepted and not yet closed (idle keep-alive ones included; not the ones
  // refused beyond max_connections), for the /metrics gauge.
  int64_t OpenConnections() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// True for 127.0.0.0/8, ::1 and "localhost".
bool IsLoopbackHost(const std::string& host);

}  // namespace omnirig::server
