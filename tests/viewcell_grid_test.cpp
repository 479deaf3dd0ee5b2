#include "visibility/viewcell_grid.h"

#include <algorithm>

#include <gtest/gtest.h>

namespace vistream::visibility {
namespace {

const scenes::Aabb kBounds{glm::dvec3(-130, -40, 0), glm::dvec3(270, 155, 80)};

ViewcellGrid Grid(double size = 50) {
  absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(kBounds, size, 0.5, 2.0);
  EXPECT_TRUE(g.ok()) << g.status();
  return *g;
}

TEST(ViewcellGrid, CellsTileTheGroundAtEyeLevel) {
  const ViewcellGrid g = Grid();
  // x from -150 to 300 (9 cells), y from -50 to 200 (5 cells): anchored at multiples of 50.
  EXPECT_EQ(g.nx(), 9);
  EXPECT_EQ(g.ny(), 5);
  const scenes::Aabb first = g.CellBox(CellCoord{0, 0});
  EXPECT_EQ(first.min, glm::dvec3(-150, -50, 0.5));
  EXPECT_EQ(first.max, glm::dvec3(-100, 0, 2.5));
  for (CellId id = 0; id < g.CellCount(); ++id) {
    const scenes::Aabb box = g.CellBox(id);
    EXPECT_EQ(g.CellAt(glm::dvec2(box.Centre())), id);
    EXPECT_EQ(g.CellAt(glm::dvec2(box.min)), id);  // lower-left corner belongs to the cell
    EXPECT_EQ(g.Id(g.Coord(id)), id);
  }
  EXPECT_FALSE(g.CellAt({-151, 0}).has_value());
  EXPECT_FALSE(g.CellAt({0, 200}).has_value());
  EXPECT_FALSE(g.CellAt({NAN, 0}).has_value());
}

TEST(ViewcellGrid, ACatalogBandMakesTheSameGrid) {
  const scenes::ViewcellSpec spec{.size_m = 50, .height_m = 2.0, .base_m = 0.5};
  absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(kBounds, spec);
  ASSERT_TRUE(g.ok()) << g.status();
  const ViewcellGrid h = Grid();
  EXPECT_EQ(g->nx(), h.nx());
  EXPECT_EQ(g->ny(), h.ny());
  EXPECT_EQ(g->corner(), h.corner());
  EXPECT_EQ(g->base_z(), 0.5);
  EXPECT_EQ(g->height(), 2.0);
  EXPECT_FALSE(ViewcellGrid::Create(kBounds, scenes::ViewcellSpec{.size_m = -1}).ok());
}

TEST(ViewcellGrid, NeighboursAtCornersEdgesAndInside) {
  const ViewcellGrid g = Grid();
  EXPECT_EQ(g.Neighbours(g.Id({0, 0})).size(), 3u);
  EXPECT_EQ(g.Neighbours(g.Id({4, 0})).size(), 5u);
  const std::vector<CellId> inner = g.Neighbours(g.Id({4, 2}));
  ASSERT_EQ(inner.size(), 8u);
  EXPECT_TRUE(std::is_sorted(inner.begin(), inner.end()));
  for (CellId n : inner) {
    const CellCoord c = g.Coord(n);
    EXPECT_LE(std::abs(c.i - 4), 1);
    EXPECT_LE(std::abs(c.j - 2), 1);
  }
}

TEST(ViewcellGrid, CrossingAnEdgeNeedsThreeCellsACornerFive) {
  const ViewcellGrid g = Grid();
  const CellId from = g.Id({4, 2});
  EXPECT_EQ(g.NewlyAdjacent(from, g.Id({5, 2})).size(), 3u);
  const std::vector<CellId> corner = g.NewlyAdjacent(from, g.Id({5, 3}));
  EXPECT_EQ(corner.size(), 5u);
  for (CellId c : corner) {
    const std::vector<CellId> old = g.Neighbours(from);
    EXPECT_EQ(std::find(old.begin(), old.end(), c), old.end());
    EXPECT_NE(c, from);
  }
  EXPECT_TRUE(g.NewlyAdjacent(from, g.Id({7, 2})).empty());  // not adjacent
  EXPECT_TRUE(g.NewlyAdjacent(from, from).empty());
  // At the border fewer cells exist.
  EXPECT_EQ(g.NewlyAdjacent(g.Id({1, 0}), g.Id({0, 0})).size(), 0u);
  EXPECT_EQ(g.NewlyAdjacent(g.Id({1, 1}), g.Id({0, 0})).size(), 0u);
  EXPECT_EQ(g.NewlyAdjacent(g.Id({7, 2}), g.Id({8, 2})).size(), 0u);
  EXPECT_EQ(g.NewlyAdjacent(g.Id({6, 2}), g.Id({7, 2})).size(), 3u);
}

TEST(ViewcellGrid, TranslatingTheSceneByWholeCellsShiftsTheGridExactly) {
  scenes::Aabb far = kBounds;
  const glm::dvec3 t(500000, 5000000, 0);
  far.min += t;
  far.max += t;
  absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(far, 50, 0.5, 2.0);
  ASSERT_TRUE(g.ok());
  const ViewcellGrid near = Grid();
  ASSERT_EQ(g->nx(), near.nx());
  ASSERT_EQ(g->ny(), near.ny());
  for (CellId id = 0; id < near.CellCount(); ++id) {
    EXPECT_EQ(g->CellBox(id).min, near.CellBox(id).min + t);
  }
}

TEST(ViewcellGrid, SampleIsFixedDistinctAndInside) {
  const ViewcellGrid g = Grid();
  const std::vector<CellCoord> a = g.Sample(10, 7), b = g.Sample(10, 7), c = g.Sample(10, 8);
  ASSERT_EQ(a.size(), 10u);
  EXPECT_EQ(a, b);  // the same seed, the same cells
  EXPECT_NE(a, c);
  for (size_t k = 0; k < a.size(); ++k) {
    EXPECT_TRUE(g.Valid(a[k]));
    for (size_t m = 0; m < k; ++m) EXPECT_FALSE(a[k] == a[m]) << "cell drawn twice";
  }
  // Asking for more cells than the grid has gives each once.
  EXPECT_EQ(g.Sample(g.CellCount() + 5, 1).size(), g.CellCount());
}

TEST(ViewcellGrid, BadParametersAreErrors) {
  EXPECT_FALSE(ViewcellGrid::Create(kBounds, 0, 0.5, 2).ok());
  EXPECT_FALSE(ViewcellGrid::Create(kBounds, -5, 0.5, 2).ok());
  EXPECT_FALSE(ViewcellGrid::Create(kBounds, NAN, 0.5, 2).ok());
  EXPECT_FALSE(ViewcellGrid::Create(kBounds, 50, 0.5, 0).ok());
  EXPECT_FALSE(ViewcellGrid::Create(scenes::Aabb{}, 50, 0.5, 2).ok());
  absl::StatusOr<ViewcellGrid> huge = ViewcellGrid::Create(kBounds, 1e-4, 0.5, 2);
  ASSERT_FALSE(huge.ok());
  EXPECT_NE(huge.status().message().find("too large"), std::string::npos);
}

}  // namespace
}  // namespace vistream::visibility
