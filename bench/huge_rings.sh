#!/usr/bin/env bash
# Import time and AGVS sampling rate on one building with huge rings (issue 20), for rings of
# 5,000, 20,000 and 50,000 nodes: prints a Markdown table. VISTREAM=path picks the binary (to
# compare builds side by side); SECONDS_AGVS the sampling time per scene (default 10).
#   bench/huge_rings.sh [NODES ...]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bin=${VISTREAM:-build/bin/vistream}
secs=${SECONDS_AGVS:-10}
[ $# -gt 0 ] || set -- 5000 20000 50000
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
# The number under key $1 in the pretty-printed JSON on stdin.
json() { sed -n "s/^ *\"$1\": \([-0-9.e+]*\),\{0,1\}$/\1/p" | head -1; }
echo "| nodes per ring | triangles | import (s) | AGVS samples/s | AGVS rays/s |"
echo "|---|---|---|---|---|"
for n in "$@"; do
  bench/huge_ring_osm.sh "$n" "$dir/ring.osm"
  import=$("$bin" scene import-osm "$dir/ring.osm" -o "$dir/ring.glb" --json | json import_s)
  tris=$("$bin" scene info "$dir/ring.glb" --json | json triangles)
  agvs=$("$bin" agvs --scene "$dir/ring.glb" --cell-size 50 --seconds "$secs" --json)
  sps=$(echo "$agvs" | json samples_per_s)
  rps=$(echo "$agvs" | json rays_per_s)
  printf '| %s | %s | %.2f | %.0f | %.0f |\n' "$n" "$tris" "$import" "$sps" "$rps"
done
