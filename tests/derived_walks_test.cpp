// Walks derived from the data (scenes/derived_walks.h): street graphs made by hand, road
// polygons, and the free space of a generated city checked against every footprint.
#include "scenes/derived_walks.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include <glm/geometric.hpp>

#include "scenes/city_generator.h"

namespace vistream::scenes {
namespace {

using P = glm::dvec2;

double PointSegment(const P& p, const P& a, const P& b) {
  const P ab = b - a;
  const double len2 = glm::dot(ab, ab);
  const double t = len2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / len2, 0.0, 1.0) : 0.0;
  return glm::distance(p, a + t * ab);
}

// Whether every point of segment ab lies on one of the polylines (to 1e-9 m): sampled.
bool OnPolylines(const P& a, const P& b, const std::vector<StreetPolyline>& streets) {
  for (int k = 0; k <= 100; ++k) {
    const P p = a + (b - a) * (k / 100.0);
    bool on = false;
    for (const StreetPolyline& s : streets) {
      for (size_t i = 0; i + 1 < s.points.size() && !on; ++i) on = PointSegment(p, s.points[i], s.points[i + 1]) < 1e-9;
    }
    if (!on) return false;
  }
  return true;
}

// The T junction, with collinear inner points, and a loop at the main street's east end: one
// component of 750 m. A zigzag far away with more nodes and only 150 m: another.
std::vector<StreetPolyline> HandMadeStreets() {
  return {
      {{{0, 0}, {100, 0}, {200, 0}, {300, 0}}, "Main Street"},
      {{{100, 0}, {100, -75}, {100, -150}}, ""},                          // the T's stem, from an inner point
      {{{300, 0}, {400, 0}, {400, 100}, {300, 100}, {300, 0}}, "Loop"},  // shares the main street's end
      {{{1000, 1000}, {1025, 1010}, {1050, 1000}, {1075, 1010}, {1100, 1000}, {1125, 1010}}, "Far"},
  };
}

TEST(DerivedWalks, StreetWalkIsTheLongestShortestPathOfTheLargestComponentSimplified) {
  const std::vector<StreetPolyline> streets = HandMadeStreets();
  DeriveWalkOptions o;
  o.max_walks = 1;
  const DerivedWalks d = DeriveStreetWalks(streets, o);
  EXPECT_EQ(d.components, 2u);
  EXPECT_EQ(d.graph_nodes, 15u);  // 9 in the first component (shared points once), 6 in the zigzag
  EXPECT_NEAR(d.largest_component_length_m, 850.0, 1e-9);
  ASSERT_EQ(d.paths.size(), 1u);
  const ScenePath& w = d.paths[0];
  EXPECT_EQ(w.name, "street 1");
  // The stem's foot to the loop's far corner, either way round the loop: 150 + 200 + 200 m.
  EXPECT_NEAR(d.lengths_m[0], 550.0, 1e-9);
  EXPECT_NEAR(PolylineLength(w.waypoints), 550.0, 1e-9);
  const std::set<std::pair<double, double>> ends{{w.waypoints.front().x, w.waypoints.front().y},
                                                 {w.waypoints.back().x, w.waypoints.back().y}};
  EXPECT_EQ(ends, (std::set<std::pair<double, double>>{{100, -150}, {400, 100}}));
  // Simplified: the stem's middle and the main street's collinear points are gone; the corners stay.
  EXPECT_TRUE(w.waypoints.size() == 4 || w.waypoints.size() == 5) << w.waypoints.size();
  EXPECT_EQ(std::count(w.waypoints.begin(), w.waypoints.end(), P(100, -75)), 0);
  EXPECT_EQ(std::count(w.waypoints.begin(), w.waypoints.end(), P(200, 0)), 0);
  EXPECT_EQ(std::count(w.waypoints.begin(), w.waypoints.end(), P(100, 0)), 1);
  for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
    EXPECT_TRUE(OnPolylines(w.waypoints[k], w.waypoints[k + 1], streets)) << "segment " << k;
  }
}

TEST(DerivedWalks, FurtherStreetWalksStartFarFromEarlierOnes) {
  const std::vector<StreetPolyline> streets = HandMadeStreets();
  const DerivedWalks d = DeriveStreetWalks(streets);  // up to 3
  ASSERT_GE(d.paths.size(), 2u);
  EXPECT_EQ(d.paths[1].name.rfind("street 2", 0), 0u) << d.paths[1].name;
  for (size_t i = 0; i < d.paths.size(); ++i) {
    EXPECT_GE(d.lengths_m[i], 200.0) << i;
    const ScenePath& w = d.paths[i];
    for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
      EXPECT_TRUE(OnPolylines(w.waypoints[k], w.waypoints[k + 1], streets)) << "walk " << i << " segment " << k;
    }
    // Never into the other component.
    for (const P& p : w.waypoints) EXPECT_LT(p.x, 500.0);
  }
  // Walk 2 starts 100 m from walk 1: the main street's west end or a loop corner walk 1 missed.
  const P s = d.paths[1].waypoints.front();
  EXPECT_TRUE(s == P(0, 0) || s == P(400, 0) || s == P(300, 100)) << s.x << ", " << s.y;
}

TEST(DerivedWalks, AWalkAlongOneNamedStreetIsNamedAfterIt) {
  const std::vector<StreetPolyline> streets = {
      {{{0, 0}, {150, 0}, {300, 0}}, "Boulevard"},
      {{{150, 0}, {150, 20}}, "Alley"},
  };
  const DerivedWalks d = DeriveStreetWalks(streets);
  ASSERT_FALSE(d.paths.empty());
  EXPECT_EQ(d.paths[0].name, "street 1 (Boulevard)");
  std::vector<P> w = d.paths[0].waypoints;
  if (!w.empty() && w.front() != P(0, 0)) std::reverse(w.begin(), w.end());
  EXPECT_EQ(w, (std::vector<P>{{0, 0}, {300, 0}}));
}

TEST(DerivedWalks, AShortGraphGivesOneWalkAndSaysSo) {
  const DerivedWalks d = DeriveStreetWalks({{{{0, 0}, {60, 0}, {60, 40}}, ""}});
  ASSERT_EQ(d.paths.size(), 1u);
  EXPECT_NEAR(d.lengths_m[0], 100.0, 1e-9);
  ASSERT_FALSE(d.notes.empty());
  EXPECT_NE(d.notes[0].find("the longest walk the graph allows is 100 m, shorter than 200 m"), std::string::npos)
      << d.notes[0];
}

TEST(DerivedWalks, NoStreetsNoWalksAndBadPointsCutStreets) {
  EXPECT_TRUE(DeriveStreetWalks({}).paths.empty());
  EXPECT_FALSE(DeriveStreetWalks({}).notes.empty());
  const double nan = std::nan("");
  const DerivedWalks d = DeriveStreetWalks({{{{0, 0}, {300, 0}, {nan, 5}, {300, 300}, {0, 300}}, ""}});
  ASSERT_EQ(d.paths.size(), 1u);
  EXPECT_EQ(d.components, 2u);
  EXPECT_NEAR(d.lengths_m[0], 300.0, 1e-9);
}

TEST(DerivedWalks, BoundsCutStreetsWhereTheyLeave) {
  DeriveWalkOptions o;
  o.bounds.emplace(P(-10, -10), P(250, 10));
  const DerivedWalks d = DeriveStreetWalks({{{{0, 0}, {100, 0}, {200, 0}, {300, 0}, {400, 0}}, ""}}, o);
  ASSERT_EQ(d.paths.size(), 1u);
  EXPECT_NEAR(d.lengths_m[0], 200.0, 1e-9);
  for (const P& p : d.paths[0].waypoints) EXPECT_LE(p.x, 250.0);
}

// Whether p lies in polygon `ring` (or within `tol` of it).
bool InPolygon(const P& p, const std::vector<P>& ring, double tol) {
  bool in = false;
  for (size_t i = 0, j = ring.size() - 1; i < ring.size(); j = i++) {
    if (PointSegment(p, ring[i], ring[j]) <= tol) return true;
    if ((ring[i].y > p.y) != (ring[j].y > p.y) &&
        p.x < (ring[j].x - ring[i].x) * (p.y - ring[i].y) / (ring[j].y - ring[i].y) + ring[i].x) {
      in = !in;
    }
  }
  return in;
}

TEST(DerivedWalks, RoadWalksStayOnTheRoads) {
  // An L of road surfaces: a long east-west road, a north-south one sharing an edge with its
  // east end, and one touching that only at a vertex; plus a square far away.
  const std::vector<std::vector<P>> roads = {
      {{0, 0}, {200, 0}, {200, 10}, {0, 10}},
      {{200, 0}, {210, 0}, {210, 10}, {200, 10}},  // shares the edge x = 200
      {{200, 10}, {210, 10}, {210, 150}, {200, 150}},
      {{210, 150}, {300, 150}, {300, 160}, {210, 160}},  // shares only the vertex (210, 150)
      {{1000, 1000}, {1010, 1000}, {1010, 1010}, {1000, 1010}},
  };
  const DerivedWalks d = DeriveRoadWalks(roads);
  ASSERT_FALSE(d.paths.empty());
  EXPECT_EQ(d.components, 2u);
  EXPECT_GE(d.lengths_m[0], 200.0 + 140.0);  // along the L, into the vertex-joined road
  for (const ScenePath& w : d.paths) {
    for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
      for (int s = 0; s <= 50; ++s) {
        const P p = w.waypoints[k] + (w.waypoints[k + 1] - w.waypoints[k]) * (s / 50.0);
        const bool on = std::any_of(roads.begin(), roads.end(), [&](const std::vector<P>& r) { return InPolygon(p, r, 1.0 + 1e-9); });
        EXPECT_TRUE(on) << w.name << " segment " << k << " at (" << p.x << ", " << p.y << ")";
      }
    }
  }
  // One end in the vertex-joined road: the polygons are joined through their shared vertex.
  const bool reaches = std::any_of(d.paths[0].waypoints.begin(), d.paths[0].waypoints.end(),
                                   [](const P& p) { return p.x > 215.0; });
  EXPECT_TRUE(reaches);
}

// Distance from segment ab to a simple polygon (0 when they meet or ab is inside).
double SegmentPolygonDistance(const P& a, const P& b, const std::vector<P>& poly) {
  if (InPolygon(a, poly, 0.0) || InPolygon(b, poly, 0.0)) return 0.0;
  auto cross = [](const P& o, const P& p, const P& q) { return (p.x - o.x) * (q.y - o.y) - (p.y - o.y) * (q.x - o.x); };
  double d = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < poly.size(); ++i) {
    const P& c = poly[i];
    const P& e = poly[(i + 1) % poly.size()];
    const double d1 = cross(c, e, a), d2 = cross(c, e, b), d3 = cross(a, b, c), d4 = cross(a, b, e);
    if (((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0)) && d1 != 0 && d2 != 0 && d3 != 0 && d4 != 0) return 0.0;
    d = std::min({d, PointSegment(a, c, e), PointSegment(b, c, e), PointSegment(c, a, b), PointSegment(e, a, b)});
  }
  return d;
}

// Pavements of a planar partition reach the walls: an L of road round a building's corner,
// sharing its edges. Without obstacles the walk runs along the wall (and a shortcut may cut the
// corner); with the building as an obstacle every segment keeps the clearance.
TEST(DerivedWalks, RoadWalksKeepTheirClearanceFromObstacles) {
  const std::vector<P> building = {{0, 10}, {90, 10}, {90, 100}, {0, 100}};
  const std::vector<std::vector<P>> roads = {
      {{0, 0}, {100, 0}, {100, 10}, {90, 10}, {0, 10}},
      {{90, 10}, {100, 10}, {100, 100}, {90, 100}},
  };
  auto nearest = [&](const DerivedWalks& d) {
    double n = std::numeric_limits<double>::infinity();
    for (const ScenePath& w : d.paths) {
      for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
        n = std::min(n, SegmentPolygonDistance(w.waypoints[k], w.waypoints[k + 1], building));
      }
    }
    return n;
  };
  const DerivedWalks free = DeriveRoadWalks(roads);
  ASSERT_FALSE(free.paths.empty());
  EXPECT_LT(nearest(free), 1.0) << "without obstacles the walk touches the building";
  DeriveWalkOptions options;
  options.obstacles = {{building[0], building[1], building[2]}, {building[0], building[2], building[3]}};
  options.clearance_m = 1.0;
  const DerivedWalks clear = DeriveRoadWalks(roads, options);
  ASSERT_FALSE(clear.paths.empty());
  EXPECT_GE(nearest(clear), 1.0);
  EXPECT_GE(clear.lengths_m[0], 150.0) << "still round the corner, along both arms";
}

TEST(DerivedWalks, FreeSpaceWalksOfCity1KeepTwoMetresFromEveryFootprintAndAreLong) {
  const Scene city = GenerateTestCity(/*dense=*/true, 1);
  const DerivedWalks d = DeriveFreeSpaceWalks(city);
  for (const std::string& n : d.notes) std::printf("note: %s\n", n.c_str());
  ASSERT_FALSE(d.paths.empty());
  std::printf("%zu free points, %zu edges, %zu components; walks:", d.graph_nodes, d.graph_edges, d.components);
  for (size_t i = 0; i < d.paths.size(); ++i) std::printf(" %s %.0f m (%zu points)", d.paths[i].name.c_str(), d.lengths_m[i], d.paths[i].waypoints.size());
  std::printf("\n");
  ASSERT_FALSE(city.occluders.empty());
  for (size_t i = 0; i < d.paths.size(); ++i) {
    const ScenePath& w = d.paths[i];
    EXPECT_GE(d.lengths_m[i], 200.0) << w.name;
    EXPECT_EQ(w.name, "street " + std::to_string(i + 1));
    for (const P& p : w.waypoints) {
      EXPECT_TRUE(p.x >= city.bounds.min.x && p.x <= city.bounds.max.x && p.y >= city.bounds.min.y &&
                  p.y <= city.bounds.max.y);
    }
    double nearest = std::numeric_limits<double>::infinity();
    for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
      for (const Occluder25D& oc : city.occluders) {
        const double dist = SegmentPolygonDistance(w.waypoints[k], w.waypoints[k + 1], oc.footprint);
        nearest = std::min(nearest, dist);
        ASSERT_GE(dist, 2.0) << w.name << " segment " << k << " comes within " << dist << " m of object " << oc.object;
      }
    }
    std::printf("%s: nearest footprint %.2f m\n", w.name.c_str(), nearest);
  }
}

TEST(DerivedWalks, FreeSpaceOfASceneFullOfBuildingGivesNoWalk) {
  Scene s;
  Mesh m;
  m.positions = {{-50, -50, 0}, {50, -50, 0}, {50, 50, 0}, {-50, 50, 10}};
  m.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  m.indices = {0, 1, 2, 0, 2, 3};
  s.AddObject("slab", m);
  s.bounds = s.objects[0].bounds;
  const DerivedWalks d = DeriveFreeSpaceWalks(s);
  EXPECT_TRUE(d.paths.empty());
  EXPECT_FALSE(d.notes.empty());
  // As terrain the same slab is walked on.
  s.terrain = {0};
  const DerivedWalks t = DeriveFreeSpaceWalks(s);
  ASSERT_FALSE(t.paths.empty());
  EXPECT_GE(t.lengths_m[0], 100.0);
}

}  // namespace
}  // namespace vistream::scenes
