#include "server/log_line.h"

#include <unistd.h>

#include <cerrno>
#include <cstdio>

#include "api/service_json.h"

namespace omnirig::server {
namespace {

bool NeedsQuotes(std::string_view value) {
  if (value.empty()) return true;
  for (const char c : value) {
    if (c == ' ' || c == '"' || c == '=' || c == '\\' || static_cast<unsigned char>(c) < 32 ||
        c == 127) {
      return true;
    }
  }
  return false;
}

void Append(std::string& line, std::string_view key, std::string_view value) {
  line += ' ';
  line += key;
  line += '=';
  line += LogfmtValue(value);
}

}  // namespace

std::string LogfmtValue(std::string_view value) {
  if (!NeedsQuotes(value)) return std::string(value);
  std::string quoted = "\"";
  for (const char c : value) {
    const auto byte = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      quoted += '\\';
      quoted += c;
    } else if (c == '\n') {
      quoted += "\\n";
    } else if (c == '\t') {
      quoted += "\\t";
    } else if (byte < 32 || byte == 127) {
      char escaped[8];
      std::snprintf(escaped, sizeof(escaped), "\\x%02x", byte);
      quoted += escaped;
    } else {
      quoted += c;
    }
  }
  return quoted + "\"";
}

std::string LogfmtLine(std::string_view event, const LogFields& fields) {
  std::string line = "omnirig:";
  Append(line, "ts", api::TimeJson(storage::NowSeconds()).get<std::string>());
  Append(line, "event", event);
  for (const auto& [key, value] : fields) Append(line, key, value);
  return line + "\n";
}

void LogEvent(std::string_view event, const LogFields& fields) {
  try {
    const std::string line = LogfmtLine(event, fields);
    size_t written = 0;
    while (written < line.size()) {
      const ssize_t n = ::write(STDERR_FILENO, line.data() + written, line.size() - written);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return;  // stderr closed or full: the line is lost, the request is not
      written += static_cast<size_t>(n);
    }
  } catch (...) {
  }
}

void LogJobState(const std::string& job_id, const std::string& type, std::string_view state,
                 int attempt, const LogFields& detail) {
  try {
    LogFields fields = {{"job", job_id},
                        {"type", type},
                        {"state", std::string(state)},
                        {"attempt", std::to_string(attempt)}};
    fields.insert(fields.end(), detail.begin(), detail.end());
    LogEvent("job", fields);
  } catch (...) {
  }
}

void LogJobState(const storage::JobRecord& job, const LogFields& detail) {
  LogJobState(job.id, job.type, storage::JobStateName(job.state), job.attempts, detail);
}

void LogRecovery(storage::JobStore& store, const storage::RecoveryReport& report,
                 std::string_view reason) {
  for (const auto* ids : {&report.requeued, &report.failed, &report.canceled}) {
    for (const std::string& id : *ids) {
      try {
        if (const auto job = store.GetJob(id)) LogJobState(*job, {{"reason", std::string(reason)}});
      } catch (const std::exception&) {
        // The store is unreachable: the recovery itself is recorded, only its line is lost.
      }
    }
  }
}

}  // namespace omnirig::server
