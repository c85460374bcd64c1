#pragma once
// A thin wrapper over cpp-httplib (its public API only), so that routes never see httplib
// types and every handler runs inside one exception wrapper: whatever a handler throws, the
// client gets a real status code and {"error": {"code", "message", "details"}} (HttpError: its
// status; omnirig::InvalidArgument, a caller's mistake: 400; anything else, a broken
// invariant: 500 and a line in the log). It also routes (one router: segments, see Route),
// checks the bearer token and counts requests by route and status for /metrics.

#include <atomic>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

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
  // Sent with the error (e.g. a resumable upload's Upload-Offset on 409).
  std::multimap<std::string, std::string> headers;
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
  // Streaming routes only: reads the body chunk by chunk (return false to stop); true when it
  // was read to its end. An exception the callback throws stops the reading and comes out here.
  std::function<bool(const std::function<bool(const char*, size_t)>&)> read_body;
  // Streaming routes only: multipart bodies part by part (exceptions as read_body's).
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
  // When set, the body is streamed instead of `body` (chunked; e.g. Server-Sent Events): called
  // again and again on the serving thread, it may block, appends what to send next to `chunk`
  // (nothing is fine) and returns false to end the response. When it throws, the connection
  // closes without the terminating chunk (the client sees an incomplete transfer).
  std::function<bool(std::string& chunk)> stream;

  void Json(int status_code, const nlohmann::json& json);
};

using HttpHandler = std::function<void(const HttpRequest&, HttpResponse&)>;

struct HttpServerOptions {
  // cpp-httplib's thread pool: one thread per open connection while it is open (an idle
  // keep-alive connection holds its thread until the keep-alive timeout), so size it for the
  // keep-alive clients; connections beyond the threads wait for one.
  int num_threads = 64;
  int keep_alive_timeout_ms = 5000;  // idle keep-alive connections are closed after this (whole s)
  int read_timeout_ms = 5000;        // a request whose bytes stall this long is dropped
  // A body the handler left unread is read and discarded for at most this long (or until it
  // stalls for the read timeout) before the response, so that the connection stays usable; a
  // body that takes longer closes it ("Connection: close"), and the rest is never parsed as
  // requests.
  int unread_body_linger_ms = 1000;
  int64_t max_body_bytes = 1LL << 30;  // larger bodies are refused (413) before reading
  std::string token;                   // bearer token required under /api/ and /metrics when set
  // Open connections at most (0: no cap). A connection beyond it gets a 503 (code
  // "unavailable", Retry-After) in answer to its first request and is closed; the open ones are
  // unaffected. The file descriptors left over stay for SQLite, uploads and artifacts
  // (DefaultMaxConnections).
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

  // Pattern: '/'-separated literal segments and "{name}" (one non-empty segment) or "{name+}"
  // (the non-empty rest, with '/'; last only). Routes are tried in the order registered and
  // take precedence over static files. HEAD is served by the GET route.
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
  // Connections accepted and not yet closed (idle keep-alive ones and those waiting for a
  // thread included; not the ones refused beyond max_connections), for the /metrics gauge.
  int64_t OpenConnections() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// True for 127.0.0.0/8, ::1 and "localhost".
bool IsLoopbackHost(const std::string& host);

}  // namespace omnirig::server
