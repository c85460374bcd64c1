// The HTTP layer on real loopback sockets: one router (segments), keep-alive connections served
// by a thread each, slow uploads beside status polls, the keep-alive and read timeouts, Stop()
// with idle connections open, the cap on open connections, a body left unread, a Range header
// on a JSON answer, and streamed (event) responses. No timing is asserted: tests wait for what
// they expect (a response, a close, a count), with the sockets' receive timeout as the bound.

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

// Waits until `condition` holds (the ctest timeout bounds a hang).
template <typename Condition>
void WaitUntil(Condition condition) {
  while (!condition()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
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
  // The server first: its threads count requests into counts_ until it has stopped.
  ~HttpServerTest() override { server_.reset(); }

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
    // Each answers with its name, path parameters, query and body.
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
    // A stream of three chunks, as GET /api/v1/events sends its events.
    server_->Route("GET", "/stream", [](const HttpRequest&, HttpResponse& response) {
      response.content_type = "text/event-stream";
      auto sent = std::make_shared<int>(0);
      response.stream = [sent](std::string& chunk) {
        if (*sent == 3) return false;
        chunk = "data: " + std::to_string((*sent)++) + "\n\n";
        return true;
      };
    });
    const int port = server_->Bind("127.0.0.1", 0);
    server_->Start();
    return port;
  }
  int Count(const std::string& key) {
    std::lock_guard<std::mutex> lock(mutex_);
    return counts_[key];
  }

  static HttpServerOptions Options(int threads) {
    HttpServerOptions options;
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
      ASSERT_TRUE(extra.Send(Get("/status")));
      const std::string response = extra.ReadResponse();
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
    // Once the server has seen the two closes, a new connection is served.
    WaitUntil([&] { return server_->OpenConnections() == cap - 2; });
    RawConnection fresh(port);
    ASSERT_TRUE(fresh.Send(Get("/status")));
    EXPECT_EQ(fresh.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
    for (auto& connection : open) {
      ASSERT_TRUE(connection->Send(Get("/status")));
      EXPECT_EQ(connection->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
    }
    // The counter is called just after the 503 is written.
    WaitUntil([&] { return Count(std::string(kRefusedRoute) + " 503") >= refused; });
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

TEST_F(HttpServerTest, RefusesConnectionsBeyondTheCap) {
  HttpServerOptions options = Options(/*threads=*/8);  // more than the cap: each has its thread
  options.max_connections = 4;
  ExpectConnectionCap(Start(options), options.max_connections);
}

TEST_F(HttpServerTest, ServesEachKeepAliveConnectionOnItsThread) {
  constexpr int kConnections = 64;
  const int port = Start(Options(/*threads=*/kConnections));
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
  ASSERT_TRUE(connections[0]->Send(Get("/nothing")));
  EXPECT_EQ(connections[0]->ReadResponse().rfind("HTTP/1.1 404", 0), 0u);
  // The request counter sees each request's route (set and read on the serving thread). The
  // logger runs after the response is written, so the last count may lag.
  WaitUntil([&] { return Count("GET /status 200") >= 3 * kConnections; });
  EXPECT_EQ(Count("GET /status 200"), 3 * kConnections);
  WaitUntil([&] { return Count("unmatched 404") >= 1; });
  EXPECT_EQ(Count("unmatched 404"), 1);
}

TEST_F(HttpServerTest, DiscardsABodyTheHandlerDidNotRead) {
  const int port = Start(Options(/*threads=*/4));
  // The unread body is read and dropped before the answer: its bytes are not parsed as requests
  // (a 400 each), and the connection serves the next request.
  RawConnection connection(port);
  const std::string body(100000, 'x');
  ASSERT_TRUE(connection.Send("PUT /refuse HTTP/1.1\r\nHost: test\r\nContent-Length: " +
                              std::to_string(body.size()) + "\r\n\r\n" + body));
  const std::string response = connection.ReadResponse();
  EXPECT_EQ(response.rfind("HTTP/1.1 404", 0), 0u) << response;
  EXPECT_EQ(response.find("Connection: close"), std::string::npos) << response;
  ASSERT_TRUE(connection.Send(Get("/status")));
  EXPECT_EQ(connection.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  EXPECT_EQ(Count("unmatched 400"), 0);
  // A body the handler read to the end keeps the connection.
  ASSERT_TRUE(
      connection.Send("PUT /upload HTTP/1.1\r\nHost: test\r\nContent-Length: 3\r\n\r\nabc"));
  EXPECT_EQ(connection.ReadResponse().rfind("HTTP/1.1 201", 0), 0u);
  ASSERT_TRUE(connection.Send(Get("/status")));
  EXPECT_EQ(connection.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
}

TEST_F(HttpServerTest, ClosesTheConnectionAfterAnUnreadBodyThatStalls) {
  HttpServerOptions options = Options(/*threads=*/4);
  options.read_timeout_ms = 300;  // a body that stalls is given up after the read timeout
  const int port = Start(options);
  // Half the body, then nothing: the answer says "Connection: close" and the connection ends,
  // so the rest, should it come, is never parsed as requests.
  RawConnection connection(port);
  ASSERT_TRUE(
      connection.Send("PUT /refuse HTTP/1.1\r\nHost: test\r\nContent-Length: 100000\r\n\r\n" +
                      std::string(50000, 'x')));
  const std::string response = connection.ReadResponse();
  EXPECT_EQ(response.rfind("HTTP/1.1 404", 0), 0u) << response;
  EXPECT_NE(response.find("Connection: close\r\n"), std::string::npos) << response;
  EXPECT_NE(response.find("\"code\":\"not_found\""), std::string::npos) << response;
  EXPECT_TRUE(connection.ClosedByServer());
}

// The route, parameters, query and body a request reached, or the status line when not 200.
nlohmann::json Reached(RawConnection& connection, const std::string& request) {
  if (!connection.Send(request)) return "send failed";
  const std::string response = connection.ReadResponse();
  if (response.rfind("HTTP/1.1 200", 0) != 0) return response.substr(0, response.find('\r'));
  return nlohmann::json::parse(response.substr(response.find("\r\n\r\n") + 4));
}

TEST_F(HttpServerTest, MatchesRoutesAsTheirPatternsSay) {
  const int port = Start(Options(/*threads=*/2));
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
  // No route: a JSON 404, counted as unmatched, on the same connection.
  for (const std::string path :
       {"/api/v1/items/", "/api/v1/items//files/a", "/api/v1/items/x/files/", "/api/v1/items/x/y",
        "/api/v1/itemsx", "/api/v2/items"}) {
    EXPECT_EQ(reached(Get(path)), "HTTP/1.1 404 Not Found") << path;
  }
  EXPECT_EQ(reached("DELETE /api/v1/items HTTP/1.1\r\nHost: test\r\n\r\n"),
            "HTTP/1.1 404 Not Found");
  // A DELETE with a body: the body is read for the route.
  const nlohmann::json with_body =
      reached("DELETE /api/v1/items/b HTTP/1.1\r\nHost: test\r\nContent-Length: 3\r\n\r\nxyz");
  EXPECT_EQ(with_body["params"], nlohmann::json({{"id", "b"}}));
  EXPECT_EQ(with_body["body"], "xyz");
  EXPECT_EQ(reached(Get("/api/v1/items/c"))["params"], nlohmann::json({{"id", "c"}}));
  // The request counter sees the route patterns.
  WaitUntil([&] { return Count("GET /api/v1/items/{id} 200") >= 4; });
  EXPECT_EQ(Count("GET /api/v1/items/{id} 200"), 4);
  EXPECT_EQ(Count("DELETE /api/v1/items/{id} 200"), 2);
  WaitUntil([&] { return Count("unmatched 404") >= 7; });
  EXPECT_EQ(Count("unmatched 404"), 7);
  // A pattern whose parameter is not a whole segment is refused at registration.
  EXPECT_THROW(server_->Route("GET", "/api/v1/odd/{id}.json", [](auto&, auto&) {}),
               std::logic_error);
}

TEST_F(HttpServerTest, ARangeHeaderDoesNotSliceAJsonAnswer) {
  const int port = Start(Options(/*threads=*/2));
  RawConnection connection(port);
  ASSERT_TRUE(connection.Send("GET /status HTTP/1.1\r\nHost: test\r\nRange: bytes=0-3\r\n\r\n"));
  // Chunked (httplib applies ranges to bodies with a length): read to the last chunk.
  std::string response;
  while (response.find("0\r\n\r\n") == std::string::npos) {
    const std::string part = connection.ReadResponse();
    ASSERT_FALSE(part.empty()) << response;
    response += part;
  }
  EXPECT_EQ(response.rfind("HTTP/1.1 200", 0), 0u) << response;
  EXPECT_NE(response.find("{\"state\":\"running\"}"), std::string::npos) << response;
}

TEST_F(HttpServerTest, StreamsAResponseChunkByChunk) {
  const int port = Start(Options(/*threads=*/2));
  RawConnection connection(port);
  ASSERT_TRUE(connection.Send(Get("/stream")));
  std::string response;
  while (response.find("0\r\n\r\n") == std::string::npos) {
    const std::string part = connection.ReadResponse();
    ASSERT_FALSE(part.empty()) << response;
    response += part;
  }
  EXPECT_NE(response.find("Content-Type: text/event-stream"), std::string::npos) << response;
  EXPECT_NE(response.find("Transfer-Encoding: chunked"), std::string::npos) << response;
  for (int i = 0; i < 3; ++i) {
    EXPECT_NE(response.find("data: " + std::to_string(i) + "\n\n"), std::string::npos) << response;
  }
  // The connection serves the next request.
  ASSERT_TRUE(connection.Send(Get("/status")));
  EXPECT_EQ(connection.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
}

TEST_F(HttpServerTest, CountsOpenConnections) {
  const int port = Start(Options(/*threads=*/4));
  EXPECT_EQ(server_->OpenConnections(), 0);
  std::vector<std::unique_ptr<RawConnection>> connections;
  for (int i = 0; i < 3; ++i) {
    connections.push_back(std::make_unique<RawConnection>(port));
    ASSERT_TRUE(connections.back()->Send(Get("/status")));
    ASSERT_EQ(connections.back()->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  }
  EXPECT_EQ(server_->OpenConnections(), 3);
  connections.resize(1);
  // The server sees the closes when it next looks at the sockets.
  WaitUntil([&] { return server_->OpenConnections() == 1; });
  server_->Stop();
  EXPECT_EQ(server_->OpenConnections(), 0);
}

TEST_F(HttpServerTest, PostWithoutContentLengthHasAnEmptyBody) {
  const int port = Start(Options(/*threads=*/2));
  // What `curl -X POST URL` sends: no Content-Length, no body. Answered without waiting for a
  // body (the read timeout is 5 s, the connection's receive timeout 3 s), and the connection
  // stays usable.
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
  const int port = Start(Options(/*threads=*/32));
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
  // Polls on 20 other connections are all answered meanwhile.
  std::vector<std::unique_ptr<RawConnection>> polls;
  for (int i = 0; i < 20; ++i) polls.push_back(std::make_unique<RawConnection>(port));
  for (int round = 0; round < 5; ++round) {
    for (auto& poll : polls) ASSERT_TRUE(poll->Send(Get("/status")));
    for (auto& poll : polls) ASSERT_EQ(poll->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  }
  // The uploads then complete.
  for (auto& upload : uploads) {
    ASSERT_TRUE(upload->Send(half));
    const std::string response = upload->ReadResponse();
    EXPECT_EQ(response.rfind("HTTP/1.1 201", 0), 0u) << response;
    EXPECT_NE(response.find("\"bytes\":" + std::to_string(kBodyBytes)), std::string::npos)
        << response;
  }
}

TEST_F(HttpServerTest, ClosesIdleAndStalledConnections) {
  HttpServerOptions options = Options(/*threads=*/4);
  options.keep_alive_timeout_ms = 1000;
  options.read_timeout_ms = 300;
  const int port = Start(options);
  // An idle keep-alive connection is closed by the server (within the client's 3 s).
  RawConnection idle(port);
  ASSERT_TRUE(idle.Send(Get("/status")));
  ASSERT_EQ(idle.ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
  EXPECT_TRUE(idle.ClosedByServer());
  // A request whose headers stall gets 400 after the read timeout (httplib's answer, as JSON),
  // and a request line that stalls closes the connection.
  RawConnection stalled_headers(port);
  ASSERT_TRUE(stalled_headers.Send("GET /status HTTP/1.1\r\nHo"));
  const std::string response = stalled_headers.ReadResponse();
  EXPECT_EQ(response.rfind("HTTP/1.1 400", 0), 0u) << response;
  EXPECT_NE(response.find("\"code\":\"bad_request\""), std::string::npos) << response;
  RawConnection stalled_line(port);
  ASSERT_TRUE(stalled_line.Send("GET /sta"));
  EXPECT_TRUE(stalled_line.ClosedByServer());
}

TEST_F(HttpServerTest, StopClosesIdleConnectionsAndStartsAgain) {
  const int port = Start(Options(/*threads=*/64));
  std::vector<std::unique_ptr<RawConnection>> connections;
  for (int i = 0; i < 50; ++i) {
    connections.push_back(std::make_unique<RawConnection>(port));
    // Half have served a request and wait for the next; half never sent anything.
    if (i % 2 == 0) {
      ASSERT_TRUE(connections.back()->Send(Get("/status")));
      ASSERT_EQ(connections.back()->ReadResponse().rfind("HTTP/1.1 200", 0), 0u);
    }
  }
  server_->Stop();
  EXPECT_EQ(server_->OpenConnections(), 0);
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
