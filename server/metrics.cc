#include "server/metrics.h"

#include <algorithm>
#include <sstream>

#include "server/http.h"

namespace omnirig::server {
namespace {

std::string Escape(const std::string& value) {
  std::string escaped;
  for (char c : value) {
    if (c == '"' || c == '\\') escaped += '\\';
    if (c == '\n') {
      escaped += "\\n";
      continue;
    }
    escaped += c;
  }
  return escaped;
}

void RenderHistogram(std::ostringstream& out, const std::string& name, const std::string& labels,
                     const std::vector<double>& bounds, const std::vector<int64_t>& buckets,
                     double sum, int64_t count) {
  int64_t cumulative = 0;
  for (size_t i = 0; i <= bounds.size(); ++i) {
    cumulative += i < buckets.size() ? buckets[i] : 0;
    out << name << "_bucket{" << labels << ",le=\""
        << (i < bounds.size() ? std::to_string(bounds[i]) : std::string("+Inf")) << "\"} "
        << cumulative << "\n";
  }
  out << name << "_sum{" << labels << "} " << sum << "\n";
  out << name << "_count{" << labels << "} " << count << "\n";
}

}  // namespace

Metrics::Metrics()
    : request_bounds_s_{0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.5, 1, 5},
      job_bounds_s_{0.1, 0.5, 1, 5, 10, 30, 60, 300, 1800, 7200} {}

void Metrics::Histogram::Add(const std::vector<double>& bounds, double value) {
  bucket_counts.resize(bounds.size() + 1, 0);
  ++bucket_counts[static_cast<size_t>(std::lower_bound(bounds.begin(), bounds.end(), value) -
                                      bounds.begin())];
  sum += value;
  ++count;
}

void Metrics::CountRequest(const std::string& route, int status, double seconds) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++requests_[{route, status}];
  request_durations_[route].Add(request_bounds_s_, seconds);
}

void Metrics::ObserveJobDuration(const std::string& type, const std::string& state,
                                 double seconds) {
  std::lock_guard<std::mutex> lock(mutex_);
  job_durations_[{type, state}].Add(job_bounds_s_, seconds);
}

void Metrics::SetOpenConnectionsGauge(std::function<int64_t()> open_connections) {
  open_connections_ = std::move(open_connections);
}

std::string Metrics::Render(storage::JobStore& store, int busy_workers, int num_workers) const {
  std::ostringstream out;
  const auto counts = store.CountJobsByState();
  out << "# HELP omnirig_jobs Jobs by state.\n# TYPE omnirig_jobs gauge\n";
  for (const auto& [state, count] : counts) {
    out << "omnirig_jobs{state=\"" << storage::JobStateName(state) << "\"} " << count << "\n";
  }
  out << "# HELP omnirig_queue_depth Jobs waiting for a worker.\n"
      << "# TYPE omnirig_queue_depth gauge\nomnirig_queue_depth "
      << counts.at(storage::JobState::kQueued) << "\n";
  out << "# HELP omnirig_workers_busy Workers running a job in this process.\n"
      << "# TYPE omnirig_workers_busy gauge\nomnirig_workers_busy " << busy_workers << "\n"
      << "# TYPE omnirig_workers gauge\nomnirig_workers " << num_workers << "\n";
  // Every worker process sharing the store (this one's included), by heartbeat.
  const auto alive = store.ListWorkers(worker_alive_window_s_);
  out << "# HELP omnirig_workers_alive Worker processes whose heartbeat was seen within the "
      << "lease.\n# TYPE omnirig_workers_alive gauge\nomnirig_workers_alive " << alive.size()
      << "\n# HELP omnirig_worker_running_jobs Jobs each live worker process was running at its "
      << "last heartbeat.\n# TYPE omnirig_worker_running_jobs gauge\n";
  for (const storage::WorkerRecord& worker : alive) {
    out << "omnirig_worker_running_jobs{worker=\"" << Escape(worker.id) << "\"} "
        << worker.running_jobs.size() << "\n";
  }
  out << "# HELP omnirig_http_open_connections Open HTTP connections, idle keep-alive ones "
      << "included.\n# TYPE omnirig_http_open_connections gauge\nomnirig_http_open_connections "
      << (open_connections_ ? open_connections_() : 0) << "\n";
  std::lock_guard<std::mutex> lock(mutex_);
  out << "# HELP omnirig_http_requests_total HTTP requests by route and status.\n"
      << "# TYPE omnirig_http_requests_total counter\n";
  for (const auto& [key, count] : requests_) {
    out << "omnirig_http_requests_total{route=\"" << Escape(key.first) << "\",status=\""
        << key.second << "\"} " << count << "\n";
  }
  const auto refused = requests_.find({kRefusedRoute, 503});
  out << "# HELP omnirig_http_connections_refused_total Connections refused with 503 beyond "
      << "--max-connections.\n# TYPE omnirig_http_connections_refused_total counter\n"
      << "omnirig_http_connections_refused_total "
      << (refused == requests_.end() ? 0 : refused->second) << "\n";
  out << "# HELP omnirig_http_request_duration_seconds Time to handle a request.\n"
      << "# TYPE omnirig_http_request_duration_seconds histogram\n";
  for (const auto& [route, h] : request_durations_) {
    RenderHistogram(out, "omnirig_http_request_duration_seconds", "route=\"" + Escape(route) + "\"",
                    request_bounds_s_, h.bucket_counts, h.sum, h.count);
  }
  out << "# HELP omnirig_job_duration_seconds Run time of finished job attempts.\n"
      << "# TYPE omnirig_job_duration_seconds histogram\n";
  for (const auto& [key, h] : job_durations_) {
    RenderHistogram(out, "omnirig_job_duration_seconds",
                    "type=\"" + Escape(key.first) + "\",state=\"" + key.second + "\"",
                    job_bounds_s_, h.bucket_counts, h.sum, h.count);
  }
  return out.str();
}

}  // namespace omnirig::server
