#pragma once
// Walks derived from the data, so that any imported city can be walked without hand-written
// waypoints (Scene::paths): along its streets (OSM highway=* ways), its road surfaces
// (CityJSON Road objects), or, where the data has neither, through the free space between
// its buildings.
//
// Each source becomes a graph in scene-local metres (xy); its largest connected component (by
// total edge length) gives the walks. The first is the longest shortest path, found by a
// double sweep of Dijkstra (the node farthest from any node, then the node farthest from
// that); each further one starts at the node farthest from every earlier walk and ends at the
// node farthest from its start, so the walks spread over the component. Each walk is
// simplified (Douglas-Peucker, DeriveWalkOptions::simplify_m; its waypoints are graph nodes)
// and kept only if it is at least min_length_m long, except the first, which is kept whatever
// its length with a note saying the graph allows no longer one.

#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <glm/vec2.hpp>

#include "scenes/polygon.h"
#include "scenes/scene.h"

namespace vistream::scenes {

struct DeriveWalkOptions {
  size_t max_walks = 3;         // at most this many walks
  double min_length_m = 200.0;  // walks after the first shorter than this are dropped
  double simplify_m = 1.0;      // Douglas-Peucker tolerance, metres
  std::string name_prefix = "street";  // walks are named "<prefix> 1", "<prefix> 2", ...
  // Only the parts of the graph inside this xy box (scene-local metres, min and max corners)
  // are used, e.g. the scene's bounds, so that every walk stays over the viewcell grid.
  // Street polylines are cut where they leave it. None: everything.
  std::optional<std::pair<glm::dvec2, glm::dvec2>> bounds;
  // Road walks only (DeriveRoadWalks): what a walk keeps clearance_m from, as xy triangles
  // (scene-local metres; e.g. the buildings' triangles projected, zero-area ones as segments).
  // Road surfaces of a planar partition (the Dutch BGT) reach the walls, so a walk along a
  // pavement, or a simplification's shortcut past a corner, would touch or cut a building.
  std::vector<Triangle2> obstacles;
  double clearance_m = 0.0;
};

// What a derivation gives: the walks, their lengths, and what it found out on the way.
struct DerivedWalks {
  std::vector<ScenePath> paths;
  std::vector<double> lengths_m;  // of paths[i], along its simplified waypoints
  size_t graph_nodes = 0, graph_edges = 0, components = 0;
  size_t largest_component_nodes = 0;
  double largest_component_length_m = 0.0;  // total edge length
  // For people: why there are fewer walks than asked for, or why one is short ("the longest
  // walk the graph allows is 120 m, shorter than 200 m").
  std::vector<std::string> notes;
};

// One street as a polyline in scene-local metres (xy), and the street's name when it has one
// (OSM name=*; may be empty).
struct StreetPolyline {
  std::vector<glm::dvec2> points;
  std::string name;
};

// Walks along streets. Polylines are joined where they share a point (an end or an inner
// point, equal to 1 mm); a street crossing another without a shared point is not a junction
// (a bridge). A walk that follows one named street for more than half its length is named
// "<prefix> N (<street name>)". Polylines with non-finite points are skipped; fewer than 2
// usable points give no edges. No walks (and a note) when there are no edges.
DerivedWalks DeriveStreetWalks(const std::vector<StreetPolyline>& streets, const DeriveWalkOptions& options = {});

// Walks on road surfaces, e.g. CityJSON Road objects' surfaces projected to xy (scene-local
// metres): each polygon is triangulated (scenes/polygon.h; polygons that do not triangulate
// are skipped and counted in a note), and the graph joins each triangle's centroid to its
// vertices and to the midpoints of its edges. Triangles of different polygons that share a
// vertex or an edge (equal to 1 mm) are joined through it. Every graph edge lies inside one
// triangle, so the graph stays on the roads; the simplified walk leaves them by at most
// options.simplify_m. With options.obstacles, graph edges closer than options.clearance_m to
// one are left out and simplification takes only shortcuts that keep that clearance, so every
// segment of every walk keeps it.
DerivedWalks DeriveRoadWalks(const std::vector<PolygonWithHoles>& polygons, const DeriveWalkOptions& options = {});
// The same for simple polygons without holes (counter-clockwise or not).
DerivedWalks DeriveRoadWalks(const std::vector<std::vector<glm::dvec2>>& polygons,
                             const DeriveWalkOptions& options = {});

struct FreeSpaceOptions {
  double clearance_m = 2.0;  // every waypoint and every segment at least this far from obstacles
  double spacing_m = 4.0;    // of the grid of candidate points
  // Grids with more points than this use a coarser spacing (the note says which).
  size_t max_grid_points = 4'000'000;
};

// Walks through the free space of a scene without streets (a CityGML tile with buildings and
// terrain only). Obstacles are the xy projections of every triangle of every object that is
// not terrain (Scene::terrain) and every occluder footprint. The graph: points of a square
// grid (options.spacing_m) inside the scene's xy bounds at least clearance_m from every
// obstacle, 8-connected by segments that keep that clearance; simplification only takes
// shortcuts that keep it too, so every segment of every walk is at least clearance_m from
// every obstacle. walk.bounds, when set, narrows the grid further. No walks (and a note) when
// no two free points connect.
DerivedWalks DeriveFreeSpaceWalks(const Scene& scene, const FreeSpaceOptions& options = {},
                                  const DeriveWalkOptions& walk = {});

// The length of a polyline, metres.
double PolylineLength(const std::vector<glm::dvec2>& points);

}  // namespace vistream::scenes
