#pragma once
// One line per event on stderr, as logfmt `key=value` pairs that journald stores as they are
// and `grep`/`awk` read without a parser:
//
//   omnirig: ts=2026-11-27T13:20:01.123Z event=request method=GET path=/api/v1/jobs status=200
//            duration_ms=0.41 route="GET /api/v1/jobs" remote=127.0.0.1        (one line)
//   omnirig: ts=... event=job job=f4ba8870de2b7a2e type=calibration state=running attempt=1
//
// A value is written bare unless it is empty or holds a space, '"', '=' or a control character:
// then it is quoted, with '"' and '\' escaped and control characters as \n, \t or \xHH. Each
// line goes out in one write(2), so lines of concurrent threads never interleave.

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "storage/job_store.h"
#include "storage/records.h"

namespace omnirig::server {

// Keys are literals; values any text.
using LogFields = std::vector<std::pair<std::string_view, std::string>>;

// A value as logfmt writes it (quoted and escaped when needed).
std::string LogfmtValue(std::string_view value);

// "omnirig: ts=NOW event=EVENT k1=v1 k2=v2 ...\n", the values through LogfmtValue.
std::string LogfmtLine(std::string_view event,
                       const LogFields& fields);

// Writes LogfmtLine(...) to stderr in one write; never throws.
void LogEvent(std::string_view event,
              const LogFields& fields);

// A job's state as it now is (or "deleted"), with its type and attempt; `detail` adds e.g. why
// ("reason") or how it ended ("error_code", "duration_s").
void LogJobState(const std::string& job_id, const std::string& type, std::string_view state,
                 int attempt,
                 const LogFields& detail = {});
void LogJobState(const storage::JobRecord& job,
                 const LogFields& detail = {});

// One line per job that recovery moved (`reason`: "interrupted" at start-up, "lease_expired"),
// each as the store now holds it.
void LogRecovery(storage::JobStore& store, const storage::RecoveryReport& report,
                 std::string_view reason);

}  // namespace omnirig::server
