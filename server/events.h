#pragma once
// Job changes pushed to GET /api/v1/events (Server-Sent Events). Whatever changes a job in this
// process (a route, a worker claiming or finishing it, a progress write) calls Changed(id); the
// job is then read from the store once and queued, as an event, to every open stream. The
// text of one event (the job's JSON as GET /api/v1/jobs/{id} returns it, on one line):
//
//   id: 17
//   event: job
//   data: {"id": "...", "state": "running", "progress": {"fraction": 0.4, ...}, ...}
//
// and for a deleted job `event: job_deleted` with `data: {"id": "..."}`. A stream that falls
// more than kBacklog events behind skips the oldest (the next poll or event brings it up to
// date). Changes made by another process sharing the store are not seen here.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "storage/job_store.h"

namespace omnirig::server {

class JobEvents {
 public:
  static constexpr size_t kBacklog = 4096;

  explicit JobEvents(storage::JobStore& store) : store_(store) {}

  // Job `id` changed (or was deleted): queues its event when a stream is open. Never throws.
  void Changed(const std::string& id);

  // An event of job `id` other than its record's change (e.g. a live job's tracked frame:
  // `event: frame`), with `data` as its data line. Never throws.
  void Publish(const std::string& id, const std::string& type, const nlohmann::json& data);

  // One open stream. Next() waits up to `timeout_ms` for events after the ones it returned
  // before and appends them, SSE-encoded, to `text` (those of job `only_job` alone when set);
  // false once the hub is closed.
  class Stream {
   public:
    Stream(JobEvents& events, std::optional<std::string> only_job);
    ~Stream();
    Stream(const Stream&) = delete;
    Stream& operator=(const Stream&) = delete;
    bool Next(std::string& text, int timeout_ms);

   private:
    JobEvents& events_;
    std::optional<std::string> only_job_;
    uint64_t next_id_;
  };

  // Ends every stream (their Next() returns false) and refuses new events.
  void Close();

 private:
  struct Event {
    uint64_t id;
    std::string job_id;
    std::string text;  // SSE-encoded, ending in the blank line
  };

  // Under publish_mutex_: appends the event and wakes the streams.
  void Queue(const std::string& id, const std::string& type, const std::string& data);

  storage::JobStore& store_;
  // Held while a change is read and queued, so that two changes of one job queue in order.
  std::mutex publish_mutex_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Event> events_;
  uint64_t next_id_ = 1;  // of the next event
  int streams_ = 0;
  bool closed_ = false;
};

}  // namespace omnirig::server
