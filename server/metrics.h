#pragma once
// Counters for GET /metrics in the Prometheus text format: HTTP requests by route and status,
// job run durations by type and final state; job counts by state and the queue depth come from
// the store when the page is rendered.

#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <tuple>
#include <vector>

#include "storage/job_store.h"

namespace omnirig::server {

class Metrics {
 public:
  Metrics();
  // `route` is "METHOD /pattern" (or "static", "unmatched", "auth", or kRefusedRoute for a
  // connection refused beyond --max-connections, also rendered as its own counter).
  void CountRequest(const std::string& route, int status, double seconds);
  void ObserveJobDuration(const std::string& type, const std::string& state, double seconds);
  // Where the omnirig_http_open_connections gauge reads its value when the page is rendered
  // (HttpServer::OpenConnections); 0 until set. Set before serving starts.
  void SetOpenConnectionsGauge(std::function<int64_t()> open_connections);
  // A worker counts as alive while its last heartbeat is at most this old (the lease: workers
  // heartbeat three times per lease).
  void SetWorkerAliveWindow(double seconds) { worker_alive_window_s_ = seconds; }
  // The whole exposition text; `busy_workers` is the number of jobs running in this process.
  std::string Render(storage::JobStore& store, int busy_workers, int num_workers) const;

 private:
  struct Histogram {
    std::vector<int64_t> bucket_counts;  // cumulative counts are computed when rendering
    double sum = 0;
    int64_t count = 0;
    void Add(const std::vector<double>& bounds, double value);
  };
  std::function<int64_t()> open_connections_;
  double worker_alive_window_s_ = 30;
  mutable std::mutex mutex_;
  std::vector<double> request_bounds_s_, job_bounds_s_;
  std::map<std::pair<std::string, int>, int64_t> requests_;
  std::map<std::string, Histogram> request_durations_;
  std::map<std::pair<std::string, std::string>, Histogram> job_durations_;
};

}  // namespace omnirig::server
