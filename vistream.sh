#!/usr/bin/env bash
# vistream set-up and entry point. The two commands of the README (README.md, "The two commands"):
#   ./vistream.sh run    install what is missing, configure, build, run the main job
#   ./vistream.sh test   install what is missing, configure, build, run every test
# Both are idempotent: a second call with nothing changed only re-checks and rebuilds nothing.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"

# Debian 12 packages the project builds against. Keep in one place.
PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler libabsl-dev
  libosmesa6-dev libglfw3-dev libglm-dev libembree-dev libtbb-dev libtinygltf-dev
  nlohmann-json3-dev libcli11-dev libpng-dev zlib1g-dev libbz2-dev libdraco-dev
  libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev
  libcgal-dev libgmp-dev libmpfr-dev libmeshoptimizer-dev libosmium2-dev libgeographiclib-dev
  xvfb xauth xdotool   # the window's tests: a bare X server and real key presses
  libimgui-dev   # the client's overlay (Dear ImGui with its GLFW back end)
  libcairo2-dev gnuplot-nox fonts-dejavu-core   # figures: maps through Cairo, plots through gnuplot
  libtomlplusplus-dev   # the server's configuration file
  libcpp-httplib-dev prometheus   # the server's /metrics and /healthz; promtool checks the exposition in a test
  libssl-dev openssl   # TLS: checking PEM files (server and client), certificates made by the tests and bench server --tls
  dpkg-dev systemd   # the package (cpack -G DEB: dpkg-shlibdeps) and its unit's check (systemd-analyze)
  libhiredis-dev redis-server   # the PVS store replicas share (Redis), and the real Redis its tests start
  stunnel4   # a TLS-only Redis reached through stunnel, as docs/scaling-out.md says (tested)
  libcitygml-dev   # the CityGML reader (scenes/citygml_read.cpp)
  haproxy   # the load balancer in front of replicas (deploy/haproxy.cfg); balancer_test runs it
  chromium   # the browser client's tests and `vistream bench web` (headless, WebGL 2 through SwiftShader)
  libboost-dev   # the web edge (server/web_server.h): Boost.Beast HTTP and WebSocket over Boost.Asio
)
BUILD_DIR=${VISTREAM_BUILD_DIR:-build}
BUILD_TYPE=${VISTREAM_BUILD_TYPE:-RelWithDebInfo}

log() { printf '[vistream] %s\n' "$*" >&2; }

install_packages() {
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  log "installing ${#missing[@]} missing Debian packages: ${missing[*]}"
  local sudo=()
  [ "$(id -u)" -ne 0 ] && sudo=(sudo)
  "${sudo[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends \
    "${missing[@]}"
}

# The Khronos glTF validator checks the .glb files vistream writes (ctest gltf_validator_test).
# An npm library, pinned, installed into the build folder (ignored by git); node and npm come
# from Debian only when they are missing, so an existing install (e.g. nodesource's) is kept.
GLTF_VALIDATOR_VERSION=2.0.0-dev.3.10
install_gltf_validator() {
  if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    log "installing Debian's nodejs and npm (for the glTF validator)"
    local sudo=()
    [ "$(id -u)" -ne 0 ] && sudo=(sudo)
    "${sudo[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends nodejs npm
  fi
  local dir="$BUILD_DIR/node"
  local installed="$dir/node_modules/gltf-validator/package.json"
  if [ -f "$installed" ] && grep -q "\"version\": *\"$GLTF_VALIDATOR_VERSION\"" "$installed"; then
    return 0
  fi
  log "installing gltf-validator@$GLTF_VALIDATOR_VERSION (npm) into $dir"
  mkdir -p "$dir"
  npm install --prefix "$dir" --no-save --no-audit --no-fund --loglevel=error \
    "gltf-validator@$GLTF_VALIDATOR_VERSION" >&2
}

# The browser client's npm packages (three.js, meshoptimizer, protobufjs, esbuild; puppeteer-core
# for its headless tests), pinned by web/package-lock.json, into web/node_modules (ignored by
# git); the build bundles the page from them (web/CMakeLists.txt).
install_web_packages() {
  # npm ci writes web/node_modules/.package-lock.json: newer than the lock file, nothing to do.
  if [ -f web/node_modules/.package-lock.json ] && [ web/node_modules/.package-lock.json -nt web/package-lock.json ]; then
    return 0
  fi
  log "installing the browser client's npm packages (web/package-lock.json) into web/node_modules"
  npm ci --prefix web --no-audit --no-fund --loglevel=error >&2
}

configure_and_build() {
  local extra=()
  [ "${CI:-}" = "true" ] && extra+=(-DVISTREAM_WERROR=ON)
  # VISTREAM_DEBUG_INFO=0: RelWithDebInfo without -g (.ci/run: a third less compile time);
  # =1: with it again (CMake's default, which an unset variable leaves as the folder has it).
  case "${VISTREAM_DEBUG_INFO:-}" in
    0) extra+=(-DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -DNDEBUG") ;;
    1) extra+=(-DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g -DNDEBUG") ;;
  esac
  if [ ! -f "$BUILD_DIR/build.ninja" ] || [ ${#extra[@]} -gt 0 ]; then
    cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE="$BUILD_TYPE" "${extra[@]}" >/dev/null
  fi
  # Two jobs: the machine has 2 cores and gRPC headers are heavy on memory.
  cmake --build "$BUILD_DIR" --parallel "${VISTREAM_JOBS:-2}"
}

cmd=${1:-}
case "$cmd" in
  run)
    install_packages
    install_gltf_validator
    install_web_packages
    configure_and_build
    shift
    # The main job: a walkthrough. A server on the default scene (a free loopback port), the
    # headless client along the default walk (at 60 km/h unless --speed is given, checking
    # its frames against the full scene), then the server is stopped.
    out="$BUILD_DIR/walkthrough"
    # This run's screenshots go to a fresh folder that replaces the last run's only once it
    # holds any: a run that fails before its first frame (a bad --path) leaves the old ones.
    rm -rf "$out/screenshots.new"
    mkdir -p "$out/screenshots.new"
    "$BUILD_DIR/bin/vistream-server" --scene default --listen 127.0.0.1:0 >"$out/server.out" 2>"$out/server.log" &
    server=$!
    stop_server() { kill -TERM "$server" 2>/dev/null && wait "$server" 2>/dev/null || true; }
    trap stop_server EXIT
    trap 'exit 130' INT TERM  # while waiting for the server
    address=""
    for _ in $(seq 1 600); do
      address=$(sed -n 's/^vistream-server: ready on \([0-9.]*:[0-9]*\): .*/\1/p' "$out/server.out")
      [ -n "$address" ] && break
      if ! kill -0 "$server" 2>/dev/null; then
        log "the server did not start; its log:"
        cat "$out/server.log" >&2
        exit 1
      fi
      sleep 0.5
    done
    [ -n "$address" ] || { log "the server was not ready after 300 s; log in $out/server.log"; exit 1; }
    log "server ready on $address (log: $out/server.log)"
    # The script's defaults, unless given (as --speed 30 or --speed=30).
    speed=(--speed 60) every=(--every 10)
    for a in "$@"; do
      case "$a" in
        --speed | --speed=*) speed=() ;;
        --every | --every=*) every=() ;;
      esac
    done
    defaults=("${speed[@]}" "${every[@]}")
    rm -f "$out/frames.csv"
    "$BUILD_DIR/bin/vistream-client" --server "$address" --headless --verify \
      --screenshots "$out/screenshots.new" --frame-log "$out/frames.csv" "${defaults[@]}" "$@" &
    client=$!
    # A signal to this script reaches the client (which stops after its frame and prints what
    # it walked); the server is stopped on the way out.
    trap 'kill -INT "$client" 2>/dev/null' INT TERM
    rc=0
    wait "$client" || rc=$?
    while kill -0 "$client" 2>/dev/null; do wait "$client" || rc=$?; done
    stop_server
    trap - EXIT
    shots=$(find "$out/screenshots.new" -name '*.png' | wc -l)
    if [ "$shots" -gt 0 ]; then
      rm -rf "$out/screenshots"
      mv "$out/screenshots.new" "$out/screenshots"
      log "screenshots: $shots PNGs in $out/screenshots; per-frame log: $out/frames.csv"
    else
      rm -rf "$out/screenshots.new"
    fi
    exit "$rc"
    ;;
  test)
    install_packages
    install_gltf_validator
    install_web_packages
    configure_and_build
    ctest --test-dir "$BUILD_DIR" --no-tests=error --output-on-failure --parallel "${VISTREAM_JOBS:-2}" \
      --timeout 900
    ;;
  *)
    echo "usage: ./vistream.sh run|test" >&2
    exit 2
    ;;
esac
