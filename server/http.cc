#include "server/http.h"

#include <httplib.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <fstream>
#include <mutex>
#include <regex>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include "api/service_json.h"

namespace omnirig::server {
namespace {

// The route pattern and start time of the request this connection thread is serving, for the
// request counter (httplib calls the logger on the same thread after the handler).
thread_local std::string current_route;
thread_local std::chrono::steady_clock::time_point request_start;
// Set by Dispatch when a streaming handler answered without reading its whole body: the rest
// of the body is still on the connection and would be parsed as the next request (a 400 for
// each line, answers out of step with the client's requests), so the connection closes after
// this response instead (see LingerBeforeClose).
thread_local bool close_after_response = false;

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

// One '/'-separated piece of a route pattern, for matching without std::regex.
struct Segment {
  enum Kind { kLiteral, kParam, kRest } kind = kLiteral;
  std::string literal;
};

// The pattern's segments; false when a parameter is not a whole segment (e.g. "{id}.json") or
// "{name+}" is not the last one: such a pattern is left to its regex.
bool PatternToSegments(const std::string& pattern, std::vector<Segment>& segments) {
  if (pattern.empty() || pattern[0] != '/') return false;
  size_t pos = 1;
  while (true) {
    const size_t end = std::min(pattern.find('/', pos), pattern.size());
    const std::string piece = pattern.substr(pos, end - pos);
    const bool braced = piece.size() >= 2 && piece.front() == '{' && piece.back() == '}';
    const std::string inner = braced ? piece.substr(1, piece.size() - 2) : piece;
    if (inner.find_first_of("{}") != std::string::npos) return false;
    Segment segment;
    if (braced) {
      segment.kind = !inner.empty() && inner.back() == '+' ? Segment::kRest : Segment::kParam;
    } else {
      segment.literal = piece;
    }
    if (!segments.empty() && segments.back().kind == Segment::kRest) return false;
    segments.push_back(std::move(segment));
    if (end == pattern.size()) return true;
    pos = end + 1;
  }
}

// Matches `path` as the pattern's regex (PatternToRegex) does: "{name}" is one non-empty segment
// ([^/]+), "{name+}" the non-empty rest (.+, which stops at line breaks). `values` gets the
// parameters in order.
bool MatchSegments(const std::vector<Segment>& segments, const std::string& path,
                   std::vector<std::string>& values) {
  values.clear();
  size_t pos = 0;
  for (const Segment& segment : segments) {
    if (pos >= path.size() || path[pos] != '/') return false;
    ++pos;
    if (segment.kind == Segment::kRest) {
      if (pos == path.size() || path.find_first_of("\r\n", pos) != std::string::npos) return false;
      values.push_back(path.substr(pos));
      return true;
    }
    const size_t end = std::min(path.find('/', pos), path.size());
    if (segment.kind == Segment::kParam) {
      if (end == pos) return false;
      values.push_back(path.substr(pos, end - pos));
    } else if (path.compare(pos, end - pos, segment.literal) != 0) {
      return false;
    }
    pos = end;
  }
  return pos == path.size();
}

// Header names for httplib's lookups, which take std::string: built once, not per request.
const std::string kContentLength = "Content-Length";
const std::string kTransferEncoding = "Transfer-Encoding";
const std::string kAuthorization = "Authorization";

// The pre-routing handler gives every request without Content-Length or Transfer-Encoding a
// "Content-Length: 0" (see Install).
bool HasBody(const httplib::Request& req) {
  return req.get_header_value(kContentLength) != "0" || req.has_header(kTransferEncoding);
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

// A connection's socket as an httplib::Stream, with a read buffer that lives as long as the
// connection (httplib's own SocketStream is rebuilt per request, reads its request line
// through 4 KB reads and drops pipelined bytes). Reads and writes wait at most the timeouts.
class ConnectionStream : public httplib::Stream {
 public:
  ConnectionStream(int sock, int timeout_ms) : sock_(sock), timeout_ms_(timeout_ms) {}

  bool is_readable() const override { return begin_ < end_ || Wait(POLLIN, timeout_ms_); }
  bool is_writable() const override { return Wait(POLLOUT, timeout_ms_); }
  bool has_buffered() const { return begin_ < end_; }

  ssize_t read(char* ptr, size_t size) override {
    // A response part must leave before we wait for the client (e.g. "100 Continue").
    if (!Flush()) return -1;
    if (begin_ == end_) {
      // Large reads (image bodies) go straight to the caller; small ones refill the buffer.
      if (size >= sizeof(buffer_)) return Receive(ptr, size);
      const ssize_t got = Receive(buffer_, sizeof(buffer_));
      if (got <= 0) return got;
      begin_ = 0;
      end_ = static_cast<size_t>(got);
    }
    const size_t n = std::min(size, end_ - begin_);
    std::memcpy(ptr, buffer_ + begin_, n);
    begin_ += n;
    return static_cast<ssize_t>(n);
  }

  // httplib writes a response's headers and body separately; they are gathered here and sent
  // together by Flush() (one segment for a status poll, not two with TCP_NODELAY).
  ssize_t write(const char* ptr, size_t size) override {
    if (out_.size() + size > kOutBytes && !Flush()) return -1;
    if (size >= kOutBytes) return SendAll(ptr, size) ? static_cast<ssize_t>(size) : -1;
    out_.append(ptr, size);
    return static_cast<ssize_t>(size);
  }

  bool Flush() {
    if (out_.empty()) return true;
    const bool ok = SendAll(out_.data(), out_.size());
    out_.clear();
    return ok;
  }

  // httplib asks for both addresses on every request (REMOTE_ADDR, LOCAL_ADDR headers); they
  // do not change while the connection lives, so each is looked up once (a system call and two
  // inet_ntop were ~6 % of a status poll's user-space instructions).
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    if (!remote_) remote_ = Address(::getpeername);
    ip = remote_->first;
    port = remote_->second;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    if (!local_) local_ = Address(::getsockname);
    ip = local_->first;
    port = local_->second;
  }
  int socket() const override { return sock_; }

 private:
  bool Wait(short events, int timeout_ms) const {
    pollfd fd{sock_, events, 0};
    while (true) {
      const int ready = ::poll(&fd, 1, timeout_ms);
      if (ready < 0 && errno == EINTR) continue;
      return ready > 0;
    }
  }
  bool SendAll(const char* ptr, size_t size) {
    while (size > 0) {
      const ssize_t sent = ::send(sock_, ptr, size, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (sent >= 0) {
        ptr += sent;
        size -= static_cast<size_t>(sent);
      } else if (errno != EINTR &&
                 ((errno != EAGAIN && errno != EWOULDBLOCK) || !Wait(POLLOUT, timeout_ms_))) {
        return false;
      }
    }
    return true;
  }
  // Tries first and waits only when nothing is there: a request usually arrives whole, and
  // the event loop hands over a connection only once its bytes are readable.
  ssize_t Receive(char* ptr, size_t size) {
    while (true) {
      const ssize_t got = ::recv(sock_, ptr, size, MSG_DONTWAIT);
      if (got >= 0) return got;
      if (errno == EINTR) continue;
      if ((errno != EAGAIN && errno != EWOULDBLOCK) || !Wait(POLLIN, timeout_ms_)) return -1;
    }
  }
  template <typename Getter>
  std::pair<std::string, int> Address(Getter getter) const {
    sockaddr_storage address{};
    socklen_t length = sizeof(address);
    int port = 0;
    if (getter(sock_, reinterpret_cast<sockaddr*>(&address), &length) != 0) return {"", 0};
    char text[INET6_ADDRSTRLEN] = {};
    if (address.ss_family == AF_INET) {
      const auto* v4 = reinterpret_cast<const sockaddr_in*>(&address);
      ::inet_ntop(AF_INET, &v4->sin_addr, text, sizeof(text));
      port = ntohs(v4->sin_port);
    } else if (address.ss_family == AF_INET6) {
      const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&address);
      ::inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof(text));
      port = ntohs(v6->sin6_port);
    }
    return {text, port};
  }

  static constexpr size_t kOutBytes = 64 * 1024;
  int sock_;
  int timeout_ms_;
  std::string out_;
  char buffer_[64 * 1024];
  size_t begin_ = 0;
  size_t end_ = 0;
  mutable std::optional<std::pair<std::string, int>> remote_, local_;
};

// Before closing a connection whose client may still be sending (a body the handler did not
// read): shuts the write side (the response is out) and discards what arrives until the client
// closes, for at most `linger_ms` (HttpServerOptions::unread_body_linger_ms, 1 s: a client that
// keeps its end open after "Connection: close" held the serving thread for the whole read
// timeout, 5 s, before). Closing at once with unread bytes would send a reset, which may
// discard the response before the client reads it (RFC 9112, 9.6).
void LingerBeforeClose(int sock, int linger_ms) {
  ::shutdown(sock, SHUT_WR);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(linger_ms);
  char scratch[64 * 1024];
  while (true) {
    const auto left =
        std::chrono::ceil<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return;
    pollfd fd{sock, POLLIN, 0};
    const int ready = ::poll(&fd, 1, static_cast<int>(left.count()));
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) return;
    const ssize_t got = ::recv(sock, scratch, sizeof(scratch), MSG_DONTWAIT);
    if (got == 0 || (got < 0 && errno != EINTR && errno != EAGAIN && errno != EWOULDBLOCK)) {
      return;
    }
  }
}

// Answers the connections beyond HttpServerOptions::max_connections: a 503 with the JSON error
// and Retry-After, written at once (a fresh socket's send buffer takes it without waiting), then
// the write side shut and the request drained until the client closes, so that the client reads
// the 503 rather than a reset (closing a socket with unread request bytes sends RST, which may
// discard the response before the client reads it: RFC 9112, 9.6). One thread waits on all of
// them; each lingers at most kLinger, and beyond kMaxLingering at once a socket is closed right
// after its 503 (a flood of connections then costs no more descriptors).
class ConnectionRefuser {
 public:
  explicit ConnectionRefuser(int max_connections)
      : response_(Response(max_connections)), wake_fd_(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)) {
    if (wake_fd_ < 0) throw std::runtime_error("cannot create an eventfd");
    thread_ = std::thread([this] { Run(); });
  }
  ~ConnectionRefuser() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    Wake();
    thread_.join();
    for (const Lingering& lingering : lingering_) ::close(lingering.sock);
    ::close(wake_fd_);
  }
  ConnectionRefuser(const ConnectionRefuser&) = delete;
  ConnectionRefuser& operator=(const ConnectionRefuser&) = delete;

  // Takes ownership of an accepted socket.
  void Refuse(int sock) {
    (void)!::send(sock, response_.data(), response_.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    ::shutdown(sock, SHUT_WR);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!stopping_ && lingering_.size() < kMaxLingering) {
        lingering_.push_back({sock, std::chrono::steady_clock::now() + kLinger});
        Wake();
        return;
      }
    }
    ::close(sock);
  }

 private:
  static constexpr size_t kMaxLingering = 64;
  static constexpr std::chrono::milliseconds kLinger{1000};
  static constexpr int kRetryAfterS = 1;

  struct Lingering {
    int sock;
    std::chrono::steady_clock::time_point deadline;
  };

  static std::string Response(int max_connections) {
    const std::string body =
        api::ErrorJson("unavailable",
                       "too many open connections (" + std::to_string(max_connections) + ")",
                       {{"max_connections", max_connections}, {"retry_after_s", kRetryAfterS}})
            .dump();
    return "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n"
           "Content-Length: " +
           std::to_string(body.size()) + "\r\nRetry-After: " + std::to_string(kRetryAfterS) +
           "\r\nConnection: close\r\n\r\n" + body;
  }

  void Wake() {
    const uint64_t one = 1;
    (void)!::write(wake_fd_, &one, sizeof(one));
  }

  // True once the client has closed (or reset) its side: everything it sent has been read.
  static bool DrainedToEnd(int sock) {
    char scratch[4096];
    while (true) {
      const ssize_t got = ::recv(sock, scratch, sizeof(scratch), MSG_DONTWAIT);
      if (got > 0) continue;
      if (got < 0 && errno == EINTR) continue;
      return got == 0 || (errno != EAGAIN && errno != EWOULDBLOCK);
    }
  }

  // For poll(): -1 (no deadline) or the time to the earliest one. Called with the lock held.
  int MillisecondsToNextDeadline() const {
    if (lingering_.empty()) return -1;
    auto next = lingering_.front().deadline;
    for (const Lingering& lingering : lingering_) next = std::min(next, lingering.deadline);
    const auto left =
        std::chrono::ceil<std::chrono::milliseconds>(next - std::chrono::steady_clock::now());
    return static_cast<int>(std::clamp<int64_t>(left.count(), 0, kLinger.count()));
  }

  void Run() {
    std::vector<pollfd> fds;
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stopping_) {
      // Refuse() only appends and only this thread removes: the first fds.size() - 1 entries
      // stay the ones polled while the lock is released.
      fds.assign(1, pollfd{wake_fd_, POLLIN, 0});
      for (const Lingering& lingering : lingering_) {
        fds.push_back(pollfd{lingering.sock, POLLIN, 0});
      }
      const int timeout_ms = MillisecondsToNextDeadline();
      lock.unlock();
      const int ready = ::poll(fds.data(), fds.size(), timeout_ms);
      if (ready > 0 && (fds[0].revents & POLLIN)) {
        uint64_t value;
        (void)!::read(wake_fd_, &value, sizeof(value));
      }
      lock.lock();
      const auto now = std::chrono::steady_clock::now();
      std::vector<bool> done(lingering_.size(), false);
      for (size_t i = 0; i + 1 < fds.size(); ++i) {
        const bool closed = ready > 0 && fds[i + 1].revents != 0 && DrainedToEnd(fds[i + 1].fd);
        if (closed || now >= lingering_[i].deadline) {
          ::close(lingering_[i].sock);
          done[i] = true;
        }
      }
      size_t kept = 0;
      for (size_t i = 0; i < lingering_.size(); ++i) {
        if (!done[i]) lingering_[kept++] = lingering_[i];
      }
      lingering_.resize(kept);
    }
  }

  const std::string response_;
  const int wake_fd_;
  std::mutex mutex_;
  std::vector<Lingering> lingering_;
  bool stopping_ = false;
  std::thread thread_;
};

// Serves every open connection from one fixed pool of threads (leader/follower): the
// connections wait in one epoll set, each armed with EPOLLONESHOT, and the pool's threads block
// in epoll_wait on it. The thread that gets a ready connection owns it alone (one-shot: no
// other thread sees it until it is re-armed), serves its requests inline with the connection's
// own buffered stream, and re-arms or closes it. With one thread per keep-alive connection,
// 200 clients meant 200 threads waking every 10 ms, and latency grew with the connection
// count (p99 1.5 ms at 50 connections, 3.8-8.4 ms at 200, 12.6 ms at 400 for the same rate);
// here an idle connection costs no thread and no wake-up. The kernel wakes one waiting thread
// per ready connection (the most recent waiter first), so the pool's threads beyond the
// requests in flight just sleep; a pool as large as --http-threads means slow requests
// (200 MB uploads, downloads) cannot occupy every thread while status polls wait.
class ConnectionLoop {
 public:
  // Serves the requests that are ready (or buffered) on a connection; false closes it.
  using ServeFn = std::function<bool(ConnectionStream&)>;

  // max_connections: how many Add() takes at most (0: no cap).
  // `open_connections` counts the connections listed here (owned by the caller, outlives this).
  ConnectionLoop(int num_threads, int max_connections, int keep_alive_timeout_ms,
                 int read_timeout_ms, std::atomic<int64_t>& open_connections, ServeFn serve)
      : open_connections_(open_connections),
        max_connections_(static_cast<size_t>(std::max(0, max_connections))),
        keep_alive_(keep_alive_timeout_ms),
        read_timeout_ms_(read_timeout_ms),
        serve_(std::move(serve)),
        epoll_fd_(::epoll_create1(EPOLL_CLOEXEC)),
        stop_fd_(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)) {
    if (epoll_fd_ < 0 || stop_fd_ < 0) throw std::runtime_error("cannot create an epoll set");
    // Level-triggered, never read: once signalled, every epoll_wait returns it (the kernel
    // passes a level-triggered event on from waiter to waiter), so all threads see the stop.
    epoll_event event{};
    event.events = EPOLLIN;
    event.data.u64 = kStopId;
    ::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, stop_fd_, &event);
    for (int i = 0; i < num_threads; ++i) threads_.emplace_back([this] { RunThread(); });
    expiry_thread_ = std::thread([this] { ExpireIdleConnections(); });
  }
  ~ConnectionLoop() {
    Stop();
    ::close(epoll_fd_);
    ::close(stop_fd_);
  }

  // Takes ownership of an accepted socket, or returns false (the socket stays the caller's)
  // when max_connections are open. Only the accepting thread adds, so the count checked here
  // can only shrink before the connection is listed.
  bool Add(int sock) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (max_connections_ > 0 && connections_.size() >= max_connections_) return false;
    }
    const int one = 1;
    ::setsockopt(sock, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
    auto connection = std::make_unique<Connection>(sock, read_timeout_ms_, open_connections_);
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return true;  // closes the socket
    const uint64_t id = next_id_++;
    if (!Arm(EPOLL_CTL_ADD, sock, id)) return true;
    connections_.emplace(id, std::move(connection));
    return true;
  }

  // Wakes every thread, waits for requests in progress to end, closes all connections.
  void Stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    const uint64_t one = 1;
    (void)!::write(stop_fd_, &one, sizeof(one));
    expiry_wake_.notify_all();
    for (auto& thread : threads_) {
      if (thread.joinable()) thread.join();
    }
    if (expiry_thread_.joinable()) expiry_thread_.join();
    std::lock_guard<std::mutex> lock(mutex_);
    connections_.clear();
  }

 private:
  // Events carry a connection id rather than its fd or address: an event taken from epoll_wait
  // just before its connection expired then finds nothing, instead of a reused fd or freed memory.
  static constexpr uint64_t kStopId = 0;

  struct Connection {
    Connection(int sock, int read_timeout_ms, std::atomic<int64_t>& open_count)
        : stream(sock, read_timeout_ms), open(open_count) {
      ++open;
    }
    ~Connection() {
      ::shutdown(stream.socket(), SHUT_RDWR);
      ::close(stream.socket());
      --open;
    }
    ConnectionStream stream;
    std::atomic<int64_t>& open;
    bool busy = false;  // owned by a pool thread; only that thread may close it
    std::chrono::steady_clock::time_point idle_since = std::chrono::steady_clock::now();
  };

  bool Arm(int operation, int sock, uint64_t id) {
    epoll_event event{};
    event.events = EPOLLIN | EPOLLONESHOT;
    event.data.u64 = id;
    return ::epoll_ctl(epoll_fd_, operation, sock, &event) == 0;
  }

  void RunThread() {
    while (!stopping_) {
      epoll_event event{};
      const int ready = ::epoll_wait(epoll_fd_, &event, 1, -1);
      if (ready < 0 && errno != EINTR) return;
      if (ready <= 0) continue;
      if (event.data.u64 == kStopId) return;
      ConnectionStream* stream = Take(event.data.u64);
      if (stream != nullptr) Release(event.data.u64, serve_(*stream));
    }
  }

  ConnectionStream* Take(uint64_t id) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = connections_.find(id);
    if (it == connections_.end()) return nullptr;
    it->second->busy = true;
    return &it->second->stream;
  }

  // Re-arms a connection after its requests, or closes it (outside the lock).
  void Release(uint64_t id, bool keep) {
    std::unique_ptr<Connection> closing;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto it = connections_.find(id);
      if (it == connections_.end()) return;  // not reached: a busy connection stays listed
      Connection& connection = *it->second;
      connection.busy = false;
      connection.idle_since = std::chrono::steady_clock::now();
      if (keep && !stopping_ && Arm(EPOLL_CTL_MOD, connection.stream.socket(), id)) return;
      closing = std::move(it->second);
      connections_.erase(it);
    }
  }

  // Closes connections idle for longer than the keep-alive timeout, checking a few times per
  // timeout. One whose next request has arrived (its event may be on its way to a thread) stays.
  void ExpireIdleConnections() {
    const auto interval = std::clamp(keep_alive_ / 10, std::chrono::milliseconds(10),
                                     std::chrono::milliseconds(1000));
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stopping_) {
      expiry_wake_.wait_for(lock, interval);
      const auto now = std::chrono::steady_clock::now();
      std::vector<std::unique_ptr<Connection>> expired;
      for (auto it = connections_.begin(); it != connections_.end();) {
        Connection& connection = *it->second;
        pollfd fd{connection.stream.socket(), POLLIN, 0};
        if (!connection.busy && now - connection.idle_since >= keep_alive_ &&
            ::poll(&fd, 1, 0) == 0) {
          expired.push_back(std::move(it->second));
          it = connections_.erase(it);
        } else {
          ++it;
        }
      }
      lock.unlock();
      expired.clear();
      lock.lock();
    }
  }

  std::atomic<int64_t>& open_connections_;
  const size_t max_connections_;
  const std::chrono::milliseconds keep_alive_;
  const int read_timeout_ms_;
  const ServeFn serve_;
  const int epoll_fd_;
  const int stop_fd_;
  std::vector<std::thread> threads_;
  std::thread expiry_thread_;
  std::condition_variable expiry_wake_;
  std::mutex mutex_;
  std::unordered_map<uint64_t, std::unique_ptr<Connection>> connections_;
  uint64_t next_id_ = kStopId + 1;
  std::atomic<bool> stopping_{false};
};

// Runs httplib's per-connection task on the accepting thread: handing a socket to the
// ConnectionLoop is a few system calls, cheaper than a hop through another thread.
class InlineTaskQueue : public httplib::TaskQueue {
 public:
  void enqueue(std::function<void()> fn) override { fn(); }
  void shutdown() override {}
};

// Set on the accepting thread while it runs the task of a connection beyond the cap.
thread_local bool refusing_connection = false;

// --http-loop threads: httplib's pool, with the connections handed to it (queued or served)
// counted against max_connections. httplib's task for an accepted socket is an opaque closure
// over process_and_close_socket(sock); beyond the cap it runs right here on the accepting
// thread with `refusing_connection` set, and process_and_close_socket refuses the socket.
class CappedThreadPool : public httplib::TaskQueue {
 public:
  // `open` counts the connections handed to the pool (owned by the caller, outlives this).
  CappedThreadPool(int num_threads, int max_connections, std::atomic<int64_t>& open)
      : pool_(static_cast<size_t>(num_threads)), max_connections_(max_connections), open_(open) {}
  void enqueue(std::function<void()> fn) override {
    // Only the accepting thread enqueues: the count can only shrink between check and add.
    if (max_connections_ > 0 && open_ >= max_connections_) {
      refusing_connection = true;
      fn();
      refusing_connection = false;
      return;
    }
    ++open_;
    pool_.enqueue([this, fn = std::move(fn)] {
      fn();
      --open_;
    });
  }
  void shutdown() override { pool_.shutdown(); }

 private:
  httplib::ThreadPool pool_;
  const int max_connections_;
  std::atomic<int64_t>& open_;
};

// httplib 0.11 waits for a keep-alive connection's next request by polling it for 10 ms and
// then sleeping 1 ms, over and over: twice the wakeups, and up to 1 ms added to a request that
// lands in the sleep. It also rebuilds its socket stream per request and writes headers and
// body as two segments. This server keeps one buffered stream per connection, sends each
// response in one piece and waits on the socket and on an eventfd that Stop() signals.
class KeepAliveServer : public httplib::Server {
 public:
  KeepAliveServer() : stop_fd_(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)) {}
  ~KeepAliveServer() override {
    if (stop_fd_ >= 0) ::close(stop_fd_);
  }
  // Wakes every connection waiting for its next request, so stop() does not wait for them.
  void WakeIdleConnections() {
    stopping_ = true;
    const uint64_t one = 1;
    if (stop_fd_ >= 0) (void)!::write(stop_fd_, &one, sizeof(one));
  }
  // httplib listens with a backlog of 5: 200 clients connecting at once overflow it, and the
  // dropped SYNs are retried only after 1 s (wrk saw 1.7 s maxima and timeouts). Listening
  // again on the bound socket raises the backlog.
  void RaiseListenBacklog() {
    const int sock = svr_sock_;
    if (sock >= 0) ::listen(sock, SOMAXCONN);
  }
  void ResetStop() {
    stopping_ = false;
    uint64_t value;
    if (stop_fd_ >= 0) (void)!::read(stop_fd_, &value, sizeof(value));
  }
  // Accepted sockets go to `loop` (owned by the caller, alive until listening ends) when set,
  // else each gets a thread of httplib's task queue until it closes.
  void SetConnectionLoop(ConnectionLoop* loop) { loop_ = loop; }
  // Where connections beyond the cap go (owned by the caller, alive until listening ends), and
  // what counts them.
  void SetConnectionRefuser(ConnectionRefuser* refuser, std::function<void()> on_refused) {
    refuser_ = refuser;
    on_refused_ = std::move(on_refused);
  }
  // The ConnectionLoop's ServeFn: every request ready on the connection, pipelined ones too.
  bool ServeReady(ConnectionStream& stream) {
    do {
      bool connection_closed = false;
      close_after_response = false;
      const bool ok =
          process_request(stream, /*close_connection=*/stopping_, connection_closed, nullptr);
      const bool flushed = stream.Flush();
      if (flushed && close_after_response) LingerBeforeClose(stream.socket(), linger_ms());
      if (!flushed || !ok || connection_closed || close_after_response || stopping_) {
        return false;
      }
    } while (stream.has_buffered());
    return true;
  }
  int read_timeout_ms() const {
    return static_cast<int>(read_timeout_sec_ * 1000 + read_timeout_usec_ / 1000);
  }
  int keep_alive_timeout_ms() const { return keep_alive_timeout_ms_; }
  int linger_ms() const { return std::min(read_timeout_ms(), unread_body_linger_ms_); }
  void SetTimeouts(int keep_alive_timeout_ms, int read_timeout_ms, int unread_body_linger_ms) {
    keep_alive_timeout_ms_ = keep_alive_timeout_ms;
    unread_body_linger_ms_ = unread_body_linger_ms;
    set_keep_alive_timeout((keep_alive_timeout_ms + 999) / 1000);
    set_read_timeout(read_timeout_ms / 1000, (read_timeout_ms % 1000) * 1000);
  }

 private:
  bool process_and_close_socket(int sock) override {
    if (refusing_connection || (loop_ != nullptr && !loop_->Add(sock))) {
      Refuse(sock);
      return false;
    }
    if (loop_ != nullptr) return true;
    const int one = 1;
    ::setsockopt(sock, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
    // An idle keep-alive connection closes after keep_alive_timeout_ms_, a request whose bytes
    // stall fails after the read timeout.
    ConnectionStream stream(sock, read_timeout_ms());
    bool ok = false;
    while (!stopping_ && WaitForRequest(stream)) {
      bool connection_closed = false;
      close_after_response = false;
      ok = process_request(stream, /*close_connection=*/stopping_, connection_closed, nullptr);
      const bool flushed = stream.Flush();
      if (flushed && close_after_response) LingerBeforeClose(stream.socket(), linger_ms());
      ok = flushed && ok;
      if (!ok || connection_closed || close_after_response) break;
    }
    ::shutdown(sock, SHUT_RDWR);
    ::close(sock);
    return ok;
  }

  // Waits in 10 ms slices rather than one long poll(): measured with wrk at 2,000 polls/s on
  // the 2-core machine while other processes kept both cores busy (load ~10), p99 was 3.6-5.4 ms
  // with 10 ms slices against 9.6-44 ms with one blocking poll (the scheduler seems to place a
  // thread that slept for 100 ms behind the running tasks). The slices cost ~20,000 cheap
  // wakeups a second with 200 open connections; httplib's sleep(1 ms) between polls is gone.
  bool WaitForRequest(const ConnectionStream& stream) const {
    if (stream.has_buffered()) return true;
    constexpr int kSliceMs = 10;
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(keep_alive_timeout_ms_);
    pollfd fds[2] = {{stream.socket(), POLLIN, 0}, {stop_fd_, POLLIN, 0}};
    while (!stopping_ && std::chrono::steady_clock::now() < deadline) {
      const int ready = ::poll(fds, stop_fd_ >= 0 ? 2 : 1, kSliceMs);
      if (ready < 0 && errno != EINTR) return false;
      if (ready > 0) return (fds[0].revents & (POLLIN | POLLHUP | POLLERR)) && !stopping_;
    }
    return false;
  }

  void Refuse(int sock) {
    if (refuser_ == nullptr) {  // not reached: a cap comes with a refuser
      ::close(sock);
      return;
    }
    refuser_->Refuse(sock);
    if (on_refused_) on_refused_();
  }

  int stop_fd_;
  std::atomic<bool> stopping_{false};
  ConnectionLoop* loop_ = nullptr;
  ConnectionRefuser* refuser_ = nullptr;
  std::function<void()> on_refused_;
  int keep_alive_timeout_ms_ = 5000;
  int unread_body_linger_ms_ = 1000;
};

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

void HttpResponse::JsonText(int status_code, std::string json_text) {
  status = status_code;
  content_type = "application/json";
  body = std::move(json_text);
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
    std::vector<Segment> segments;
    bool whole_segments = false;  // `segments` match as the regex does (PatternToSegments)
  };

  HttpServerOptions options;
  RequestCounter counter;
  // Accepted and not yet closed, in either loop (declared before `server`, which uses it).
  std::atomic<int64_t> open_connections{0};
  KeepAliveServer server;
  std::unique_ptr<ConnectionLoop> loop;  // with options.event_loop, between Start() and Stop()
  std::unique_ptr<ConnectionRefuser> refuser;  // with max_connections, between Start() and Stop()
  std::thread thread;
  std::atomic<bool> listen_returned{false};
  // GET and DELETE routes by method, in the order registered (httplib tries them in that order
  // too); fixed once serving starts.
  std::map<std::string, std::vector<std::shared_ptr<const RouteInfo>>> bodyless_routes;
  std::string expected_authorization;  // "Bearer <token>"

  // `values`: the path parameters in order; nullptr takes them from the regex's req.matches.
  void Dispatch(const RouteInfo& route, const httplib::Request& req, httplib::Response& res,
                const httplib::ContentReader* reader,
                const std::vector<std::string>* values = nullptr);
  bool DispatchBodyless(const httplib::Request& req, httplib::Response& res);
  HttpRequest MakeRequest(const RouteInfo& route, const httplib::Request& req,
                          const httplib::ContentReader* reader,
                          const std::vector<std::string>* values, bool& body_read);
  void Install();
};

// `body_read` becomes true once a streaming handler has read its body to the end.
HttpRequest HttpServer::Impl::MakeRequest(const RouteInfo& route, const httplib::Request& req,
                                          const httplib::ContentReader* reader,
                                          const std::vector<std::string>* values, bool& body_read) {
  HttpRequest request;
  request.method = req.method;
  request.path = req.path;
  if (values != nullptr) {
    for (size_t i = 0; i < route.names.size() && i < values->size(); ++i) {
      request.path_params[route.names[i]] = (*values)[i];
    }
  } else {
    for (size_t i = 0; i < route.names.size() && i + 1 < req.matches.size(); ++i) {
      request.path_params[route.names[i]] = req.matches[i + 1].str();
    }
  }
  request.query.insert(req.params.begin(), req.params.end());
  request.body = req.body;
  request.header = [&req](const std::string& name) { return req.get_header_value(name); };
  if (reader) {
    request.is_multipart = req.is_multipart_form_data();
    request.read_body = [reader,
                         &body_read](const std::function<bool(const char*, size_t)>& on_data) {
      body_read = (*reader)([&](const char* data, size_t size) { return on_data(data, size); });
      return body_read;
    };
    request.read_multipart = [reader, &body_read](
                                 const std::function<bool(const MultipartPart&)>& on_part,
                                 const std::function<bool(const char*, size_t)>& on_data) {
      body_read = (*reader)(
          [&](const httplib::MultipartFormData& part) {
            return on_part(MultipartPart{part.name, part.filename, part.content_type});
          },
          [&](const char* data, size_t size) { return on_data(data, size); });
      return body_read;
    };
  }
  return request;
}

void HttpServer::Impl::Dispatch(const RouteInfo& route, const httplib::Request& req,
                                httplib::Response& res, const httplib::ContentReader* reader,
                                const std::vector<std::string>* values) {
  current_route = route.pattern;
  HttpResponse response;
  bool body_read = false;
  try {
    route.handler(MakeRequest(route, req, reader, values, body_read), response);
  } catch (const HttpError& e) {
    response.Json(e.status, api::ErrorJson(e.code, e.what(), e.details));
  } catch (const std::invalid_argument& e) {
    response.Json(400, api::ErrorJson("invalid_argument", e.what()));
  } catch (const std::exception& e) {
    response.Json(500, api::ErrorJson("internal", e.what()));
  } catch (...) {
    response.Json(500, api::ErrorJson("internal", "unknown error"));
  }
  if (reader != nullptr && !body_read && HasBody(req)) {
    // See close_after_response. A "Connection: close" request header makes httplib say so in
    // the response (the request is httplib's mutable local, as above).
    close_after_response = true;
    auto& headers = const_cast<httplib::Request&>(req).headers;
    headers.erase("Connection");
    headers.emplace("Connection", "close");
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

// httplib finds a handler by trying each route's std::regex in turn: for a status poll that was
// ~12 % of its user-space instructions (7 regexes before /api/v1/jobs/{id}). A GET or DELETE
// without a body is matched here by segments instead, in the same order with the same result;
// anything else (a body to read, a pattern with a partial-segment parameter, no match: 404)
// goes on to httplib as before. Only under /api/: httplib would first look for a static file
// of that path under a mount at "/" (a stat() per request); the web folder has no api/ folder,
// and elsewhere static files keep their precedence.
bool HttpServer::Impl::DispatchBodyless(const httplib::Request& req, httplib::Response& res) {
  if (req.path.rfind("/api/", 0) != 0 || HasBody(req)) return false;
  const auto routes = bodyless_routes.find(req.method);
  if (routes == bodyless_routes.end()) return false;
  thread_local std::vector<std::string> values;
  for (const auto& route : routes->second) {
    if (!route->whole_segments) return false;  // its regex decides from here on
    if (MatchSegments(route->segments, req.path, values)) {
      Dispatch(*route, req, res, nullptr, &values);
      return true;
    }
  }
  return false;
}

void HttpServer::Impl::Install() {
  expected_authorization = "Bearer " + options.token;
  const int threads = options.num_threads;
  const int max_connections = options.max_connections;
  std::atomic<int64_t>* open = &open_connections;
  if (options.event_loop) {
    server.new_task_queue = [] { return new InlineTaskQueue(); };
  } else {
    server.new_task_queue = [threads, max_connections, open] {
      return new CappedThreadPool(threads, max_connections, *open);
    };
  }
  server.SetTimeouts(options.keep_alive_timeout_ms, options.read_timeout_ms,
                     options.unread_body_linger_ms);
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
    // A request without Content-Length or Transfer-Encoding has no body (RFC 9112, 6.3), but
    // httplib 0.11 reads the body of such a POST, PUT or DELETE until the client closes: a
    // `curl -X POST .../cancel` waited out the read timeout (5 s) and got 400. Say it is empty.
    if (!req.has_header(kContentLength) && !req.has_header(kTransferEncoding)) {
      headers.emplace(kContentLength, "0");
    }
    const bool protected_path = req.path.rfind("/api/", 0) == 0 || req.path == "/metrics";
    if (!options.token.empty() && protected_path &&
        !ConstantTimeEquals(req.get_header_value(kAuthorization), expected_authorization)) {
      current_route = "auth";
      res.status = 401;
      res.set_header("WWW-Authenticate", "Bearer");
      res.set_content(api::ErrorJson("unauthorized", "a valid bearer token is required").dump(),
                      "application/json");
      return httplib::Server::HandlerResponse::Handled;
    }
    return DispatchBodyless(req, res) ? httplib::Server::HandlerResponse::Handled
                                      : httplib::Server::HandlerResponse::Unhandled;
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
  route->whole_segments = PatternToSegments(pattern, route->segments);
  if (method == "GET" || method == "DELETE") impl_->bodyless_routes[method].push_back(route);
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

int64_t HttpServer::OpenConnections() const { return impl_->open_connections.load(); }

int HttpServer::Bind(const std::string& host, int port) {
  const int bound = port == 0 ? impl_->server.bind_to_any_port(host)
                              : (impl_->server.bind_to_port(host, port) ? port : -1);
  if (bound <= 0) {
    throw std::runtime_error("cannot bind " + host + ":" + std::to_string(port));
  }
  impl_->server.RaiseListenBacklog();
  return bound;
}

void HttpServer::Start() {
  impl_->listen_returned = false;
  impl_->server.ResetStop();
  if (impl_->options.event_loop) {
    KeepAliveServer& server = impl_->server;
    impl_->loop = std::make_unique<ConnectionLoop>(
        impl_->options.num_threads, impl_->options.max_connections, server.keep_alive_timeout_ms(),
        server.read_timeout_ms(), impl_->open_connections,
        [&server](ConnectionStream& stream) { return server.ServeReady(stream); });
  }
  if (impl_->options.max_connections > 0) {
    impl_->refuser = std::make_unique<ConnectionRefuser>(impl_->options.max_connections);
  }
  impl_->server.SetConnectionLoop(impl_->loop.get());
  Impl* impl = impl_.get();
  impl_->server.SetConnectionRefuser(impl_->refuser.get(), [impl] {
    if (impl->counter) impl->counter(kRefusedRoute, 503, 0.0);
  });
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
  impl_->server.WakeIdleConnections();
  impl_->server.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
  // Listening has ended: no socket reaches the loop or the refuser any more.
  impl_->server.SetConnectionLoop(nullptr);
  impl_->server.SetConnectionRefuser(nullptr, nullptr);
  impl_->loop.reset();
  impl_->refuser.reset();
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
