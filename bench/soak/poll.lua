-- wrk script for bench/soak/soak.sh: every connection is one client following jobs. Each request
-- polls GET /api/v1/jobs/{id} of one of the jobs the churn client (churn.py) lists as live in
-- IDS_FILE (re-read every 500 requests of a thread, so the clients follow new jobs as they are
-- created), pausing between polls for an exponential time of mean DELAY_MS (independent
-- clients: Poisson arrivals at about connections * 1000 / DELAY_MS requests/s).
local delay_ms = tonumber(os.getenv("DELAY_MS") or "199")
local ids_file = os.getenv("IDS_FILE")
local threads = {}
local ids = {}
local requests = 0
server_errors = 0  -- globals: done() reads them from each thread
not_found = 0

function setup(thread)
  table.insert(threads, thread)
  thread:set("thread_index", #threads)
end

local function read_ids()
  local file = ids_file and io.open(ids_file, "r")
  if not file then return end
  local fresh = {}
  for line in file:lines() do
    if #line > 0 then table.insert(fresh, line) end
  end
  file:close()
  if #fresh > 0 then ids = fresh end
end

function init(args)
  math.randomseed(7919 * (thread_index or 1) + 17)
  read_ids()
end

function request()
  if requests % 500 == 0 then read_ids() end
  requests = requests + 1
  local id = #ids > 0 and ids[math.random(#ids)] or "none"
  return wrk.format("GET", "/api/v1/jobs/" .. id)
end

function response(status, headers, body)
  if status >= 500 then server_errors = server_errors + 1 end
  if status == 404 then not_found = not_found + 1 end
end

function delay()
  return math.floor(-math.log(1 - math.random()) * delay_ms + 0.5)
end

function done(summary, latency, requests_)
  local errors_5xx, errors_404 = 0, 0
  for _, thread in ipairs(threads) do
    errors_5xx = errors_5xx + (thread:get("server_errors") or 0)
    errors_404 = errors_404 + (thread:get("not_found") or 0)
  end
  io.write(string.format("poll_requests %d\npoll_duration_s %.2f\npoll_rate_per_s %.0f\n",
    summary.requests, summary.duration / 1e6, summary.requests / (summary.duration / 1e6)))
  io.write(string.format("poll_p50_ms %.3f\npoll_p99_ms %.3f\npoll_p999_ms %.3f\npoll_max_ms %.3f\n",
    latency:percentile(50) / 1000, latency:percentile(99) / 1000,
    latency:percentile(99.9) / 1000, latency.max / 1000))
  io.write(string.format("poll_5xx %d\npoll_404 %d\npoll_socket_errors %d\n", errors_5xx, errors_404,
    summary.errors.connect + summary.errors.read + summary.errors.write + summary.errors.timeout))
end
