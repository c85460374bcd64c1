#!/usr/bin/env bash
# omnirig's two commands:
#   ./omnirig.sh run [SERVE OPTIONS]   install what is missing, build what serving needs (the
#                                      `omnirig` executable; the web page needs no build), serve
#                                      on http://127.0.0.1:8080 with the data in ./data. Options
#                                      go to `omnirig serve` (e.g. --port 9000 --data DIR; see
#                                      build/server/omnirig serve --help).
#   ./omnirig.sh test                  install what is missing, build everything (tests and
#                                      benchmarks too), run every test (unit, sanitizer,
#                                      integration, browser) and every fuzz
#                                      target briefly over its corpus
# Re-running either on a set-up machine only rebuilds what changed.
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$(pwd)

APT_PACKAGES=(build-essential cmake ninja-build ccache pkg-config git
  libeigen3-dev libopencv-dev libopencv-contrib-dev libceres-dev libcpp-httplib-dev
  nlohmann-json3-dev libsqlite3-dev sqlite3 googletest libgtest-dev libbenchmark-dev
  libssl-dev libpq-dev libopengv-dev libbz2-dev liblz4-dev libzstd-dev zlib1g-dev nodejs npm
  libpng-dev curl jq)
# Only the tests need these: the browser they drive, a PostgreSQL server they start themselves,
# clang with its libFuzzer and sanitizer runtimes for the fuzz targets (fuzz/), unzip, which
# checks the job archives the server streams, and ROS's own bag writer (ROS 1 bags with bz2 and
# lz4 chunks) for the recordings they read.
TEST_APT_PACKAGES=(chromium postgresql clang libclang-rt-14-dev unzip python3-rosbag
  python3-sensor-msgs python3-roslz4)
JOBS=${OMNIRIG_JOBS:-$(nproc)}
# Cache compiles by paths relative to the checkout, so that a second clone reuses them.
export CCACHE_BASEDIR="$ROOT"

log() { printf '\033[1m[omnirig]\033[0m %s\n' "$*" >&2; }

install_apt_packages() {  # package...
  local missing=()
  for pkg in "$@"; do
    # Node.js may come from elsewhere than Debian (e.g. nodesource); only install when absent.
    if [[ $pkg == nodejs && -x "$(command -v node)" ]] || [[ $pkg == npm && -x "$(command -v npm)" ]]; then
      continue
    fi
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done
  [[ ${#missing[@]} -eq 0 ]] && return
  log "installing Debian packages: ${missing[*]}"
  local sudo=()
  [[ $(id -u) -ne 0 ]] && sudo=(sudo)
  "${sudo[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

install_npm_packages() {
  # web/package.json carries three.js (the 3D viewer), playwright-core (browser tests) and, for
  # the tests' recordings, the MCAP writer @mcap/core with @foxglove/cdr, lz4js, wasm-zstd.
  [[ -f web/package.json ]] || return 0
  local stamp=web/node_modules/.omnirig-installed
  if [[ ! -f $stamp || web/package.json -nt $stamp || web/package-lock.json -nt $stamp ]]; then
    log "installing npm packages for web/"
    (cd web && if [[ -f package-lock.json ]]; then npm ci --no-audit --no-fund; else npm install --no-audit --no-fund; fi)
    touch "$stamp"
  fi
}

configure() {  # build_dir [cmake args...]
  local dir=$1
  shift
  if [[ ! -f $dir/build.ninja ]]; then
    cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DOMNIRIG_WERROR=ON "$@"
  fi
}

configure_and_build() {  # build_dir [cmake args...]
  configure "$@"
  cmake --build "$1" -j "$JOBS"
}

cmd_run() {
  install_apt_packages "${APT_PACKAGES[@]}"
  install_npm_packages
  configure build
  # Serving needs the `omnirig` executable only: tests and benchmarks are built by `test`.
  cmake --build build -j "$JOBS" --target omnirig
  local port=8080 data=./data args=("$@")
  for ((i = 0; i < ${#args[@]}; i++)); do
    case ${args[i]} in
      --port) port=${args[i + 1]:-$port} ;;
      --port=*) port=${args[i]#--port=} ;;
      --data) data=${args[i + 1]:-$data} ;;
      --data=*) data=${args[i]#--data=} ;;
    esac
  done
  mkdir -p "$data"
  log "serving on http://127.0.0.1:$port (data in $data)"
  # Later options win: the user's come after the defaults.
  exec build/server/omnirig serve --host 127.0.0.1 --port 8080 --data ./data "$@"
}

cmd_test() {
  install_apt_packages "${APT_PACKAGES[@]}" "${TEST_APT_PACKAGES[@]}"
  install_npm_packages
  configure_and_build build
  log "unit, integration and browser tests (Release)"
  (cd build && ctest --output-on-failure -j "$JOBS")
  log "unit tests under AddressSanitizer + UndefinedBehaviorSanitizer"
  # -O1: sanitizer builds only need to run the unit tests, and compile much faster than -O3.
  configure_and_build build-asan -DOMNIRIG_SANITIZE=ON -DCMAKE_CXX_FLAGS_RELEASE="-O1 -DNDEBUG"
  (cd build-asan && ctest --output-on-failure -j "$JOBS" -L unit)
  log "fuzz targets: their seed corpora, then mutations up to 2000 inputs each (libFuzzer, ASan + UBSan)"
  # build-fuzz/ (clang) holds the fuzz targets and the libraries they link only.
  OMNIRIG_JOBS=$JOBS scripts/fuzz.sh --runs 2000
  log "all tests passed"
}

case "${1:-}" in
  run)
    shift
    cmd_run "$@"
    ;;
  test) cmd_test ;;
  *)
    echo "usage: $0 run [omnirig serve options, e.g. --port 9000 --data DIR] | test" >&2
    exit 2
    ;;
esac
