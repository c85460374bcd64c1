#include "server/http.h"

#include <dirent.h>
#include <httplib.h>
#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <thread>
#include <utility>
#include <vector>

#include "api/service_json.h"
#include "engine/util/check.h"
#include "server/log_line.h"
#include "storage/data_dir.h"
#include "storage/job_store.h"

namespace omnirig::server {
namespace {

// The route pattern and start time of the request this connection thread is serving, for the
// request counter (httplib calls the logger on the same thread after the response).
thread_local std::string current_route;
thread_local std::chrono::steady_clock::time_point request_start;
// Set on the threads that serve connections beyond max_connections (ConnectionQueue).
thread_local bool refusing_connection = false;

// One '/'-separated piece of a route pattern.
struct Segment {
  enum Kind { kLiteral, kParam, kRest } kind = kLiteral;
  std::string literal;  // kLiteral: the text; else the parameter's name
};

// "/api/v1/jobs/{id}" -> segments; throws for a parameter that is not a whole segment or a
// "{name+}" that is not the last one.
std::vector<Segment> ParsePattern(const std::string& pattern) {
  if (pattern.empty() || pattern[0] != '/') throw std::logic_error("bad route " + pattern);
  std::vector<Segment> segments;
  size_t pos = 1;
  while (true) {
    const size_t end = std::min(pattern.find('/', pos), pattern.size());
    const std::string piece = pattern.substr(pos, end - pos);
    const bool braced = piece.size() >= 2 && piece.front() == '{' && piece.back() == '}';
    Segment segment{Segment::kLiteral, braced ? piece.substr(1, piece.size() - 2) : piece};
    if (segment.literal.find_first_of("{}") != std::string::npos ||
        (!segments.empty() && segments.back().kind == Segment::kRest)) {
      throw std::logic_error("bad route " + pattern);
    }
    if (braced) {
      segment.kind = segment.literal.back() == '+' ? Segment::kRest : Segment::kParam;
      if (segment.kind == Segment::kRest) segment.literal.pop_back();
    }
    segments.push_back(std::move(segment));
    if (end == pattern.size()) return segments;
    pos = end + 1;
  }
}

// True when `path` matches; `params` gets the parameters.
bool MatchSegments(const std::vector<Segment>& segments, const std::string& path,
                   std::map<std::string, std::string>& params) {
  params.clear();
  size_t pos = 0;
  for (const Segment& segment : segments) {
    if (pos >= path.size() || path[pos] != '/') return false;
    ++pos;
    if (segment.kind == Segment::kRest) {
      if (pos == path.size()) return false;
      params[segment.literal] = path.substr(pos);
      return true;
    }
    const size_t end = std::min(path.find('/', pos), path.size());
    if (segment.kind == Segment::kParam) {
      if (end == pos) return false;
      params[segment.literal] = path.substr(pos, end - pos);
    } else if (path.compare(pos, end - pos, segment.literal) != 0) {
      return false;
    }
    pos = end;
  }
  return pos == path.size();
}

bool ConstantTimeEquals(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char difference = 0;
  for (size_t i = 0; i < a.size(); ++i) difference |= static_cast<unsigned char>(a[i] ^ b[i]);
  return difference == 0;
}

// A request without Content-Length or Transfer-Encoding has no body (RFC 9112, 6.3).
bool HasBody(const httplib::Request& req) {
  return (req.has_header("Content-Length") && req.get_header_value("Content-Length") != "0") ||
         req.has_header("Transfer-Encoding");
}

// The error code of a status httplib answers by itself (its error handler).
std::string DefaultErrorCode(int status) {
  static const std::map<int, std::string> kCodes = {
      {400, "bad_request"},       {401, "unauthorized"}, {404, "not_found"},
      {413, "payload_too_large"}, {414, "uri_too_long"}, {416, "range_not_satisfiable"},
      {503, "unavailable"}};
  const auto it = kCodes.find(status);
  return it != kCodes.end() ? it->second : status >= 500 ? "internal" : "error";
}

// Sets a body that httplib must neither slice by the request's Range header (it slices every
// body, JSON errors included, when one is present) nor follow with another request on this
// connection (`close`). Both go through a content provider: httplib applies ranges to a
// provider with a length, so with a Range header the body goes chunked; a provider that
// returns false after writing everything makes httplib close the connection.
void SetBody(const httplib::Request& req, httplib::Response& res, std::string body,
             const std::string& content_type, bool close) {
  if (!close && req.ranges.empty()) {
    res.set_content(body, content_type);
    return;
  }
  if (close) res.set_header("Connection", "close");
  auto shared = std::make_shared<const std::string>(std::move(body));
  if (req.ranges.empty() && !shared->empty()) {
    res.set_content_provider(
        shared->size(), content_type,
        [shared, close](size_t offset, size_t length, httplib::DataSink& sink) {
          sink.write(shared->data() + offset, length);
          return !close;
        });
  } else {
    res.set_chunked_content_provider(content_type,
                                     [shared, close](size_t, httplib::DataSink& sink) {
                                       if (!shared->empty())
                                         sink.write(shared->data(), shared->size());
                                       sink.done();
                                       return !close;
                                     });
  }
}

void SetFile(const httplib::Request& req, const HttpResponse& response, httplib::Response& res) {
  const int64_t size = response.file_size;
  for (const auto& [first, last] : req.ranges) {
    const bool satisfiable =
        first >= 0 ? first < size && (last < 0 || last >= first) : last > 0 && size > 0;
    if (!satisfiable) {
      res.status = 416;
      res.set_header("Content-Range", "bytes */" + std::to_string(size));
      SetBody(req, res,
              api::JsonText(api::ErrorJson("range_not_satisfiable",
                                           "the requested range lies outside the file",
                                           {{"size", size}})),
              "application/json", false);
      return;
    }
  }
  if (!req.ranges.empty()) res.status = 206;
  auto stream = std::make_shared<std::ifstream>(*response.file, std::ios::binary);
  res.set_content_provider(static_cast<size_t>(size), response.content_type,
                           [stream](size_t offset, size_t length, httplib::DataSink& sink) {
                             std::vector<char> buffer(std::min<size_t>(length, 256 * 1024));
                             stream->seekg(static_cast<std::streamoff>(offset));
                             stream->read(buffer.data(),
                                          static_cast<std::streamsize>(buffer.size()));
                             const auto got = stream->gcount();
                             if (got <= 0) return false;
                             return sink.write(buffer.data(), static_cast<size_t>(got));
                           });
}

// gzip of `data` (zlib's default level), or nullopt on failure.
std::optional<std::string> Gzip(const std::string& data) {
  z_stream z{};
  if (deflateInit2(&z, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 31, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
    return std::nullopt;
  }
  std::string out(deflateBound(&z, data.size()), '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = static_cast<uInt>(data.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  const bool done = deflate(&z, Z_FINISH) == Z_STREAM_END;
  out.resize(z.total_out);
  deflateEnd(&z);
  if (!done) return std::nullopt;
  return out;
}

// Debian's cpp-httplib compresses a static file with brotli at maximum quality whenever the
// client accepts it: about 6 s for three.js against 0.17 s with gzip. For such a client the file
// goes gzip-compressed here (or as it is) through a content provider, which httplib does not
// compress; other clients get httplib's own gzip as before.
void AvoidBrotli(const httplib::Request& req, httplib::Response& res) {
  const std::string accepted = req.get_header_value("Accept-Encoding");
  if (accepted.find("br") == std::string::npos || res.body.empty()) return;
  std::string type = res.get_header_value("Content-Type");
  std::string body = std::move(res.body);
  res.body.clear();
  if (accepted.find("gzip") != std::string::npos && req.ranges.empty()) {
    if (auto compressed = Gzip(body)) {
      body = std::move(*compressed);
      res.set_header("Content-Encoding", "gzip");
    }
  }
  res.set_header("Vary", "Accept-Encoding");
  auto shared = std::make_shared<const std::string>(std::move(body));
  res.set_content_provider(shared->size(), type,
                           [shared](size_t offset, size_t length, httplib::DataSink& sink) {
                             return sink.write(shared->data() + offset, length);
                           });
}

// httplib's pool of connection threads, with the connections handed to it (queued or served)
// counted against max_connections. Beyond the cap a connection is served by a small pool of its
// own with `refusing_connection` set: its first request gets the 503 and the connection closes.
class ConnectionQueue : public httplib::TaskQueue {
 public:
  ConnectionQueue(int num_threads, int max_connections, std::atomic<int64_t>& open)
      : pool_(static_cast<size_t>(num_threads)), max_connections_(max_connections), open_(open) {}

  // Called on the accepting thread only: the count can only shrink between check and add.
  void enqueue(std::function<void()> fn) override {
    if (max_connections_ > 0 && open_ >= max_connections_) {
      refusals_.enqueue([fn = std::move(fn)] {
        refusing_connection = true;
        fn();
        refusing_connection = false;
      });
      return;
    }
    ++open_;
    pool_.enqueue([this, fn = std::move(fn)] {
      fn();
      --open_;
    });
  }
  void shutdown() override {
    pool_.shutdown();
    refusals_.shutdown();
  }

 private:
  httplib::ThreadPool pool_;
  httplib::ThreadPool refusals_{2};
  const int max_connections_;
  std::atomic<int64_t>& open_;
};

uint16_t LocalPort(int fd) {
  sockaddr_storage address{};
  socklen_t length = sizeof(address);
  if (::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) != 0) return 0;
  if (address.ss_family == AF_INET) {
    return ntohs(reinterpret_cast<const sockaddr_in&>(address).sin_port);
  }
  if (address.ss_family == AF_INET6) {
    return ntohs(reinterpret_cast<const sockaddr_in6&>(address).sin6_port);
  }
  return 0;
}

// httplib 0.11 leaves a thread that waits for an idle keep-alive connection's next request
// there until the keep-alive timeout, stopped or not. Shutting down the reading side of the
// server's connections (the sockets of this process with local port `port` and a peer) wakes
// those threads at once; a request in progress still writes its response.
void ShutDownConnectionReads(int port) {
  DIR* fds = ::opendir("/proc/self/fd");
  if (fds == nullptr) return;
  const int own = ::dirfd(fds);
  while (const dirent* entry = ::readdir(fds)) {
    const int fd = std::atoi(entry->d_name);
    if (entry->d_name[0] == '.' || fd == own || LocalPort(fd) != port) continue;
    sockaddr_storage peer{};
    socklen_t length = sizeof(peer);
    if (::getpeername(fd, reinterpret_cast<sockaddr*>(&peer), &length) == 0) {
      ::shutdown(fd, SHUT_RD);
    }
  }
  ::closedir(fds);
}

// What `handle` answers; each exception becomes a JSON error instead: an HttpError as it says,
// an InvalidArgument 400 (its check's location to the log only), a store that cannot be reached
// 503 with Retry-After (the client tries again; nothing was changed), a store whose disk is full
// 507, anything else a logged 500.
HttpResponse AnswerOrError(const std::string& route_label,
                           const std::function<void(HttpResponse&)>& handle) {
  HttpResponse response;
  try {
    handle(response);
  } catch (const HttpError& e) {
    response = HttpResponse{};
    response.headers = e.headers;
    response.Json(e.status, api::ErrorJson(e.code, e.what(), e.details));
  } catch (const storage::StoreUnavailable& e) {
    constexpr int kRetryAfterS = 1;
    response = HttpResponse{};
    response.headers.emplace("Retry-After", std::to_string(kRetryAfterS));
    response.Json(503, api::ErrorJson("database_unavailable",
                                      "the job database cannot be reached right now; nothing "
                                      "was changed: try again in a moment",
                                      {{"reason", e.what()}, {"retry_after_s", kRetryAfterS}}));
  } catch (const InvalidArgument& e) {
    if (!e.where().empty()) {
      std::cerr << "omnirig: " << route_label << ": 400: " << e.what() << " (check at " << e.where()
                << ")" << std::endl;
    }
    response = HttpResponse{};
    response.Json(400, api::ErrorJson("invalid_argument", e.what()));
  } catch (const std::exception& e) {
    response = HttpResponse{};
    if (storage::IsDiskFull(e)) {
      std::cerr << "omnirig: " << route_label << ": 507: " << e.what() << std::endl;
      response.Json(507, api::ErrorJson("insufficient_storage",
                                        "the disk holding the data folder is full; nothing of "
                                        "this request was stored: free some space and try again",
                                        {{"reason", e.what()}}));
    } else {
      std::cerr << "omnirig: " << route_label << ": 500: " << e.what() << std::endl;
      response.Json(500, api::ErrorJson("internal", e.what()));
    }
  } catch (...) {
    std::cerr << "omnirig: " << route_label << ": 500: unknown exception" << std::endl;
    response = HttpResponse{};
    response.Json(500, api::ErrorJson("internal", "unknown error"));
  }
  return response;
}

// Hands `response` to httplib: a file (its ranges), a stream, or a body (then the connection
// closes when `close`).
void WriteResponse(const httplib::Request& req, HttpResponse response, bool close,
                   httplib::Response& res) {
  res.status = response.status;
  for (const auto& [name, value] : response.headers) res.set_header(name, value);
  if (response.file && response.status == 200) {
    SetFile(req, response, res);
  } else if (response.stream) {
    res.set_chunked_content_provider(response.content_type, [stream = std::move(response.stream),
                                                             path = req.path](
                                                                size_t, httplib::DataSink& sink) {
      std::string chunk;
      try {
        if (!stream(chunk)) {
          sink.done();
          return true;
        }
      } catch (const std::exception& e) {
        // The status went out long ago: the connection drops without the last chunk, so that
        // the client sees a broken transfer rather than a short body that looks whole.
        LogEvent("stream_failed", {{"path", path}, {"message", e.what()}});
        return false;
      }
      return chunk.empty() || sink.write(chunk.data(), chunk.size());
    });
  } else {
    SetBody(req, res, std::move(response.body), response.content_type, close);
  }
}

}  // namespace

std::optional<std::string> HttpRequest::Query(const std::string& name) const {
  const auto it = query.find(name);
  if (it == query.end()) return std::nullopt;
  return it->second;
}

void HttpResponse::Json(int status_code, const nlohmann::json& json) {
  status = status_code;
  content_type = "application/json";
  body = api::JsonText(json);
  file.reset();
}

bool IsLoopbackHost(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

struct HttpServer::Impl {
  struct RouteInfo {
    std::string method;
    std::string label;  // "GET /api/v1/jobs/{id}", for the request counter
    std::vector<Segment> segments;
    HttpHandler handler;
    bool streaming = false;
  };

  HttpServerOptions options;
  RequestCounter counter;
  std::atomic<int64_t> open_connections{0};  // declared before `server`, whose queue uses it
  httplib::Server server;
  int listen_socket = -1;
  int port = 0;
  std::thread thread;
  std::atomic<bool> listen_returned{false};
  std::vector<RouteInfo> routes;       // fixed once serving starts
  std::string expected_authorization;  // "Bearer <token>"

  const RouteInfo* Find(const std::string& method, const std::string& path,
                        std::map<std::string, std::string>& params) const {
    const std::string& wanted = method == "HEAD" ? "GET" : method;
    for (const RouteInfo& route : routes) {
      if (route.method == wanted && MatchSegments(route.segments, path, params)) return &route;
    }
    return nullptr;
  }
  void Dispatch(const RouteInfo& route, std::map<std::string, std::string> params,
                const httplib::Request& req, httplib::Response& res,
                const httplib::ContentReader* reader);
  // The httplib handler for every request that reaches the handlers (those with a body, and
  // GETs that are not routes): routes it, or answers 404.
  void DispatchOrNotFound(const httplib::Request& req, httplib::Response& res,
                          const httplib::ContentReader* reader);
  httplib::Server::HandlerResponse PreRoute(const httplib::Request& req, httplib::Response& res);
  bool ReadWholeBody(const httplib::Request& req, const httplib::Response& res,
                     const httplib::ContentReader& reader, std::string& body) const;
  bool DiscardBody(const httplib::Request& req, const httplib::ContentReader& reader) const;
  void Install();
};

// Reads a buffered route's body into `body`; throws HttpError when it is too large or broken.
bool HttpServer::Impl::ReadWholeBody(const httplib::Request& req, const httplib::Response& res,
                                     const httplib::ContentReader& reader,
                                     std::string& body) const {
  const auto limit = static_cast<size_t>(options.max_body_bytes);
  bool too_large = false;
  const auto append = [&](const char* data, size_t size) {
    too_large = body.size() + size > limit;
    if (!too_large) body.append(data, size);
    return !too_large;
  };
  // A multipart body to a buffered route: read (its parts are not the route's JSON) and dropped.
  const bool whole = req.is_multipart_form_data()
                         ? reader([](const httplib::MultipartFormData&) { return true; },
                                  [](const char*, size_t) { return true; })
                         : reader(append);
  if (whole) return true;
  if (too_large || res.status == 413) {
    throw HttpError(413, "payload_too_large",
                    "the body exceeds " + std::to_string(options.max_body_bytes) + " bytes",
                    {{"limit_bytes", options.max_body_bytes}});
  }
  throw HttpError(400, "incomplete_body", "the request body could not be read");
}

// Reads and drops a body the handler did not read, for at most unread_body_linger_ms; true
// when it was read to its end (the connection can serve the next request).
bool HttpServer::Impl::DiscardBody(const httplib::Request& req,
                                   const httplib::ContentReader& reader) const {
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(options.unread_body_linger_ms);
  const auto in_time = [deadline](const char*, size_t) {
    return std::chrono::steady_clock::now() < deadline;
  };
  if (req.is_multipart_form_data()) {
    return reader([&](const httplib::MultipartFormData&) { return in_time(nullptr, 0); }, in_time);
  }
  return reader(in_time);
}

void HttpServer::Impl::Dispatch(const RouteInfo& route, std::map<std::string, std::string> params,
                                const httplib::Request& req, httplib::Response& res,
                                const httplib::ContentReader* reader) {
  current_route = route.label;
  HttpRequest request;
  request.method = req.method;
  request.path = req.path;
  request.path_params = std::move(params);
  request.query.insert(req.params.begin(), req.params.end());
  request.header = [&req](const std::string& name) { return req.get_header_value(name); };
  bool reader_called = false;  // by the handler
  bool body_read = reader == nullptr;
  // Streaming routes: no exception crosses httplib's reader; the first one a callback throws
  // stops the reading and is rethrown after it.
  std::exception_ptr failure;
  const auto guard = [&failure](auto callback) {
    return [&failure, callback](const auto&... args) {
      try {
        return callback(args...);
      } catch (...) {
        failure = std::current_exception();
        return false;
      }
    };
  };
  const auto read = [&](const auto&... callbacks) {
    reader_called = true;
    body_read = (*reader)(guard(callbacks)...);
    if (failure) std::rethrow_exception(failure);
    return body_read;
  };
  if (reader != nullptr && route.streaming) {
    request.is_multipart = req.is_multipart_form_data();
    request.read_body = [&](const std::function<bool(const char*, size_t)>& on_data) {
      return read(on_data);
    };
    request.read_multipart = [&](const std::function<bool(const MultipartPart&)>& on_part,
                                 const std::function<bool(const char*, size_t)>& on_data) {
      return read(
          [&](const httplib::MultipartFormData& part) {
            return on_part(MultipartPart{part.name, part.filename, part.content_type});
          },
          on_data);
    };
  }
  HttpResponse response = AnswerOrError(route.label, [&](HttpResponse& answer) {
    if (reader != nullptr && !route.streaming) {
      reader_called = true;
      body_read = ReadWholeBody(req, res, *reader, request.body);
    }
    route.handler(request, answer);
  });
  // The rest of an unread body would be parsed as the next request.
  if (!body_read && !reader_called) body_read = DiscardBody(req, *reader);
  WriteResponse(req, std::move(response), !body_read, res);
}

void HttpServer::Impl::DispatchOrNotFound(const httplib::Request& req, httplib::Response& res,
                                          const httplib::ContentReader* reader) {
  std::map<std::string, std::string> params;
  if (const RouteInfo* route = Find(req.method, req.path, params)) {
    Dispatch(*route, std::move(params), req, res, reader);
    return;
  }
  bool body_read = reader == nullptr || DiscardBody(req, *reader);
  res.status = 404;
  SetBody(req, res,
          api::JsonText(api::ErrorJson("not_found", "no route for " + req.method + " " + req.path)),
          "application/json", !body_read);
}

// Every request starts here: the refusal beyond max_connections, the bearer token, and the
// routes of requests without a body. httplib 0.11 reads the body of a POST, PUT or DELETE that
// has neither Content-Length nor Transfer-Encoding until the client closes (a `curl -X POST
// .../cancel` waited out the read timeout and got 400): served here, it has none. Requests
// with a body go on to httplib, which hands them with a reader to DispatchOrNotFound; other
// GETs to httplib's static files.
httplib::Server::HandlerResponse HttpServer::Impl::PreRoute(const httplib::Request& req,
                                                            httplib::Response& res) {
  using Result = httplib::Server::HandlerResponse;
  request_start = std::chrono::steady_clock::now();
  current_route = "unmatched";
  if (refusing_connection) {
    constexpr int kRetryAfterS = 1;
    current_route = kRefusedRoute;
    res.status = 503;
    res.set_header("Retry-After", std::to_string(kRetryAfterS));
    const int cap = options.max_connections;
    SetBody(req, res,
            api::JsonText(api::ErrorJson(
                "unavailable", "too many open connections (" + std::to_string(cap) + ")",
                {{"max_connections", cap}, {"retry_after_s", kRetryAfterS}})),
            "application/json", true);
    return Result::Handled;
  }
  const bool protected_path = req.path.rfind("/api/", 0) == 0 || req.path == "/metrics";
  if (!options.token.empty() && protected_path &&
      !ConstantTimeEquals(req.get_header_value("Authorization"), expected_authorization)) {
    current_route = "auth";
    res.status = 401;
    res.set_header("WWW-Authenticate", "Bearer");
    SetBody(req, res,
            api::JsonText(api::ErrorJson("unauthorized", "a valid bearer token is required")),
            "application/json", HasBody(req));
    return Result::Handled;
  }
  if (HasBody(req)) return Result::Unhandled;
  std::map<std::string, std::string> params;
  const RouteInfo* route = Find(req.method, req.path, params);
  if (route == nullptr) {
    if (req.method == "GET" || req.method == "HEAD") return Result::Unhandled;  // static files
    DispatchOrNotFound(req, res, nullptr);
    return Result::Handled;
  }
  Dispatch(*route, std::move(params), req, res, nullptr);
  return Result::Handled;
}

void HttpServer::Impl::Install() {
  expected_authorization = "Bearer " + options.token;
  const int threads = options.num_threads;
  const int max_connections = options.max_connections;
  std::atomic<int64_t>* open = &open_connections;
  server.new_task_queue = [threads, max_connections, open] {
    return new ConnectionQueue(threads, max_connections, *open);
  };
  server.set_keep_alive_timeout(std::max(1, (options.keep_alive_timeout_ms + 999) / 1000));
  server.set_keep_alive_max_count(100000);
  server.set_read_timeout(options.read_timeout_ms / 1000, (options.read_timeout_ms % 1000) * 1000);
  server.set_payload_max_length(static_cast<size_t>(options.max_body_bytes));
  server.set_tcp_nodelay(true);
  // The listening socket, to raise its backlog after binding (see Bind).
  server.set_socket_options([this](int sock) {
    httplib::default_socket_options(sock);
    listen_socket = sock;
  });
  server.set_pre_routing_handler(
      [this](const httplib::Request& req, httplib::Response& res) { return PreRoute(req, res); });
  const auto buffered = [this](const httplib::Request& req, httplib::Response& res) {
    DispatchOrNotFound(req, res, nullptr);
  };
  const auto streamed = [this](const httplib::Request& req, httplib::Response& res,
                               const httplib::ContentReader& reader) {
    DispatchOrNotFound(req, res, &reader);
  };
  server.Get(".*", buffered);
  server.Post(".*", streamed);
  server.Put(".*", streamed);
  server.Delete(".*", streamed);
  server.set_file_request_handler([](const httplib::Request& req, httplib::Response& res) {
    current_route = "static";
    AvoidBrotli(req, res);
  });
  server.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty() || res.content_length_ > 0 || res.content_provider_) return;
    const std::string message =
        res.status == 404 ? "no route for " + req.method + " " + req.path
                          : "request refused with HTTP status " + std::to_string(res.status);
    res.set_content(api::JsonText(api::ErrorJson(DefaultErrorCode(res.status), message)),
                    "application/json");
  });
  server.set_logger([this](const httplib::Request& req, const httplib::Response& res) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - request_start).count();
    if (counter) counter(current_route, res.status, seconds);
    char duration_ms[32];
    std::snprintf(duration_ms, sizeof(duration_ms), "%.3f", seconds * 1e3);
    LogEvent("request", {{"method", req.method},
                         {"path", req.path},
                         {"status", std::to_string(res.status)},
                         {"duration_ms", duration_ms},
                         {"route", current_route},
                         {"remote", req.remote_addr}});
  });
}

HttpServer::HttpServer(const HttpServerOptions& options, RequestCounter counter)
    : impl_(std::make_unique<Impl>()) {
  impl_->options = options;
  impl_->counter = std::move(counter);
  impl_->Install();
}

HttpServer::~HttpServer() { Stop(); }

void HttpServer::Route(const std::string& method, const std::string& pattern, HttpHandler handler,
                       bool streaming) {
  if (method != "GET" && method != "POST" && method != "PUT" && method != "DELETE") {
    throw std::logic_error("unsupported method " + method);
  }
  impl_->routes.push_back(
      {method, method + " " + pattern, ParsePattern(pattern), std::move(handler), streaming});
}

bool HttpServer::MountStatic(const std::string& prefix, const std::filesystem::path& dir) {
  return impl_->server.set_mount_point(prefix, dir.string());
}

int64_t HttpServer::OpenConnections() const { return impl_->open_connections.load(); }

int HttpServer::Bind(const std::string& host, int port) {
  const int bound = port == 0 ? impl_->server.bind_to_any_port(host)
                              : (impl_->server.bind_to_port(host, port) ? port : -1);
  if (bound <= 0) {
    throw std::runtime_error("cannot bind " + host + ":" + std::to_string(port));
  }
  // httplib listens with a backlog of 5: 200 clients connecting at once overflow it, and the
  // dropped SYNs are retried only after 1 s. Listening again on the bound socket raises it.
  if (impl_->listen_socket >= 0) ::listen(impl_->listen_socket, SOMAXCONN);
  impl_->port = bound;
  return bound;
}

void HttpServer::Start() {
  impl_->listen_returned = false;
  impl_->thread = std::thread([this] {
    impl_->server.listen_after_bind();
    impl_->listen_returned = true;
  });
  // httplib's stop() does nothing until the listening thread has marked the server running, so a
  // Stop() right after Start() would leave accept() blocked forever: wait for that mark.
  while (!impl_->server.is_running() && !impl_->listen_returned) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

void HttpServer::Stop() {
  if (!impl_->thread.joinable()) return;
  impl_->server.stop();  // closes the listening socket: no connection is accepted after this
  ShutDownConnectionReads(impl_->port);
  impl_->thread.join();  // the connection threads end with listen_after_bind()
}

int64_t RaiseOpenFileLimit() {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0) return 1024;
  if (limit.rlim_cur < limit.rlim_max) {
    rlimit raised = limit;
    raised.rlim_cur = limit.rlim_max;
    if (::setrlimit(RLIMIT_NOFILE, &raised) == 0) limit = raised;
  }
  constexpr int64_t kLarge = int64_t{1} << 30;
  if (limit.rlim_cur == RLIM_INFINITY) return kLarge;
  return static_cast<int64_t>(std::min<rlim_t>(limit.rlim_cur, kLarge));
}

int DefaultMaxConnections(int64_t open_file_limit, int http_threads) {
  const int64_t reserve = 256 + 2 * static_cast<int64_t>(std::max(0, http_threads));
  return static_cast<int>(std::clamp<int64_t>(open_file_limit - reserve, 16, 4096));
}

}  // namespace omnirig::server
