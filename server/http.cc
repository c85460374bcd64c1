#include "server/http.h"

#include <httplib.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <regex>
#include <thread>
#include <vector>

#include "api/service_json.h"

namespace omnirig::server {
namespace {

// The route pattern and start time of the request this connection thread is serving, for the
// request counter (httplib calls the logger on the same thread after the handler).
thread_local std::string current_route;
thread_local std::chrono::steady_clock::time_point request_start;

// "/api/v1/jobs/{id}" -> "^/api/v1/jobs/([^/]+)$"; names collects the parameter names.
std::string PatternToRegex(const std::string& pattern, std::vector<std::string>& names) {
  std::string regex = "^";
  size_t pos = 0;
  while (pos < pattern.size()) {
    const size_t open = pattern.find('{', pos);
    const std::string literal = pattern.substr(pos, open - pos);
    for (char c : literal) {
      if (std::string(".+*?()[]^$|\\").find(c) != std::string::npos) regex += '\\';
      regex += c;
    }
    if (open == std::string::npos) break;
    const size_t close = pattern.find('}', open);
    std::string name = pattern.substr(open + 1, close - open - 1);
    const bool rest = !name.empty() && name.back() == '+';
    if (rest) name.pop_back();
    names.push_back(name);
    regex += rest ? "(.+)" : "([^/]+)";
    pos = close + 1;
  }
  return regex + "$";
}

bool ConstantTimeEquals(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char difference = 0;
  for (size_t i = 0; i < a.size(); ++i) difference |= static_cast<unsigned char>(a[i] ^ b[i]);
  return difference == 0;
}

const char* DefaultErrorCode(int status) {
  switch (status) {
    case 400:
      return "bad_request";
    case 401:
      return "unauthorized";
    case 404:
      return "not_found";
    case 405:
      return "method_not_allowed";
    case 413:
      return "payload_too_large";
    case 416:
      return "range_not_satisfiable";
    case 503:
      return "unavailable";
    default:
      return status >= 500 ? "internal" : "error";
  }
}

void WriteFile(const httplib::Request& req, HttpResponse& response, httplib::Response& res) {
  const int64_t size = response.file_size;
  for (const auto& [first, last] : req.ranges) {
    const bool satisfiable =
        first >= 0 ? first < size && (last < 0 || last >= first) : last > 0 && size > 0;
    if (!satisfiable) {
      response.Json(
          416, api::ErrorJson("range_not_satisfiable", "the requested range lies outside the file",
                              {{"size", size}}));
      res.status = 416;
      const_cast<httplib::Request&>(req).ranges.clear();  // see Dispatch
      res.set_header("Content-Range", "bytes */" + std::to_string(size));
      res.set_content(response.body, "application/json");
      return;
    }
  }
  if (!req.ranges.empty() && response.status == 200) res.status = 206;
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

}  // namespace

std::optional<std::string> HttpRequest::Query(const std::string& name) const {
  const auto it = query.find(name);
  if (it == query.end()) return std::nullopt;
  return it->second;
}

void HttpResponse::Json(int status_code, const nlohmann::json& json) {
  status = status_code;
  content_type = "application/json";
  body = json.dump();
  file.reset();
}

bool IsLoopbackHost(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

struct HttpServer::Impl {
  struct RouteInfo {
    std::string pattern;
    std::vector<std::string> names;
    HttpHandler handler;
  };

  HttpServerOptions options;
  RequestCounter counter;
  httplib::Server server;
  std::thread thread;
  std::atomic<bool> listen_returned{false};

  void Dispatch(const RouteInfo& route, const httplib::Request& req, httplib::Response& res,
                const httplib::ContentReader* reader);
  HttpRequest MakeRequest(const RouteInfo& route, const httplib::Request& req,
                          const httplib::ContentReader* reader);
  void Install();
};

HttpRequest HttpServer::Impl::MakeRequest(const RouteInfo& route, const httplib::Request& req,
                                          const httplib::ContentReader* reader) {
  HttpRequest request;
  request.method = req.method;
  request.path = req.path;
  for (size_t i = 0; i < route.names.size() && i + 1 < req.matches.size(); ++i) {
    request.path_params[route.names[i]] = req.matches[i + 1].str();
  }
  request.query.insert(req.params.begin(), req.params.end());
  request.body = req.body;
  request.header = [&req](const std::string& name) { return req.get_header_value(name); };
  if (reader) {
    request.is_multipart = req.is_multipart_form_data();
    request.read_body = [reader](const std::function<bool(const char*, size_t)>& on_data) {
      return (*reader)([&](const char* data, size_t size) { return on_data(data, size); });
    };
    request.read_multipart = [reader](const std::function<bool(const MultipartPart&)>& on_part,
                                      const std::function<bool(const char*, size_t)>& on_data) {
      return (*reader)(
          [&](const httplib::MultipartFormData& part) {
            return on_part(MultipartPart{part.name, part.filename, part.content_type});
          },
          [&](const char* data, size_t size) { return on_data(data, size); });
    };
  }
  return request;
}

void HttpServer::Impl::Dispatch(const RouteInfo& route, const httplib::Request& req,
                                httplib::Response& res, const httplib::ContentReader* reader) {
  current_route = route.pattern;
  HttpResponse response;
  try {
    route.handler(MakeRequest(route, req, reader), response);
  } catch (const HttpError& e) {
    response.Json(e.status, api::ErrorJson(e.code, e.what(), e.details));
  } catch (const std::invalid_argument& e) {
    response.Json(400, api::ErrorJson("invalid_argument", e.what()));
  } catch (const std::exception& e) {
    response.Json(500, api::ErrorJson("internal", e.what()));
  } catch (...) {
    response.Json(500, api::ErrorJson("internal", "unknown error"));
  }
  res.status = response.status;
  for (const auto& [name, value] : response.headers) res.set_header(name.c_str(), value);
  if (!response.file || response.status != 200) {
    // cpp-httplib 0.11 slices *every* response body by the request's Range header, including
    // JSON errors; only a file download may honour it. The Request object is httplib's own
    // non-const local, handed to handlers as const, so clearing its ranges here is defined.
    const_cast<httplib::Request&>(req).ranges.clear();
  }
  if (response.file) {
    WriteFile(req, response, res);
  } else {
    res.set_content(response.body, response.content_type.c_str());
  }
}

void HttpServer::Impl::Install() {
  const int threads = options.num_threads;
  server.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  server.set_payload_max_length(static_cast<size_t>(options.max_body_bytes));
  server.set_keep_alive_max_count(100000);
  server.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    request_start = std::chrono::steady_clock::now();
    current_route = "unmatched";
    // Debian's cpp-httplib prefers brotli at maximum quality whenever the client accepts it:
    // about 6 s for three.js against 0.17 s with gzip. Offer it gzip only. The request object
    // is a mutable local of httplib's request loop, so editing its headers here is defined.
    auto& headers = const_cast<httplib::Request&>(req).headers;
    const auto accept = headers.find("Accept-Encoding");
    if (accept != headers.end() && accept->second.find("br") != std::string::npos) {
      accept->second = accept->second.find("gzip") != std::string::npos ? "gzip" : "identity";
    }
    const bool protected_path = req.path.rfind("/api/", 0) == 0 || req.path == "/metrics";
    if (!options.token.empty() && protected_path &&
        !ConstantTimeEquals(req.get_header_value("Authorization"), "Bearer " + options.token)) {
      current_route = "auth";
      res.status = 401;
      res.set_header("WWW-Authenticate", "Bearer");
      res.set_content(api::ErrorJson("unauthorized", "a valid bearer token is required").dump(),
                      "application/json");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  server.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty()) return;
    const std::string message =
        res.status == 404 ? "no route for " + req.method + " " + req.path
                          : "request refused with HTTP status " + std::to_string(res.status);
    res.set_content(api::ErrorJson(DefaultErrorCode(res.status), message).dump(),
                    "application/json");
  });
  server.set_logger([this](const httplib::Request&, const httplib::Response& res) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - request_start).count();
    if (counter) counter(current_route, res.status, seconds);
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
  auto route = std::make_shared<Impl::RouteInfo>();
  route->pattern = method + " " + pattern;
  route->handler = std::move(handler);
  const std::string regex = PatternToRegex(pattern, route->names);
  Impl* impl = impl_.get();
  const auto buffered = [impl, route](const httplib::Request& req, httplib::Response& res) {
    impl->Dispatch(*route, req, res, nullptr);
  };
  const auto streamed = [impl, route](const httplib::Request& req, httplib::Response& res,
                                      const httplib::ContentReader& reader) {
    impl->Dispatch(*route, req, res, &reader);
  };
  httplib::Server& server = impl_->server;
  if (method == "GET") {
    server.Get(regex, buffered);
  } else if (method == "DELETE") {
    server.Delete(regex, buffered);
  } else if (method == "POST") {
    streaming ? server.Post(regex, streamed) : server.Post(regex, buffered);
  } else if (method == "PUT") {
    streaming ? server.Put(regex, streamed) : server.Put(regex, buffered);
  } else {
    throw std::invalid_argument("unsupported method " + method);
  }
}

bool HttpServer::MountStatic(const std::string& prefix, const std::filesystem::path& dir) {
  return impl_->server.set_mount_point(prefix, dir.string());
}

int HttpServer::Bind(const std::string& host, int port) {
  const int bound = port == 0 ? impl_->server.bind_to_any_port(host)
                              : (impl_->server.bind_to_port(host, port) ? port : -1);
  if (bound <= 0) {
    throw std::runtime_error("cannot bind " + host + ":" + std::to_string(port));
  }
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
  impl_->server.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

}  // namespace omnirig::server
