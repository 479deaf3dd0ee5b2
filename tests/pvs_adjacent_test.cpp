// The batch of adjacent viewcells (PvsComputer::ComputeAdjacent) and what it shares between
// them: a free ray found for one cell, tried for its neighbours (DualRaySpace::
// ProvenVisibleAlong), and the traversal, shared between threads from the root down.
#include <algorithm>

#include <gtest/gtest.h>

#include "scenes/city_generator.h"
#include "tests/test_util.h"
#include "visibility/dual_ray_space.h"
#include "visibility/pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream::visibility {
namespace {

using scenes::Aabb;
using scenes::Occluder25D;
using scenes::Scene;

using vistream::testing::Box;
using vistream::testing::Rect;

FreeLine Line(double x0, double y0, double x1, double y1) {
  return FreeLine{glm::dvec2(x0, y0), glm::dvec2(x1, y1), true};
}

const Aabb kCell = Box(0, 0, 0.5, 10, 10, 2.5);
const Aabb kBeyondWall = Box(50, 0, 0, 60, 10, 10);

// A wall across x = 20..25 with a gap at 4 < y < 6: B beyond it is seen through the gap only.
Scene WallWithGap() {
  Scene s;
  s.occluders.push_back(Rect(20, -200, 25, 4, 30));
  s.occluders.push_back(Rect(20, 6, 25, 200, 30));
  return s;
}

TEST(ProvenVisibleAlong, FreeLineThroughAGapProvesBVisible) {
  const Scene s = WallWithGap();
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  // Along y = 5 from A's face to B's face: through the gap, clear of both walls (the oracle).
  ASSERT_TRUE(testing::SegmentClearOfPrisms(glm::dvec3(10, 5, 2.5), glm::dvec3(50, 5, 2.5), s.occluders, 1e-6));
  EXPECT_TRUE(drs.ProvenVisibleAlong(kCell, kBeyondWall, Line(10, 5, 50, 5)));
  // The same line given the other way round, or reaching beyond the faces, is the same line.
  EXPECT_TRUE(drs.ProvenVisibleAlong(kCell, kBeyondWall, Line(55, 5, 5, 5)));
  EXPECT_TRUE(drs.Visible(kCell, kBeyondWall, CellQueryOptions{}));
}

TEST(ProvenVisibleAlong, LineIntoAWallOrBesideTheCellProvesNothing) {
  const Scene s = WallWithGap();
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  // Along y = 2: into the lower wall.
  EXPECT_FALSE(drs.ProvenVisibleAlong(kCell, kBeyondWall, Line(10, 2, 50, 2)));
  // Across the gap's x but from far beside A: it misses A's face.
  EXPECT_FALSE(drs.ProvenVisibleAlong(kCell, kBeyondWall, Line(10, -25, 22.5, 5)));
  // No line at all.
  EXPECT_FALSE(drs.ProvenVisibleAlong(kCell, kBeyondWall, FreeLine{}));
  // A line parallel to the faces crosses neither.
  EXPECT_FALSE(drs.ProvenVisibleAlong(kCell, kBeyondWall, Line(15, 0, 15, 10)));
}

TEST(ProvenVisibleAlong, BoxesNoPlaneSeparatesAreVisibleWithoutALine) {
  Scene s;
  s.occluders.push_back(Rect(-1000, -1000, 1000, 1000, 500));  // everything inside a building
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  EXPECT_TRUE(drs.ProvenVisibleAlong(kCell, Box(5, 5, 0, 20, 20, 10), FreeLine{}));  // B overlaps A
}

// B diagonal from A, behind a long wall along y = 12 that hides it: every segment from A to B
// crosses y = 12 between x = 0 and 40. The line from (10, 15) to (30, 35) runs free across the
// slab between A's face x = 10 and B's face x = 30 (it stays above the wall's line), but it
// starts beside A (A ends at y = 10): a free ray of one plane's shaft that joins no point of A
// to B proves nothing, and the other plane proves B hidden.
TEST(ProvenVisibleAlong, FreeRayOfOnePlaneThatMissesTheCellProvesNothing) {
  Scene s;
  s.occluders.push_back(Rect(-100, 12, 100, 13, 30));
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  const Aabb b = Box(30, 30, 0.5, 40, 40, 2.5);
  ASSERT_TRUE(testing::SegmentClearOfPrisms(glm::dvec3(10, 15, 2.5), glm::dvec3(30, 35, 2.5), s.occluders, 1e-6));
  ASSERT_FALSE(drs.Visible(kCell, b, CellQueryOptions{}));
  EXPECT_FALSE(drs.ProvenVisibleAlong(kCell, b, Line(10, 15, 30, 35)));
  // Without the wall, a line from A's middle to B's proves B visible.
  Scene open;
  open.occluders.push_back(Rect(-100, -50, -90, -40, 30));
  const OccluderSet open_set = OccluderSet::Build(open);
  DualRaySpace open_drs(open_set);
  EXPECT_TRUE(open_drs.ProvenVisibleAlong(kCell, b, Line(5, 5, 35, 35)));
}

// Decisions are taken in the query's frame: far from the origin (UTM-sized coordinates) the
// same lines prove the same things.
TEST(ProvenVisibleAlong, AnswersDoNotChangeWhenTheSceneIsTranslated) {
  const glm::dvec2 t(500000, 5000000);
  auto moved = [&](Scene s) {
    for (Occluder25D& o : s.occluders) {
      for (glm::dvec2& p : o.footprint) p += t;
    }
    return s;
  };
  auto box = [&](const Aabb& b) { return Aabb{b.min + glm::dvec3(t, 0), b.max + glm::dvec3(t, 0)}; };
  auto line = [&](double x0, double y0, double x1, double y1) { return Line(x0 + t.x, y0 + t.y, x1 + t.x, y1 + t.y); };
  const Scene gap = moved(WallWithGap());
  const OccluderSet gap_set = OccluderSet::Build(gap);
  DualRaySpace drs(gap_set);
  EXPECT_TRUE(drs.ProvenVisibleAlong(box(kCell), box(kBeyondWall), line(10, 5, 50, 5)));
  EXPECT_FALSE(drs.ProvenVisibleAlong(box(kCell), box(kBeyondWall), line(10, 2, 50, 2)));
  Scene wall;
  wall.occluders.push_back(Rect(-100, 12, 100, 13, 30));
  const OccluderSet wall_set = OccluderSet::Build(moved(wall));
  DualRaySpace wall_drs(wall_set);
  EXPECT_FALSE(wall_drs.ProvenVisibleAlong(box(kCell), box(Box(30, 30, 0.5, 40, 40, 2.5)), line(10, 15, 30, 35)));
}

// The batch gives each cell exactly what Compute gives it, on 1, 2 and 8 threads (8 on two
// cores: idle threads are handed nodes from the root down, so the sharing is exercised).
void ExpectBatchEqualsSingles(const PvsComputer& computer, std::span<const Aabb> cells) {
  std::vector<PvsResult> singles;
  for (const Aabb& cell : cells) singles.push_back(computer.Compute(cell, {}));
  for (unsigned threads : {1u, 2u, 8u}) {
    const std::vector<PvsResult> batch = computer.ComputeAdjacent(cells, {}, threads);
    ASSERT_EQ(batch.size(), cells.size());
    for (size_t k = 0; k < cells.size(); ++k) {
      EXPECT_EQ(batch[k].objects, singles[k].objects) << "cell " << k << ", " << threads << " threads";
      EXPECT_EQ(batch[k].triangles, singles[k].triangles) << "cell " << k << ", " << threads << " threads";
    }
  }
}

// A row of cells along a street grid: lines along the row pass through several cells, so a
// neighbour's free ray often serves; the sets are still each cell's own.
TEST(PvsAdjacent, RowOfCellsGetsExactlyWhatSingleCallsGive) {
  scenes::LondonOptions o;
  o.width_m = o.depth_m = 900;
  o.seed = 23;
  const Scene scene = scenes::GenerateLondon(o);
  const KdTree tree = KdTree::Build(scene);
  const PvsComputer computer(scene, tree);
  const auto grid = ViewcellGrid::Create(scene.bounds, 100.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  std::vector<Aabb> row;
  for (int i = 1; i <= 6; ++i) row.push_back(grid->CellBox(CellCoord{i, 4}));
  ExpectBatchEqualsSingles(computer, row);
  size_t seen = 0;
  for (const Aabb& cell : row) seen += computer.Compute(cell, {}).objects.size();
  EXPECT_GT(seen, 0u);
  EXPECT_LT(seen, row.size() * scene.objects.size()) << "nothing culled: a weak check";
}

// More than 32 cells go in groups of 32 (a cell mask is 32 bits); each still gets its own set.
TEST(PvsAdjacent, MoreThanThirtyTwoCellsGetExactlyWhatSingleCallsGive) {
  const Scene scene = scenes::GenerateTestCity(/*dense=*/true, 1);
  const KdTree tree = KdTree::Build(scene);
  const PvsComputer computer(scene, tree);
  const auto grid = ViewcellGrid::Create(scene.bounds, 50.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  std::vector<Aabb> cells;
  for (int j = 2; j < 8 && cells.size() < 36; ++j) {
    for (int i = 2; i < 8 && cells.size() < 36; ++i) {
      if (grid->Valid(CellCoord{i, j})) cells.push_back(grid->CellBox(CellCoord{i, j}));
    }
  }
  ASSERT_EQ(cells.size(), 36u);
  ExpectBatchEqualsSingles(computer, cells);
}

TEST(PvsAdjacent, NoCellsGiveNoResults) {
  const Scene scene = scenes::GenerateTestCity(/*dense=*/true, 1);
  const KdTree tree = KdTree::Build(scene);
  const PvsComputer computer(scene, tree);
  EXPECT_TRUE(computer.ComputeAdjacent({}, {}, 2).empty());
}

}  // namespace
}  // namespace vistream::visibility
