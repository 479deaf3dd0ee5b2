#!/usr/bin/env bash
# The picture of the client's overlay (README.md, docs/client.md, docs/benchmarks.md): vistream-server on a scene (default london) on
# a free loopback port, the headless client along the scene's first walk with --overlay for
# SECONDS (default 60) of it, its last frame copied to OUT (default
# bench/figures/client_overlay_london.png), the overlay's lines beside it (.txt), and the
# client's --json summary (.json). The server is stopped however the script ends.
#   bench/overlay_screenshot.sh [SCENE [SECONDS [OUT]]]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scene=${1:-london}
seconds=${2:-60}
out=${3:-bench/figures/client_overlay_$scene.png}
bin=${VISTREAM_BIN:-build/bin}
dir=$(mktemp -d)
server=""
cleanup() {
  [ -n "$server" ] && kill "$server" 2>/dev/null && wait "$server" 2>/dev/null
  rm -rf "$dir"
}
trap cleanup EXIT
"$bin/vistream-server" --scene "$scene" --listen 127.0.0.1:0 >"$dir/ready" 2>"$dir/server.log" &
server=$!
# "ready on HOST:PORT: ..." once the scene is loaded (london: a minute or two).
for _ in $(seq 1 900); do
  grep -q "ready on" "$dir/ready" 2>/dev/null && break
  kill -0 "$server" 2>/dev/null || { cat "$dir/server.log" >&2; exit 1; }
  sleep 1
done
address=$(sed -n 's/.*ready on \([^ ]*\):.*/\1/p' "$dir/ready" | head -1)
[ -n "$address" ] || { echo "overlay_screenshot: the server did not get ready" >&2; exit 1; }
"$bin/vistream-client" --headless --overlay --server "$address" --seconds "$seconds" --every "$seconds" \
  --size 1280x720 --msaa 4 --screenshots "$dir/shots" --overlay-dump "${out%.png}.txt" --json >"${out%.png}.json"
cp "$(ls "$dir/shots"/*.png | sort | tail -1)" "$out"
echo "wrote $out, ${out%.png}.txt and ${out%.png}.json"
