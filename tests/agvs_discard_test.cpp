#include "visibility/agvs.h"

#include <gtest/gtest.h>

#include "scenes/building.h"

// Samples that start inside a solid are discarded (AGVS, Bittner et al. 2009, section 8),
// also where Embree reports the coincident face of a neighbour rather than the solid's own
// back face, and the ground is solid.

namespace vistream::visibility {
namespace {

using scenes::Aabb;

std::vector<glm::dvec2> Rect(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

std::unique_ptr<GlobalSampler> Sampler(const scenes::Scene& s, const ViewcellGrid& g) {
  AgvsOptions o;
  o.batch_samples = 8192;
  o.threads = 2;
  absl::StatusOr<std::unique_ptr<GlobalSampler>> r = GlobalSampler::Create(s, g, o);
  EXPECT_TRUE(r.ok()) << r.status();
  return std::move(*r);
}

// Touching houses each have their own party wall, in the same place, facing away from each
// other, and a tier's floor lies on the roof below it: whichever of two coincident faces
// Embree reports, a sample that starts inside a house must be discarded. So a viewcell inside
// a house sees nothing, and one in the street sees what the street sees.
TEST(AgvsDiscards, NothingIsSeenThroughPartyWallsOrFromInsideATerrace) {
  scenes::Scene s;
  s.name = "terrace";
  const double heights[] = {9, 12, 9, 15};
  for (int k = 0; k < 4; ++k) {
    scenes::AddBuilding(&s, "house", {scenes::Prism{Rect(10.0 * k, 0, 10.0 * (k + 1), 12), 0.0, heights[k]}});
  }
  scenes::AddBuilding(&s, "tiered", {scenes::Prism{Rect(50, 0, 70, 20), 0.0, 10.0},
                                     scenes::Prism{Rect(55, 5, 65, 15), 10.0, 30.0}});
  scenes::AddBuilding(&s, "across the street", {scenes::Prism{Rect(0, 24, 70, 30), 0.0, 8.0}});
  absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(Aabb{glm::dvec3(0, 0, 0), glm::dvec3(70, 30, 30)}, 2.0, 0.5, 2.0);
  ASSERT_TRUE(g.ok());
  auto sampler = Sampler(s, *g);
  for (int round = 0; round < 60; ++round) sampler->RunBatch();
  size_t inside = 0, street = 0;
  for (CellId c = 0; c < g->CellCount(); ++c) {
    const Aabb cell = g->CellBox(c);
    // Strictly inside: a cell whose face lies on a street wall is reached by segments that end
    // on that wall.
    const bool in_house = (cell.min.x > 0 && cell.max.x < 40 && cell.min.y > 0 && cell.max.y < 12) ||
                          (cell.min.x > 50 && cell.max.x < 70 && cell.min.y > 0 && cell.max.y < 20);
    if (in_house) {
      ++inside;
      EXPECT_TRUE(sampler->pvs().Objects(c).empty()) << "cell " << c << " at (" << cell.min.x << ", " << cell.min.y
                                                     << ") inside a house sees " << sampler->pvs().Objects(c).size()
                                                     << " objects";
    } else if (cell.min.y >= 20 && cell.max.y <= 24 && cell.max.x <= 40) {
      ++street;
      EXPECT_GE(sampler->pvs().Objects(c).size(), 2u) << "cell " << c << " in the street";
    }
  }
  EXPECT_GT(inside, 60u);
  EXPECT_GT(street, 10u);
}

// A surface sample (object-direction distribution: a ray from a random point of a random
// object) that starts on a party wall leaves it into the neighbouring house: from inside that
// solid, so it is discarded too, though its ray meets only front faces (here a cabinet inside
// the east house; in a town on a hill, the ground inside a house whose floor lies below it).
// Nothing outside the east house sees the cabinet, and no cell inside it sees anything.
TEST(AgvsDiscards, NothingIsSeenFromAPointOnAPartyWall) {
  scenes::Scene s;
  s.name = "cabinet";
  scenes::AddBuilding(&s, "west house", {scenes::Prism{Rect(0, 0, 10, 10), 0.0, 10.0}});
  scenes::AddBuilding(&s, "east house", {scenes::Prism{Rect(10, 0, 20, 10), 0.0, 10.0}});
  const scenes::ObjectId cabinet = scenes::AddBuilding(&s, "cabinet", {scenes::Prism{Rect(14, 4, 16, 6), 0.0, 2.0}});
  absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(Aabb{glm::dvec3(0, 0, 0), glm::dvec3(30, 20, 10)}, 1.0, 0.5, 2.0);
  ASSERT_TRUE(g.ok());
  auto sampler = Sampler(s, *g);
  for (int round = 0; round < 40; ++round) sampler->RunBatch();
  size_t inside = 0, street = 0;
  for (CellId c = 0; c < g->CellCount(); ++c) {
    const Aabb cell = g->CellBox(c);
    EXPECT_FALSE(sampler->pvs().Contains(c, cabinet)) << "cell " << c << " at (" << cell.min.x << ", " << cell.min.y
                                                      << ") sees the cabinet inside the east house";
    if (cell.min.x > 10 && cell.max.x < 20 && cell.min.y > 0 && cell.max.y < 10) {
      ++inside;
      EXPECT_TRUE(sampler->pvs().Objects(c).empty()) << "cell " << c << " at (" << cell.min.x << ", " << cell.min.y
                                                     << ") inside the east house sees "
                                                     << sampler->pvs().Objects(c).size() << " objects";
    } else if (cell.min.y >= 12 && cell.max.x <= 20) {
      street += sampler->pvs().Contains(c, 0) && sampler->pvs().Contains(c, 1);
    }
  }
  EXPECT_EQ(inside, 64u);
  EXPECT_GT(street, 100u);  // of the 160 cells north of the houses
}

// The ground is solid: a cell standing on it never sees what lies beneath it (a slab under an
// open square), while it does see the building beside it.
TEST(AgvsDiscards, NothingBeneathTheGroundIsSeen) {
  scenes::Scene s;
  s.name = "basement";
  scenes::AddBuilding(&s, "house", {scenes::Prism{Rect(0, 0, 10, 10), 0.0, 8.0}});
  scenes::AddBuilding(&s, "slab below the square", {scenes::Prism{Rect(12, 0, 30, 20), -4.0, -1.0}});
  absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(Aabb{glm::dvec3(0, 0, -4), glm::dvec3(30, 20, 8)}, 2.0, 0.0, 2.0);
  ASSERT_TRUE(g.ok());
  auto sampler = Sampler(s, *g);
  for (int round = 0; round < 30; ++round) sampler->RunBatch();
  size_t see_house = 0;
  for (CellId c = 0; c < g->CellCount(); ++c) {
    EXPECT_FALSE(sampler->pvs().Contains(c, 1)) << "cell " << c << " sees the slab beneath the ground";
    see_house += sampler->pvs().Contains(c, 0);
  }
  EXPECT_GT(see_house, g->CellCount() / 2);
}

// A low annex between two tall houses lies on one triangle only of each house's wall: a wall
// is two triangles, (a0, b0, b1) below its diagonal from the foot of its first corner a to
// the top of its second corner b, and (a0, b1, a1) above it; the annex's 3 m stay under the
// diagonal (the west house's east wall runs from y = 0 to 10 and rises 20 m, the east house's
// west wall runs from y = 30 to 5 and rises 20 m: both diagonals are over 10 m high above the
// annex). A ray from inside the annex that Embree reports on a house's wall rather than on
// the annex's own (back) face must be discarded, as it must where the partner lies on either
// triangle: the annex's cells see nothing, the street north of it sees the annex.
TEST(AgvsDiscards, NothingIsSeenFromInsideAnAnnexTouchingOneTriangleOfEachWall) {
  scenes::Scene s;
  s.name = "annex";
  scenes::AddBuilding(&s, "west house", {scenes::Prism{Rect(0, 0, 10, 10), 0.0, 20.0}});
  scenes::AddBuilding(&s, "east house", {scenes::Prism{Rect(16, 5, 26, 30), 0.0, 20.0}});
  const scenes::ObjectId annex = scenes::AddBuilding(&s, "annex", {scenes::Prism{Rect(10, 5, 16, 10), 0.0, 3.0}});
  absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(Aabb{glm::dvec3(0, 0, 0), glm::dvec3(26, 30, 20)}, 1.0, 0.5, 2.0);
  ASSERT_TRUE(g.ok());
  auto sampler = Sampler(s, *g);
  for (int round = 0; round < 40; ++round) sampler->RunBatch();
  size_t inside = 0, north = 0;
  for (CellId c = 0; c < g->CellCount(); ++c) {
    const Aabb cell = g->CellBox(c);
    if (cell.min.x > 10 && cell.max.x < 16 && cell.min.y > 5 && cell.max.y < 10) {
      ++inside;
      EXPECT_TRUE(sampler->pvs().Objects(c).empty()) << "cell " << c << " at (" << cell.min.x << ", " << cell.min.y
                                                     << ") inside the annex sees " << sampler->pvs().Objects(c).size()
                                                     << " objects";
    } else if (cell.min.x > 10 && cell.max.x < 16 && cell.min.y >= 11 && cell.max.y <= 14) {
      ++north;
      EXPECT_TRUE(sampler->pvs().Contains(c, annex)) << "cell " << c << " north of the annex";
    }
  }
  EXPECT_EQ(inside, 12u);
  EXPECT_EQ(north, 12u);
}

}  // namespace
}  // namespace vistream::visibility
