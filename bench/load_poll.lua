-- wrk script for bench/load_bench.sh: every connection polls one job's status, pausing
-- DELAY_MS between requests, so C connections offer about C * 1000 / DELAY_MS requests/s
-- (wrk 4 has no fixed-rate mode; this spacing makes it an open-ish load at the target rate).
local delay_ms = tonumber(os.getenv("DELAY_MS") or "100")
local token = os.getenv("OMNIRIG_TOKEN")

function init(args)
  if token and token ~= "" then
    wrk.headers["Authorization"] = "Bearer " .. token
  end
end

function delay()
  return delay_ms
end

function done(summary, latency, requests)
  io.write(string.format("poll_requests %d\npoll_duration_s %.2f\npoll_rate_per_s %.0f\n",
    summary.requests, summary.duration / 1e6, summary.requests / (summary.duration / 1e6)))
  io.write(string.format("poll_p50_ms %.3f\npoll_p99_ms %.3f\npoll_max_ms %.3f\n",
    latency:percentile(50) / 1000, latency:percentile(99) / 1000, latency.max / 1000))
  io.write(string.format("poll_errors %d\n", summary.errors.status + summary.errors.connect +
    summary.errors.read + summary.errors.write + summary.errors.timeout))
end
