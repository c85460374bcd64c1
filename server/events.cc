#include "server/events.h"

#include <algorithm>
#include <iostream>

#include "server/json_views.h"

namespace omnirig::server {

void JobEvents::Changed(const std::string& id) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (streams_ == 0 || closed_) return;
  }
  std::lock_guard<std::mutex> publish(publish_mutex_);
  std::string type = "job";
  std::string data;
  try {
    const auto job = store_.GetJob(id);
    if (job) {
      data = JobJson(*job).dump();
    } else {
      type = "job_deleted";
      data = nlohmann::json{{"id", id}}.dump();
    }
  } catch (const std::exception& e) {
    std::cerr << "omnirig: no event for job " << id << ": " << e.what() << std::endl;
    return;
  }
  Queue(id, type, data);
}

void JobEvents::Publish(const std::string& id, const std::string& type,
                        const nlohmann::json& data) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (streams_ == 0 || closed_) return;
  }
  std::lock_guard<std::mutex> publish(publish_mutex_);
  Queue(id, type, data.dump());
}

void JobEvents::Queue(const std::string& id, const std::string& type, const std::string& data) {
  std::lock_guard<std::mutex> lock(mutex_);
  const uint64_t event_id = next_id_++;
  events_.push_back(
      {event_id, id,
       "id: " + std::to_string(event_id) + "\nevent: " + type + "\ndata: " + data + "\n\n"});
  while (events_.size() > kBacklog) events_.pop_front();
  wake_.notify_all();
}

void JobEvents::Close() {
  std::lock_guard<std::mutex> lock(mutex_);
  closed_ = true;
  wake_.notify_all();
}

JobEvents::Stream::Stream(JobEvents& events, std::optional<std::string> only_job)
    : events_(events), only_job_(std::move(only_job)) {
  std::lock_guard<std::mutex> lock(events_.mutex_);
  ++events_.streams_;
  next_id_ = events_.next_id_;
}

JobEvents::Stream::~Stream() {
  std::lock_guard<std::mutex> lock(events_.mutex_);
  --events_.streams_;
}

bool JobEvents::Stream::Next(std::string& text, int timeout_ms) {
  std::unique_lock<std::mutex> lock(events_.mutex_);
  events_.wake_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [this] {
    return events_.closed_ || (!events_.events_.empty() && events_.events_.back().id >= next_id_);
  });
  if (events_.closed_) return false;
  const auto first =
      std::lower_bound(events_.events_.begin(), events_.events_.end(), next_id_,
                       [](const Event& event, uint64_t id) { return event.id < id; });
  for (auto it = first; it != events_.events_.end(); ++it) {
    if (!only_job_ || it->job_id == *only_job_) text += it->text;
  }
  if (!events_.events_.empty()) next_id_ = std::max(next_id_, events_.events_.back().id + 1);
  return true;
}

}  // namespace omnirig::server
