// The ε-neighbourhoods ahead of a walker (server/neighbourhood_chain.h).
#include "server/neighbourhood_chain.h"

#include <cmath>

#include <gtest/gtest.h>

namespace vistream::server {
namespace {

using visibility::CellId;
using visibility::ViewcellGrid;

// 100 m cells over [0, 500] x [0, 500], eye band 0.5 to 2.5 m.
ViewcellGrid Grid() {
  absl::StatusOr<ViewcellGrid> g =
      ViewcellGrid::Create(scenes::Aabb{glm::dvec3(0.0), glm::dvec3(500.0, 500.0, 10.0)}, 100.0, 0.5, 2.0);
  EXPECT_TRUE(g.ok()) << g.status();
  return *g;
}

const auto kAnyCell = [](CellId) { return true; };

bool Covered(const NeighbourhoodChain& chain, const glm::dvec3& p) {
  for (const Neighbourhood& n : chain.boxes()) {
    if (n.box.Contains(p)) return true;
  }
  return false;
}

// A walker on a straight line at `speed` m/s, a pose every 0.1 s for `seconds`: every point of
// its walk is inside a box planned before it got there, every box lies in its one viewcell, and
// the chain always reaches the horizon ahead.
TEST(NeighbourhoodChain, AStraightWalkIsCoveredAheadByBoxesInsideTheirCells) {
  const ViewcellGrid grid = Grid();
  for (double speed : {1.67, 16.7}) {
    for (double angle : {0.0, M_PI / 2.0, 0.6}) {
      NeighbourhoodChain chain;
      const glm::dvec3 v(speed * std::cos(angle), speed * std::sin(angle), 0.0);
      const glm::dvec3 start(20.0, 20.0, 1.7);
      size_t boxes = 0, covered = 0, poses = 0;
      for (double t = 0.0; t < 20.0; t += 0.1) {
        const glm::dvec3 eye = start + t * v;
        if (!grid.CellAt(glm::dvec2(eye.x + 50.0 * std::cos(angle), eye.y + 50.0 * std::sin(angle)))) break;
        // Before this pose's update: was the eye already inside a planned box?
        if (t > 0.0) {
          ++poses;
          covered += Covered(chain, eye) ? 1 : 0;
        }
        const NeighbourhoodChain::Update u = chain.Advance(eye, v, 0.0, grid, kAnyCell);
        boxes += u.added.size();
        for (const Neighbourhood& n : u.added) {
          const scenes::Aabb cell = grid.CellBox(n.cell);
          EXPECT_GE(n.box.min.x, cell.min.x);
          EXPECT_GE(n.box.min.y, cell.min.y);
          EXPECT_LE(n.box.max.x, cell.max.x);
          EXPECT_LE(n.box.max.y, cell.max.y);
          EXPECT_NEAR(n.box.max.z - n.box.min.z, 0.6, 1e-9);
          EXPECT_LE(n.box.min.z, 1.7);
          EXPECT_GE(n.box.max.z, 1.7);
          const glm::dvec3 e = n.box.max - n.box.min;
          EXPECT_LE(e.x * e.y, chain.options().max_area_m2 + 1e-9) << "speed " << speed;
        }
        // The chain reaches the horizon: the point horizon_s ahead (or min_horizon_m) is covered.
        const double ahead = std::clamp(speed * 8.0, 12.0, 160.0) - 1.0;
        const glm::dvec3 far = eye + ahead / speed * v;
        if (grid.CellAt(glm::dvec2(far.x, far.y))) {
          EXPECT_TRUE(Covered(chain, far)) << "t " << t << " speed " << speed;
        }
      }
      EXPECT_EQ(covered, poses) << "speed " << speed << " angle " << angle;
      // Boxes are long: at walking pace about 5 m (4 s of walking: fewer than one box a second).
      EXPECT_LT(static_cast<double>(boxes), 0.5 * 20.0 * speed / 4.0 + 12.0) << "speed " << speed;
    }
  }
}

TEST(NeighbourhoodChain, AStandingEyeGetsOneBoxAroundItInsideItsCell) {
  const ViewcellGrid grid = Grid();
  NeighbourhoodChain chain;
  NeighbourhoodChain::Update u = chain.Advance(glm::dvec3(150.0, 150.0, 1.7), glm::dvec3(0.0), 0.0, grid, kAnyCell);
  ASSERT_EQ(u.added.size(), 1u);
  EXPECT_NEAR(u.added[0].box.max.x - u.added[0].box.min.x, 4.0, 1e-9);
  EXPECT_NEAR(u.added[0].box.max.y - u.added[0].box.min.y, 4.0, 1e-9);
  // Swaying inside it changes nothing; by a cell edge the box stops at the edge.
  u = chain.Advance(glm::dvec3(150.5, 149.6, 1.7), glm::dvec3(0.1, 0.0, 0.0), 0.0, grid, kAnyCell);
  EXPECT_TRUE(u.added.empty() && u.removed.empty());
  u = chain.Advance(glm::dvec3(199.5, 101.0, 1.7), glm::dvec3(0.0), 0.0, grid, kAnyCell);
  ASSERT_EQ(u.added.size(), 1u);
  ASSERT_EQ(u.removed.size(), 1u);
  EXPECT_EQ(u.added[0].cell, grid.Id({1, 1}));
  EXPECT_NEAR(u.added[0].box.max.x, 200.0, 1e-9);
  EXPECT_NEAR(u.added[0].box.min.y, 100.0, 1e-9);
}

TEST(NeighbourhoodChain, ATurnOrAJumpDropsTheBoxesOffThePathAndStartsAgainFromTheEye) {
  const ViewcellGrid grid = Grid();
  NeighbourhoodChain chain;
  const glm::dvec3 east(1.67, 0.0, 0.0), north(0.0, 1.67, 0.0);
  chain.Advance(glm::dvec3(120.0, 150.0, 1.7), east, 0.0, grid, kAnyCell);
  ASSERT_GE(chain.boxes().size(), 2u);
  // Turning north on the spot: the boxes ahead to the east go; the one it stands in stays.
  NeighbourhoodChain::Update u = chain.Advance(glm::dvec3(120.0, 150.0, 1.7), north, 0.0, grid, kAnyCell);
  EXPECT_FALSE(u.removed.empty());
  EXPECT_FALSE(u.added.empty());
  for (const Neighbourhood& n : chain.boxes()) EXPECT_LT(n.box.min.x, 122.0);
  EXPECT_TRUE(Covered(chain, glm::dvec3(120.0, 160.0, 1.7)));
  // A jump: nothing planned holds the eye; everything goes, a new chain starts at the eye.
  const size_t before = chain.boxes().size();
  u = chain.Advance(glm::dvec3(420.0, 420.0, 1.7), north, 0.0, grid, kAnyCell);
  EXPECT_EQ(u.removed.size(), before);
  EXPECT_TRUE(Covered(chain, glm::dvec3(420.0, 420.0, 1.7)));
  // Off the grid or out of the band: nothing.
  u = chain.Advance(glm::dvec3(420.0, 420.0, 3.0), north, 0.0, grid, kAnyCell);
  EXPECT_TRUE(chain.boxes().empty());
  EXPECT_TRUE(u.added.empty());
}

TEST(NeighbourhoodChain, BoxesStopAtCellsThatAreNotAllowedAndAtTheGridsEdge) {
  const ViewcellGrid grid = Grid();
  NeighbourhoodChain chain;
  const CellId here = grid.Id({0, 0});
  chain.Advance(glm::dvec3(90.0, 50.0, 1.7), glm::dvec3(16.7, 0.0, 0.0), 0.0, grid, [&](CellId c) { return c == here; });
  ASSERT_FALSE(chain.boxes().empty());
  for (const Neighbourhood& n : chain.boxes()) EXPECT_EQ(n.cell, here);
  chain.Clear();
  const double edge = grid.Bounds().max.x;
  chain.Advance(glm::dvec3(edge - 5.0, 50.0, 1.7), glm::dvec3(16.7, 0.0, 0.0), 0.0, grid, kAnyCell);
  ASSERT_FALSE(chain.boxes().empty());
  for (const Neighbourhood& n : chain.boxes()) EXPECT_LE(n.box.max.x, edge);
  EXPECT_GT(chain.boxes().back().box.max.x, edge - 1.0);
}

TEST(NeighbourhoodChain, ATurningWalkerIsPredictedAlongItsArc) {
  const ViewcellGrid grid = Grid();
  NeighbourhoodChain chain;
  // Turning left at 0.3 rad/s at 5 m/s: after 2 s the heading has turned 0.6 rad.
  const std::vector<glm::dvec3> path = chain.PredictPath(glm::dvec3(250.0, 250.0, 1.7), glm::dvec3(5.0, 0.0, 0.0), 0.3, grid);
  ASSERT_GT(path.size(), 30u);
  const glm::dvec3 d = path.back() - path[path.size() - 2];
  EXPECT_NEAR(std::atan2(d.y, d.x), 0.6, 0.02);
  EXPECT_GT(path.back().y, 260.0);
  // Straight on without a turn; a standing eye has no path beyond itself.
  const std::vector<glm::dvec3> straight = chain.PredictPath(glm::dvec3(250.0, 250.0, 1.7), glm::dvec3(5.0, 0.0, 0.0), 0.0, grid);
  EXPECT_NEAR(straight.back().y, 250.0, 1e-9);
  EXPECT_EQ(chain.PredictPath(glm::dvec3(250.0, 250.0, 1.7), glm::dvec3(0.1, 0.0, 0.0), 0.0, grid).size(), 1u);
}

}  // namespace
}  // namespace vistream::server
