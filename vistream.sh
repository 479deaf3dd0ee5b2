#!/usr/bin/env bash
# vistream set-up and entry point. The README's two commands:
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
  nlohmann-json3-dev libcli11-dev libpng-dev zlib1g-dev
  libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev
  libcgal-dev libgmp-dev libmpfr-dev libmeshoptimizer-dev libosmium2-dev libgeographiclib-dev
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

configure_and_build() {
  local extra=()
  [ "${CI:-}" = "true" ] && extra+=(-DVISTREAM_WERROR=ON)
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
    configure_and_build
    shift
    # The main job on the default scene from the catalog. Later stages extend this to the
    # full server + client walkthrough.
    mkdir -p "$BUILD_DIR/scenes"
    "$BUILD_DIR/bin/vistream" scene generate default -o "$BUILD_DIR/scenes/default.glb" "$@"
    "$BUILD_DIR/bin/vistream" scene info "$BUILD_DIR/scenes/default.glb"
    ;;
  test)
    install_packages
    configure_and_build
    ctest --test-dir "$BUILD_DIR" --no-tests=error --output-on-failure --parallel "${VISTREAM_JOBS:-2}" \
      --timeout 900
    ;;
  *)
    echo "usage: ./vistream.sh run|test" >&2
    exit 2
    ;;
esac
