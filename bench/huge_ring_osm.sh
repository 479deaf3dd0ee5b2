#!/usr/bin/env bash
# Writes an OpenStreetMap file with one building whose rings are huge: a multipolygon of an
# outer ring of N nodes (radius 400 m) and a courtyard of N nodes (200 m), each drawn as three
# ways, like ../shared/cases/osm/b6_huge_ring_5k.osm (issue 20's "big rings").
#   bench/huge_ring_osm.sh N OUT.osm
set -euo pipefail
if [ $# -ne 2 ] || ! [[ $1 =~ ^[0-9]+$ ]] || [ "$1" -lt 3 ]; then
  echo "usage: $0 NODES_PER_RING OUT.osm (NODES_PER_RING >= 3)" >&2
  exit 2
fi
awk -v n="$1" 'BEGIN {
  pi = atan2(0, -1); lat0 = 47.0; lon0 = 8.0
  mlat = 111132.0; mlon = 111320.0 * cos(lat0 * pi / 180)
  print "<?xml version=\"1.0\" encoding=\"UTF-8\"?>"
  print "<osm version=\"0.6\" generator=\"vistream bench/huge_ring_osm.sh\">"
  for (r = 0; r < 2; r++) {
    radius = r == 0 ? 400.0 : 200.0; first = r == 0 ? 1001 : 1001 + n + 1000
    for (k = 0; k < n; k++) {
      a = 2 * pi * k / n
      printf " <node id=\"%d\" version=\"1\" lat=\"%.9f\" lon=\"%.9f\"/>\n", first + k, lat0 + radius * sin(a) / mlat, lon0 + radius * cos(a) / mlon
    }
  }
  cut[0] = 0; cut[1] = int(2 * n / 5); cut[2] = int(4 * n / 5); cut[3] = n
  for (r = 0; r < 2; r++) {
    first = r == 0 ? 1001 : 1001 + n + 1000
    for (j = 0; j < 3; j++) {
      printf " <way id=\"%d\" version=\"1\">", 5001 + 3 * r + j
      for (k = cut[j]; k <= cut[j + 1]; k++) printf "<nd ref=\"%d\"/>", first + (k % n)
      print "</way>"
    }
  }
  printf " <relation id=\"9001\" version=\"1\">"
  for (j = 0; j < 6; j++) printf "<member type=\"way\" ref=\"%d\" role=\"%s\"/>", 5001 + j, j < 3 ? "outer" : "inner"
  print "<tag k=\"type\" v=\"multipolygon\"/><tag k=\"building\" v=\"yes\"/><tag k=\"height\" v=\"20\"/></relation>"
  print "</osm>"
}' > "$2"
