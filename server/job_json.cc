#include "server/job_json.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <nlohmann/json.hpp>

#include "api/service_json.h"

namespace omnirig::server {
namespace {

void AppendLiteral(const char* text, std::string& out) { out.append(text); }

// Appends `value` as `digits` decimal digits, zero-padded (value >= 0).
void AppendPadded(int64_t value, int digits, std::string& out) {
  char text[20];
  for (int i = digits - 1; i >= 0; --i, value /= 10) text[i] = static_cast<char>('0' + value % 10);
  out.append(text, static_cast<size_t>(digits));
}

// Year, month, day of a day count since 1970-01-01 in the proleptic Gregorian calendar
// (H. Hinnant's civil_from_days): no gmtime_r, whose time-zone lock every poll would take.
void CivilFromDays(int64_t days, int64_t& year, int& month, int& day) {
  days += 719468;
  const int64_t era = (days >= 0 ? days : days - 146096) / 146097;
  const int64_t day_of_era = days - era * 146097;
  const int64_t year_of_era =
      (day_of_era - day_of_era / 1460 + day_of_era / 36524 - day_of_era / 146096) / 365;
  const int64_t day_of_year =
      day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
  const int64_t shifted_month = (5 * day_of_year + 2) / 153;
  day = static_cast<int>(day_of_year - (153 * shifted_month + 2) / 5 + 1);
  month = static_cast<int>(shifted_month < 10 ? shifted_month + 3 : shifted_month - 9);
  year = year_of_era + era * 400 + (month <= 2 ? 1 : 0);
}

// What nlohmann's serializer writes for a control character (ensure_ascii off).
void AppendEscapedControl(unsigned char c, std::string& out) {
  switch (c) {
    case '\b':
      out += "\\b";
      return;
    case '\t':
      out += "\\t";
      return;
    case '\n':
      out += "\\n";
      return;
    case '\f':
      out += "\\f";
      return;
    case '\r':
      out += "\\r";
      return;
    default: {
      static const char kHex[] = "0123456789abcdef";
      const char text[6] = {'\\', 'u', '0', '0', kHex[c >> 4], kHex[c & 15]};
      out.append(text, sizeof(text));
    }
  }
}

}  // namespace

void AppendJsonString(const std::string& value, std::string& out) {
  for (const char c : value) {
    if (static_cast<unsigned char>(c) >= 0x80) {
      // UTF-8: nlohmann checks it (invalid text throws) and copies it; leave that to it.
      out += nlohmann::json(value).dump();
      return;
    }
  }
  out += '"';
  size_t run = 0;  // start of the bytes not yet copied
  for (size_t i = 0; i < value.size(); ++i) {
    const auto c = static_cast<unsigned char>(value[i]);
    if (c >= 0x20 && c != '"' && c != '\\') continue;
    out.append(value, run, i - run);
    run = i + 1;
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else {
      AppendEscapedControl(c, out);
    }
  }
  out.append(value, run, value.size() - run);
  out += '"';
}

void AppendJsonNumber(double value, std::string& out) {
  if (!std::isfinite(value)) {
    out += "null";
    return;
  }
  char text[64];
  const char* end = nlohmann::detail::to_chars(text, text + sizeof(text), value);
  out.append(text, static_cast<size_t>(end - text));
}

void AppendJsonTime(const std::optional<double>& seconds_since_epoch, std::string& out) {
  if (!seconds_since_epoch) {
    out += "null";
    return;
  }
  const double seconds = std::floor(*seconds_since_epoch);
  // Years outside 1000..9999 (and non-finite times) are left to api::TimeJson's strftime.
  constexpr double kYear1000 = -30610224000.0, kYear10000 = 253402300800.0;
  if (!(seconds >= kYear1000 && seconds < kYear10000)) {
    out += api::TimeJson(seconds_since_epoch).dump();
    return;
  }
  const auto whole = static_cast<int64_t>(seconds);
  const int millis = std::min(999, static_cast<int>((*seconds_since_epoch - seconds) * 1000));
  const int64_t days = (whole >= 0 ? whole : whole - 86399) / 86400;
  const int64_t second_of_day = whole - days * 86400;
  int64_t year = 0;
  int month = 0, day = 0;
  CivilFromDays(days, year, month, day);
  out += '"';
  AppendPadded(year, 4, out);
  out += '-';
  AppendPadded(month, 2, out);
  out += '-';
  AppendPadded(day, 2, out);
  out += 'T';
  AppendPadded(second_of_day / 3600, 2, out);
  out += ':';
  AppendPadded(second_of_day / 60 % 60, 2, out);
  out += ':';
  AppendPadded(second_of_day % 60, 2, out);
  out += '.';
  AppendPadded(millis, 3, out);
  out += "Z\"";
}

// Keys in nlohmann's order (sorted), as the tree form (JobJson in job_json_test.cc) dumps them.
void AppendJobJson(const storage::JobRecord& job, std::string& out) {
  AppendLiteral("{\"attempts\":", out);
  out += std::to_string(job.attempts);
  AppendLiteral(job.cancel_requested ? ",\"cancel_requested\":true" : ",\"cancel_requested\":false",
                out);
  AppendLiteral(",\"created_at\":", out);
  AppendJsonTime(job.created_at, out);
  AppendLiteral(",\"dataset\":", out);
  AppendJsonString(job.dataset_id, out);
  AppendLiteral(",\"error\":", out);
  if (job.error) {
    AppendLiteral("{\"code\":", out);
    AppendJsonString(job.error->code, out);
    AppendLiteral(",\"message\":", out);
    AppendJsonString(job.error->message, out);
    out += '}';
  } else {
    AppendLiteral("null", out);
  }
  AppendLiteral(",\"finished_at\":", out);
  AppendJsonTime(job.finished_at, out);
  AppendLiteral(",\"id\":", out);
  AppendJsonString(job.id, out);
  // The stored params are the JSON text CreateJob wrote (a dump(), already in this form):
  // spliced in once checked to be JSON (without building a tree), null otherwise, as before.
  AppendLiteral(",\"params\":", out);
  if (nlohmann::json::accept(job.params)) {
    out += job.params;
  } else {
    AppendLiteral("null", out);
  }
  AppendLiteral(",\"progress\":{\"eta_s\":", out);
  if (job.progress.eta_s) {
    AppendJsonNumber(*job.progress.eta_s, out);
  } else {
    AppendLiteral("null", out);
  }
  AppendLiteral(",\"fraction\":", out);
  AppendJsonNumber(job.progress.fraction, out);
  AppendLiteral(",\"message\":", out);
  AppendJsonString(job.progress.message, out);
  AppendLiteral(",\"stage\":", out);
  AppendJsonString(job.progress.stage, out);
  AppendLiteral("},\"started_at\":", out);
  AppendJsonTime(job.started_at, out);
  AppendLiteral(",\"state\":", out);
  AppendJsonString(storage::JobStateName(job.state), out);
  AppendLiteral(",\"type\":", out);
  AppendJsonString(job.type, out);
  // The worker that ran (or runs) the job's last attempt ("HOST:PID"), null before any claim.
  AppendLiteral(",\"worker\":", out);
  if (job.worker_id.empty()) {
    AppendLiteral("null", out);
  } else {
    AppendJsonString(job.worker_id, out);
  }
  out += '}';
}

std::string JobJsonText(const storage::JobRecord& job) {
  std::string out;
  out.reserve(512 + job.params.size() + job.progress.message.size() +
              (job.error ? job.error->message.size() : 0));
  AppendJobJson(job, out);
  return out;
}

std::string JobListJsonText(const std::vector<storage::JobRecord>& jobs) {
  std::string out = "[";
  out.reserve(jobs.size() * 600 + 2);
  for (size_t i = 0; i < jobs.size(); ++i) {
    if (i > 0) out += ',';
    AppendJobJson(jobs[i], out);
  }
  out += ']';
  return out;
}

}  // namespace omnirig::server
