// The HTTP layer's connection handling with the event loop (HttpServerOptions::event_loop): more
// open keep-alive connections than threads, slow uploads beside status polls, the keep-alive
// and read timeouts, a prompt Stop() with idle connections open, the cap on open connections
// (both loops) and a body left unread. Real sockets on loopback.

#include "server/http.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace omnirig::server {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// A client socket that sends raw bytes and reads responses with a receive timeout.
class RawConnection {
 public:
  explicit RawConnection(int port, double timeout_s = 3.0)
      : fd_(::socket(AF_INET, SOCK_STREAM, 0)) {
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<uint16_t>(port));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
    const auto micros = static_cast<long>(timeout_s * 1e6);
    const timeval timeout{micros / 1000000, micros % 1000000};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
  }
  ~RawConnection() { ::close(fd_); }
  RawConnection(const RawConnection&) = delete;
  RawConnection& operator=(const RawConnection&) = delete;

  bool connected() const { return connected_; }
  bool Send(const std::string& bytes) {
    return ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) ==
           static_cast<ssize_t>(bytes.size());
  }
  // Reads one response with a Content-Length body; "" on timeout or close.
  std::string ReadResponse() {
    while (true) {
      const size_t header_end = buffer_.find("\r\n\r\n");
      if (header_end != std::string::npos) {
        const size_t length_at = buffer_.find("Content-Length: ");
        const size_t length =
            length_at < header_end ? std::stoul(buffer_.substr(length_at + 16)) : 0;
        if (buffer_.size() >= header_end + 4 + length) {
          std::string response = buffer_.substr(0, header_end + 4 + length);
          buffer_.erase(0, response.size());
          return response;
        }
      }
      if (!Receive()) return "";
    }
  }
  // True when the server closes the connection before the receive timeout: EOF, or a reset
  // for a connection still in the listen backlog when the listening socket closed.
  bool ClosedByServer() {
    char byte;
    const ssize_t got = ::recv(fd_, &byte, 1, 0);
    return got == 0 || (got < 0 && errno == ECONNRESET);
  }

 private:
  bool Receive() {
    char chunk[4096];
    const ssize_t got = ::recv(fd_, chunk, sizeof(chunk), 0);
    if (got <= 0) return false;
    buffer_.append(chunk, static_cast<size_t>(got));
    return true;
  }

  int fd_;
  bool connected_ = false;
  std::string buffer_;
};

std::string Get(const std::string& path) {
  return "GET " + path + " HTTP/1.1\r\nHost: test\r\n\r\n";
}

class HttpServerTest : public ::testing::Test {
 protected:
  // Routes: GET /status (JSON), POST /cancel (answers with the body's size), PUT /upload
  // (streamed; answers with the byte count).
  int Start(const HttpServerOptions& options) {
    server_ =
        std::make_unique<HttpServer>(options, [this](const std::string& route, int status, double) {
          std::lock_guard<std::mutex> lock(mutex_);
          ++counts_[route + " " + std::to_string(status)];
        });
    server_->Route("GET", "/status", [](const HttpRequest&, HttpResponse& response) {
      response.Json(200, {{"state", "running"}});
    });
    server_->Route("POST", "/cancel", [](const HttpRequest& request, HttpResponse& response) {
      response.Json(200, {{"body_bytes", request.body.size()}});
    });
    server_->Route(
        "PUT", "/upload",
        [](const HttpRequest& request, HttpResponse& response) {
          size_t bytes = 0;
          request.read_body([&bytes](const char*, size_t size) {
            bytes += size;
            return true;
          });
          response.Json(201, {{"bytes", bytes}});
        },
        /*streaming=*/true);
    // Refuses before reading the body (as a route does for a missing dataset).
    server_->Route(
        "PUT", "/refuse",
        [](const HttpRequest&, HttpResponse&) { throw HttpError(404, "not_found", "refused"); },
        /*streaming=*/true);
    // Under /api/, bodyless GETs and DELETEs are matched by segments rather than by httplib's
    // regexes (http.cc, DispatchBodyless); each answers with its name and path parameters.
    const auto echo = [](const std::string& name) {
      return [name](const HttpRequest& request, HttpResponse& response) {
        nlohmann::json params = nlohmann::json::object();
        for (const auto& [key, value] : request.path_params) params[key] = value;
        response.Json(200, {{"route", name},
                            {"params", params},
                            {"q", request.Query("q").value_or("")},
                            {"body", request.body}});
      };
    };
    server_->Route("GET", "/api/v1/items", echo("list"));
    server_->Route("GET", "/api/v1/items/{id}", echo("get"));
    server_->Route("GET", "/api/v1/items/{id}/files/{name+}", echo("file"));
    server_->Route("DELETE", "/api/v1/items/{id}", echo("delete"));
    server_->Route("GET", "/api/v1/odd/{id}.json", echo("odd"));  // not whole segments: regex
    server_->Route("GET", "/api/v1/odd/{id}", echo("after_odd"));
    const int port = server_->Bind("127.0.0.1", 0);
    server_->Start();
    return port;
  }
  int Count(const std::string& key) {
    std::lock_guard<std::mutex> lock(mutex_);
    return counts_[key];
  }

  static HttpServerOptions EventLoopOptions(int threads) {
    HttpServerOptions options;
    options.event_loop = true;
    options.num_threads = threads;
    return options;
  }

  // With `cap` open keep-alive connections (each has been served, so the server holds them
  // all), one more gets a prompt 503 with the JSON error and Retry-After and is closed; the open
  // ones still work; once two of them close, a new connection is served again. Every 503 seen
  // is counted as a refused connection.
  void ExpectConnectionCap(int port, int cap) {
    std::vector<std::unique_ptr<RawConnection>> open;
    for (int i = 0; i < cap; ++i) {
      open.push_back(std::make_unique<RawConnection>(port));
      ASSERT_TRUE(open.back()->Send(Get("/status")));
      ASSERT_EQ(open.back()->ReadResponse().rfind("HTTP/1.1 200", 0), 0u) << "connection " << i;
    }
    int refused = 0;
    {
      RawConnection extra(port);
      ASSERT_TRUE(extra.connected());
      const auto start = Clock::now();
      ASSERT_TRUE(extra.Send(Get("/status")));
      const std::string response = extra.ReadResponse();
      EXPECT_LT(SecondsSince(start), 1.0);
      ASSERT_EQ(response.rfind("HTTP/1.1 503", 0), 0u) << response;
      ++refused;
      EXPECT_NE(response.find("Retry-After: 1\r\n"), std::string::npos) << response;
      EXPECT_NE(response.find("Connection: close\r\n"), std::string::npos) << response;
      EXPECT_NE(response.find("{\"error\":{\"code\":\"unavailable\""), std::string::npos)
          << response;
      EXPECT_NE(response.find("too many open connections (" + std::to_string(cap) + ")"),
                std::string::npos)
          << response;
      EXPECT_TRUE(extra.ClosedByServer());
    }
    for (auto& connection : open) {
      ASSERT_TRUE(connection->Send(Get("/status")));
      EXPECT_EQ(connection->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
    }
    open.resize(static_cast<size_t>(cap - 2));
    // The server sees the two closes when their end-of-file events are served: poll.
    bool served = false;
    const auto start = Clock::now();
    while (!served && SecondsSince(start) < 5) {
      RawConnection fresh(port);
      ASSERT_TRUE(fresh.Send(Get("/status")));
      const std::string response = fresh.ReadResponse();
      served = response.rfind("HTTP/1.1 200", 0) == 0;
      if (!served) {
        ASSERT_EQ(response.rfind("HTTP/1.1 503", 0), 0u) << response;
        ++refused;
      }
    }
    EXPECT_TRUE(served);
    for (auto& connection : open) {
      ASSERT_TRUE(connection->Send(Get("/status")));
      EXPECT_EQ(connection->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
    }
    // The counter is called just after the 503 is written: poll briefly.
    const auto count_start = Clock::now();
    while (Count(std::string(kRefusedRoute) + " 503") < refused && SecondsSince(count_start) < 2) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_EQ(Count(std::string(kRefusedRoute) + " 503"), refused);
  }

  std::unique_ptr<HttpServer> server_;
  std::mutex mutex_;
  std::map<std::string, int> counts_;
};

TEST(DefaultMaxConnectionsTest, LeavesAReserveOfDescriptors) {
  // 256 + 2 per HTTP thread stay for SQLite, uploads, downloads and artifacts.
  EXPECT_EQ(DefaultMaxConnections(1024, 128), 1024 - 256 - 256);
  EXPECT_EQ(DefaultMaxConnections(4096, 16), 4096 - 256 - 32);
  EXPECT_EQ(DefaultMaxConnections(1 << 20, 128), 4096);  // memory: 64 KiB buffer each
  EXPECT_EQ(DefaultMaxConnections(300, 128), 16);
  // The soft limit is raised to the hard one (when the kernel allows, at least not lowered).
  EXPECT_GE(RaiseOpenFileLimit(), 64);
}

TEST_F(HttpServerTest, EventLoopRefusesConnectionsBeyondTheCap) {
  HttpServerOptions options = EventLoopOptions(/*threads=*/2);
  options.max_connections = 4;
  ExpectConnectionCap(Start(options), options.max_connections);
}

TEST_F(HttpServerTest, ThreadsLoopRefusesConnectionsBeyondTheCap) {
  HttpServerOptions options;
  options.event_loop = false;
  options.num_threads = 8;  // more than the cap: every open connection has its thread
  options.max_connections = 4;
  ExpectConnectionCap(Start(options), options.max_connections);
}

TEST_F(HttpServerTest, ServesManyMoreKeepAliveConnectionsThanThreads) {
  const int port = Start(EventLoopOptions(/*threads=*/4));
  // With one thread per connection, connections 5..64 would wait for the first four to close.
  constexpr int kConnections = 64;
  std::vector<std::unique_ptr<RawConnection>> connections;
  for (int i = 0; i < kConnections; ++i) {
    connections.push_back(std::make_unique<RawConnection>(port));
    ASSERT_TRUE(connections.back()->connected());
  }
  for (int round = 0; round < 3; ++round) {
    for (auto& connection : connections) ASSERT_TRUE(connection->Send(Get("/status")));
    for (auto& connection : connections) {
      const std::string response = connection->ReadResponse();
      ASSERT_EQ(response.rfind("HTTP/1.1 200", 0), 0u) << "round " << round << ": " << response;
      EXPECT_NE(response.find("\"running\""), std::string::npos);
    }
  }
  // Pipelined requests on one connection: all answered, in order.
  ASSERT_TRUE(connections[0]->Send(Get("/status") + Get("/nothing") + Get("/status")));
  EXPECT_EQ(connections[0]->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  EXPECT_EQ(connections[0]->ReadResponse().rfind("HTTP/1.1 404", 0), 0u);
  EXPECT_EQ(connections[0]->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  // The request counter sees each request's route (set and read on the serving thread). The
  // logger runs after the response is written, so the last count may lag: poll briefly.
  const int expected = 3 * kConnections + 2;
  const auto start = Clock::now();
  while (Count("GET /status 200") < expected && SecondsSince(start) < 2) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(Count("GET /status 200"), expected);
  EXPECT_EQ(Count("unmatched 404"), 1);
}

TEST_F(HttpServerTest, ClosesTheConnectionAfterABodyTheHandlerDidNotRead) {
  const int port = Start(EventLoopOptions(/*threads=*/2));
  // The unread body and a request pipelined after it: the body's bytes must not be parsed as
  // requests (a 400 each), so the answer says "Connection: close" and the connection ends.
  RawConnection connection(port);
  const std::string body(100000, 'x');
  ASSERT_TRUE(connection.Send("PUT /refuse HTTP/1.1\r\nHost: test\r\nContent-Length: " +
                              std::to_string(body.size()) + "\r\n\r\n" + body + Get("/status")));
  const std::string response = connection.ReadResponse();
  EXPECT_EQ(response.rfind("HTTP/1.1 404", 0), 0u) << response;
  EXPECT_NE(response.find("Connection: close\r\n"), std::string::npos) << response;
  EXPECT_TRUE(connection.ClosedByServer());
  EXPECT_EQ(Count("unmatched 400"), 0);
  // A body the handler read to the end keeps the connection.
  RawConnection kept(port);
  ASSERT_TRUE(kept.Send("PUT /upload HTTP/1.1\r\nHost: test\r\nContent-Length: 3\r\n\r\nabc" +
                        Get("/status")));
  EXPECT_EQ(kept.ReadResponse().rfind("HTTP/1.1 201", 0), 0u);
  EXPECT_EQ(kept.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
}

// The route, parameters, query and body a request reached, or the status line when not 200.
nlohmann::json Reached(RawConnection& connection, const std::string& request) {
  if (!connection.Send(request)) return "send failed";
  const std::string response = connection.ReadResponse();
  if (response.rfind("HTTP/1.1 200", 0) != 0) return response.substr(0, response.find('\r'));
  return nlohmann::json::parse(response.substr(response.find("\r\n\r\n") + 4));
}

TEST_F(HttpServerTest, MatchesApiRoutesAsTheirPatternsSay) {
  const int port = Start(EventLoopOptions(/*threads=*/2));
  RawConnection connection(port);
  const auto reached = [&connection](const std::string& request) {
    return Reached(connection, request);
  };
  EXPECT_EQ(reached(Get("/api/v1/items"))["route"], "list");
  EXPECT_EQ(reached(Get("/api/v1/items/abc"))["params"], nlohmann::json({{"id", "abc"}}));
  EXPECT_EQ(reached(Get("/api/v1/items/a%20b?q=7"))["params"], nlohmann::json({{"id", "a b"}}));
  EXPECT_EQ(reached(Get("/api/v1/items/a%20b?q=7"))["q"], "7");
  EXPECT_EQ(reached(Get("/api/v1/items/x/files/cam0/000012.png"))["params"],
            nlohmann::json({{"id", "x"}, {"name", "cam0/000012.png"}}));
  EXPECT_EQ(reached("DELETE /api/v1/items/abc HTTP/1.1\r\nHost: test\r\n\r\n")["route"], "delete");
  // A pattern with a parameter inside a segment, and the routes after it, go to the regexes.
  EXPECT_EQ(reached(Get("/api/v1/odd/7.json"))["params"], nlohmann::json({{"id", "7"}}));
  EXPECT_EQ(reached(Get("/api/v1/odd/7.json"))["route"], "odd");
  EXPECT_EQ(reached(Get("/api/v1/odd/8"))["route"], "after_odd");
  // No route: httplib's 404, counted as unmatched, on the same connection.
  for (const std::string path :
       {"/api/v1/items/", "/api/v1/items//files/a", "/api/v1/items/x/files/", "/api/v1/items/x/y",
        "/api/v1/itemsx", "/api/v2/items"}) {
    EXPECT_EQ(reached(Get(path)), "HTTP/1.1 404 Not Found") << path;
  }
  EXPECT_EQ(reached("DELETE /api/v1/items HTTP/1.1\r\nHost: test\r\n\r\n"),
            "HTTP/1.1 404 Not Found");
  // A DELETE with a body takes httplib's path, which reads the body.
  const nlohmann::json with_body =
      reached("DELETE /api/v1/items/b HTTP/1.1\r\nHost: test\r\nContent-Length: 3\r\n\r\nxyz");
  EXPECT_EQ(with_body["params"], nlohmann::json({{"id", "b"}}));
  EXPECT_EQ(with_body["body"], "xyz");
  EXPECT_EQ(reached(Get("/api/v1/items/c"))["params"], nlohmann::json({{"id", "c"}}));
  // The request counter sees the route patterns either way.
  const auto start = Clock::now();
  while (Count("GET /api/v1/items/{id} 200") < 4 && SecondsSince(start) < 2) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(Count("GET /api/v1/items/{id} 200"), 4);
  EXPECT_EQ(Count("GET /api/v1/odd/{id}.json 200"), 2);
  EXPECT_EQ(Count("DELETE /api/v1/items/{id} 200"), 2);
  EXPECT_EQ(Count("unmatched 404"), 7);
}

TEST_F(HttpServerTest, CountsOpenConnections) {
  for (const bool event_loop : {true, false}) {
    HttpServerOptions options = EventLoopOptions(/*threads=*/4);
    options.event_loop = event_loop;
    const int port = Start(options);
    EXPECT_EQ(server_->OpenConnections(), 0);
    std::vector<std::unique_ptr<RawConnection>> connections;
    for (int i = 0; i < 3; ++i) {
      connections.push_back(std::make_unique<RawConnection>(port));
      ASSERT_TRUE(connections.back()->Send(Get("/status")));
      ASSERT_EQ(connections.back()->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
    }
    EXPECT_EQ(server_->OpenConnections(), 3) << "event_loop " << event_loop;
    connections.resize(1);
    // The server sees the closes when it next looks at the sockets: poll.
    const auto start = Clock::now();
    while (server_->OpenConnections() != 1 && SecondsSince(start) < 3) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    EXPECT_EQ(server_->OpenConnections(), 1) << "event_loop " << event_loop;
    server_->Stop();
    EXPECT_EQ(server_->OpenConnections(), 0) << "event_loop " << event_loop;
  }
}

TEST_F(HttpServerTest, AClientIgnoringConnectionCloseHoldsTheThreadBriefly) {
  // One serving thread, the default linger (1 s) and read timeout (5 s).
  const int port = Start(EventLoopOptions(/*threads=*/1));
  RawConnection ignoring(port);
  ASSERT_TRUE(ignoring.Send("PUT /refuse HTTP/1.1\r\nHost: test\r\nContent-Length: 100000\r\n\r\n" +
                            std::string(1000, 'x')));
  const std::string response = ignoring.ReadResponse();
  EXPECT_EQ(response.rfind("HTTP/1.1 404", 0), 0u) << response;
  EXPECT_NE(response.find("Connection: close\r\n"), std::string::npos) << response;
  // The client keeps its end open and sends nothing more. The only thread lingers on it for
  // the linger, not the read timeout: another client's poll is answered within its 3 s receive
  // timeout (it waited 5 s before).
  RawConnection poll(port);
  const auto start = Clock::now();
  ASSERT_TRUE(poll.Send(Get("/status")));
  EXPECT_EQ(poll.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  EXPECT_LT(SecondsSince(start), 2.5);
}

TEST_F(HttpServerTest, PostWithoutContentLengthHasAnEmptyBody) {
  const int port = Start(EventLoopOptions(/*threads=*/2));
  // What `curl -X POST URL` sends: no Content-Length, no body. Answered at once, not after the
  // read timeout (5 s; the connection's receive timeout is 3 s), and the connection stays usable.
  RawConnection connection(port);
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(connection.Send("POST /cancel HTTP/1.1\r\nHost: test\r\n\r\n"));
    const std::string response = connection.ReadResponse();
    EXPECT_EQ(response.rfind("HTTP/1.1 200", 0), 0u) << response;
    EXPECT_NE(response.find("\"body_bytes\":0"), std::string::npos) << response;
  }
  // A body with a length is still read.
  ASSERT_TRUE(
      connection.Send("POST /cancel HTTP/1.1\r\nHost: test\r\nContent-Length: 3\r\n\r\nabc"));
  EXPECT_NE(connection.ReadResponse().find("\"body_bytes\":3"), std::string::npos);
}

TEST_F(HttpServerTest, SlowUploadsDoNotBlockStatusPolls) {
  const int port = Start(EventLoopOptions(/*threads=*/4));
  // Three uploads that send their headers and half the body, then stall: three threads wait
  // in them (up to the read timeout).
  constexpr size_t kBodyBytes = 1 << 20;
  const std::string half(kBodyBytes / 2, 'x');
  std::vector<std::unique_ptr<RawConnection>> uploads;
  for (int i = 0; i < 3; ++i) {
    uploads.push_back(std::make_unique<RawConnection>(port));
    ASSERT_TRUE(uploads.back()->Send("PUT /upload HTTP/1.1\r\nHost: test\r\nContent-Length: " +
                                     std::to_string(kBodyBytes) + "\r\n\r\n" + half));
  }
  // Polls on 20 other connections are all answered meanwhile, promptly.
  std::vector<std::unique_ptr<RawConnection>> polls;
  for (int i = 0; i < 20; ++i) polls.push_back(std::make_unique<RawConnection>(port));
  const auto start = Clock::now();
  for (int round = 0; round < 5; ++round) {
    for (auto& poll : polls) ASSERT_TRUE(poll->Send(Get("/status")));
    for (auto& poll : polls) ASSERT_EQ(poll->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  }
  EXPECT_LT(SecondsSince(start), 2.0);
  // The uploads then complete.
  for (auto& upload : uploads) {
    ASSERT_TRUE(upload->Send(half));
    const std::string response = upload->ReadResponse();
    EXPECT_EQ(response.rfind("HTTP/1.1 201", 0), 0u) << response;
    EXPECT_NE(response.find("\"bytes\":" + std::to_string(kBodyBytes)), std::string::npos)
        << response;
  }
}

TEST_F(HttpServerTest, ClosesIdleConnectionsAfterTheKeepAliveTimeout) {
  HttpServerOptions options = EventLoopOptions(/*threads=*/2);
  options.keep_alive_timeout_ms = 300;
  options.read_timeout_ms = 300;
  const int port = Start(options);
  // A connection that keeps polling every 100 ms outlives the timeout: it counts idle time.
  RawConnection busy(port);
  const auto busy_start = Clock::now();
  while (SecondsSince(busy_start) < 0.8) {
    ASSERT_TRUE(busy.Send(Get("/status")));
    ASSERT_EQ(busy.ReadResponse().rfind("HTTP/1.1 200", 0), 0u)
        << "after " << SecondsSince(busy_start) << " s";
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  // An idle one is closed after the timeout, not before.
  RawConnection idle(port);
  ASSERT_TRUE(idle.Send(Get("/status")));
  ASSERT_EQ(idle.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  const auto idle_start = Clock::now();
  EXPECT_TRUE(idle.ClosedByServer());
  EXPECT_GE(SecondsSince(idle_start), 0.25);
  EXPECT_LT(SecondsSince(idle_start), 2.0);
  // A request whose headers stall gets 400 after the read timeout (httplib's answer), and a
  // request line that stalls closes the connection.
  RawConnection stalled_headers(port);
  ASSERT_TRUE(stalled_headers.Send("GET /status HTTP/1.1\r\nHo"));
  const auto headers_start = Clock::now();
  EXPECT_EQ(stalled_headers.ReadResponse().rfind("HTTP/1.1 400", 0), 0u);
  EXPECT_GE(SecondsSince(headers_start), 0.25);
  EXPECT_LT(SecondsSince(headers_start), 2.0);
  RawConnection stalled_line(port);
  ASSERT_TRUE(stalled_line.Send("GET /sta"));
  const auto line_start = Clock::now();
  EXPECT_TRUE(stalled_line.ClosedByServer());
  EXPECT_GE(SecondsSince(line_start), 0.25);
  EXPECT_LT(SecondsSince(line_start), 2.0);
}

TEST_F(HttpServerTest, StopReturnsPromptlyWithIdleConnectionsOpen) {
  const int port = Start(EventLoopOptions(/*threads=*/8));
  std::vector<std::unique_ptr<RawConnection>> connections;
  for (int i = 0; i < 50; ++i) {
    connections.push_back(std::make_unique<RawConnection>(port));
    // Half have served a request and wait for the next; half never sent anything.
    if (i % 2 == 0) {
      ASSERT_TRUE(connections.back()->Send(Get("/status")));
      ASSERT_EQ(connections.back()->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
    }
  }
  const auto start = Clock::now();
  server_->Stop();
  EXPECT_LT(SecondsSince(start), 1.0);
  for (auto& connection : connections) EXPECT_TRUE(connection->ClosedByServer());
  // The server starts again on a new port after a stop.
  const int again = server_->Bind("127.0.0.1", 0);
  server_->Start();
  RawConnection connection(again);
  ASSERT_TRUE(connection.Send(Get("/status")));
  EXPECT_EQ(connection.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
}

}  // namespace
}  // namespace omnirig::server
