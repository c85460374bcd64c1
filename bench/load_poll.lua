-- wrk script for bench/load_bench.sh: every connection is one client polling one job's status,
-- pausing between requests so that C connections offer about C * 1000 / DELAY_MS requests/s
-- (wrk 4 has no fixed-rate mode).
-- ARRIVALS picks how the clients' polls line up in time:
--   "independent" (default): each client's pause is drawn from an exponential distribution of
--     mean DELAY_MS, seeded per connection, so the clients poll independently of each other and
--     the server sees Poisson arrivals at the offered rate (the usual open-load model);
--   "lockstep": every client pauses exactly DELAY_MS. wrk opens all connections at once, so the
--     clients stay in phase: every DELAY_MS all of them send within a fraction of a millisecond
--     (200 requests in a burst, then silence), the worst case for the same average rate.
local delay_ms = tonumber(os.getenv("DELAY_MS") or "100")
local arrivals = os.getenv("ARRIVALS") or "independent"
local token = os.getenv("OMNIRIG_TOKEN")
local threads = 0

function setup(thread)
  threads = threads + 1
  thread:set("thread_index", threads)
end

function init(args)
  if token and token ~= "" then
    wrk.headers["Authorization"] = "Bearer " .. token
  end
  -- Each wrk thread runs its own Lua state; a fixed seed per thread keeps runs repeatable.
  math.randomseed(7919 * (thread_index or 1) + 17)
end

function delay()
  if arrivals == "lockstep" then
    return delay_ms
  end
  -- Inverse-CDF sample of an exponential pause; 1 - random() lies in (0, 1].
  return math.floor(-math.log(1 - math.random()) * delay_ms + 0.5)
end

function done(summary, latency, requests)
  io.write(string.format("poll_requests %d\npoll_duration_s %.2f\npoll_rate_per_s %.0f\n",
    summary.requests, summary.duration / 1e6, summary.requests / (summary.duration / 1e6)))
  io.write(string.format("poll_p50_ms %.3f\npoll_p99_ms %.3f\npoll_max_ms %.3f\n",
    latency:percentile(50) / 1000, latency:percentile(99) / 1000, latency.max / 1000))
  io.write(string.format("poll_errors %d\n", summary.errors.status + summary.errors.connect +
    summary.errors.read + summary.errors.write + summary.errors.timeout))
end
