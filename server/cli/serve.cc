// `omnirig serve`: the HTTP service.

#include <httplib.h>

#include <iostream>

#include "server/cli/args.h"
#include "server/cli/commands.h"

namespace omnirig::cli {

int RunServe(const Args& args) {
  ArgParser parser("serve", "Runs the omnirig HTTP service: REST API under /api/v1 and the web page.");
  parser.AddOption("host", "127.0.0.1", "address to bind");
  parser.AddOption("port", "8080", "TCP port (0 picks a free one)");
  parser.AddOption("data", "./data", "folder holding the SQLite database and all files");
  parser.AddOption("web", OMNIRIG_WEB_DIR, "folder of the web page's static files");
  if (!parser.Parse(args)) return parser.exit_code();
  httplib::Server server;
  server.Get("/api/v1/health", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(R"({"status":"ok"})", "application/json");
  });
  server.set_mount_point("/", parser.Get("web"));
  const std::string host = parser.Get("host");
  const int port = parser.GetInt("port");
  std::cout << "omnirig serving on http://" << host << ":" << port << std::endl;
  return server.listen(host, port) ? 0 : 1;
}

}  // namespace omnirig::cli
