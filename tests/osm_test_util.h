#pragma once
// Helpers of the OpenStreetMap import tests: OSM XML written from scene-local metres, so that
// the right footprint and area are known by construction (the shoelace formula on the metres
// written), and the checks the tests share.

#include <absl/status/statusor.h>

#include <glm/vec2.hpp>
#include <string>
#include <vector>

#include "scenes/osm_import.h"

namespace vistream::scenes::testing_osm {

// A closed way (or a relation's member way) in metres east and north of a centre.
struct MetricWay {
  long long id = 0;                     // negative ids like an editor's
  std::vector<glm::dvec2> ring;         // open; the way closes it with the first node's id
  std::vector<std::pair<std::string, std::string>> tags;
};
struct MetricRelation {
  long long id = 0;
  std::vector<std::pair<long long, std::string>> members;  // way id, role
  std::vector<std::pair<std::string, std::string>> tags;
};

// Writes an OSM XML file with the ways' nodes at `centre` (lat, lon in degrees) plus the metre
// offsets along the UTM grid of the centre's zone (GeographicLib's inverse; 1e-9 degrees, about
// 0.1 mm). Nodes shared by ways are written once when their metres are equal. Node ids count
// down from -1 when `negative_ids`, else up from 1; `shuffle` writes the elements in reverse
// order (ids out of order).
std::string WriteMetricOsm(const std::string& path, glm::dvec2 centre_lat_lon,
                           const std::vector<MetricWay>& ways,
                           const std::vector<MetricRelation>& relations = {},
                           bool negative_ids = false, bool shuffle = false);

// The rectangle [x0, x1] x [y0, y1], counter-clockwise (metres).
std::vector<glm::dvec2> Rect(double x0, double y0, double x1, double y1);

// Shoelace area of a ring (m², positive counter-clockwise).
double Shoelace(const std::vector<glm::dvec2>& ring);

// The area of the triangles facing up at height z.
double RoofArea(const Mesh& m, float z);

// Every directed edge matched by its twin: a closed mesh.
bool Closed(const Mesh& m);

const Object* ByName(const Scene& s, const std::string& name);

// Occluders of object `id`, and their total footprint area.
size_t OccluderCount(const Scene& s, ObjectId id);
double OccluderArea(const Scene& s, ObjectId id);

}  // namespace vistream::scenes::testing_osm
