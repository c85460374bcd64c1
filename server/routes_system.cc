// Health, metrics and the web page's static files.

#include "api/job_types.h"
#include "server/service.h"
#include "storage/sqlite_job_store.h"

namespace omnirig::server {

void AddSystemRoutes(HttpServer& http, ServiceState& state) {
  http.Route("GET", "/api/v1/health", [&state](const HttpRequest&, HttpResponse& response) {
    const auto counts = state.store->CountJobsByState();
    response.Json(200, {{"status", "ok"},
                        {"version", "0.1.0"},
                        {"schema_version", storage::SqliteJobStore::SchemaVersion()},
                        {"uptime_s", storage::NowSeconds() - state.started_at},
                        {"workers", state.workers->size()},
                        {"busy_workers", state.workers->busy()},
                        {"threads_per_job", state.options.workers.threads_per_job},
                        {"queue_depth", counts.at(storage::JobState::kQueued)},
                        {"job_types", state.job_types.Names()},
                        {"auth_required", !state.options.token.empty()},
                        {"integrity", state.consistency.integrity}});
  });
  http.Route("GET", "/metrics", [&state](const HttpRequest&, HttpResponse& response) {
    response.content_type = "text/plain; version=0.0.4; charset=utf-8";
    response.body =
        state.metrics.Render(*state.store, state.workers->busy(), state.workers->size());
  });
  const auto& web = state.options.web_dir;
  if (!web.empty()) {
    http.MountStatic("/", web);
    // The 3D viewer's three.js, installed by npm into web/node_modules.
    http.MountStatic("/vendor/three/", web / "node_modules" / "three" / "build");
  }
}

}  // namespace omnirig::server
