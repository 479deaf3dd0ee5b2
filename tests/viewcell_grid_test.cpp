#include "visibility/viewcell_grid.h"

#include <algorithm>

#include <gtest/gtest.h>

#include "scenes/city_generator.h"
#include "tests/terrain_test_util.h"

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

// --- Cells that follow terrain ---

const scenes::ViewcellSpec kSpec{.size_m = 30, .height_m = 2.0, .base_m = 0.5};

// z = 2 + x / 4 + y / 8 over [0, 100]^2 in 20 m quads.
double Slope(double x, double y) { return 2.0 + 0.25 * x + 0.125 * y; }

TEST(ViewcellGrid, ASceneWithoutTerrainGetsTodaysGrid) {
  const scenes::Scene city = scenes::GenerateTestCity(true, 1);
  ASSERT_TRUE(city.terrain.empty());
  const ViewcellGrid a = *ViewcellGrid::Create(city, kSpec), b = *ViewcellGrid::Create(city.bounds, kSpec);
  EXPECT_FALSE(a.has_bands());
  EXPECT_EQ(a.nx(), b.nx());
  EXPECT_EQ(a.ny(), b.ny());
  EXPECT_EQ(a.corner(), b.corner());
  EXPECT_EQ(a.Bounds(), b.Bounds());
  for (CellId id = 0; id < a.CellCount(); ++id) {
    ASSERT_EQ(a.CellBox(id), b.CellBox(id));
    ASSERT_EQ(a.Band(id), (CellBand{0.5, 2.5}));
  }
}

TEST(ViewcellGrid, BandsSpanTheGroundOfASlopeAndZeroOffIt) {
  const scenes::Scene s = testing::TerrainScene(Slope, {0, 0}, {100, 100}, 5, 5);
  const absl::StatusOr<ViewcellGrid> g = ViewcellGrid::Create(s, kSpec);
  ASSERT_TRUE(g.ok()) << g.status();
  ASSERT_TRUE(g->has_bands());
  EXPECT_EQ(g->nx(), 4);  // x from 0 to 120: the last column reaches past the terrain
  EXPECT_EQ(g->bands().size(), g->CellCount());
  // Cell (1, 1), [30, 60]^2: corners inside triangles hold the extremes.
  const CellBand b11 = g->Band(g->Id({1, 1}));
  EXPECT_NEAR(b11.z0, Slope(30, 30) + 0.5, 1e-9);
  EXPECT_NEAR(b11.z1, Slope(60, 60) + 2.5, 1e-9);
  const scenes::Aabb box = g->CellBox(CellCoord{1, 1});
  EXPECT_EQ(box.min, glm::dvec3(30, 30, b11.z0));
  EXPECT_EQ(box.max, glm::dvec3(60, 60, b11.z1));
  // Cell (3, 0), [90, 120] x [0, 30]: partly off the terrain, where the ground is 0.
  const CellBand b30 = g->Band(g->Id({3, 0}));
  EXPECT_EQ(b30.z0, 0.5);
  EXPECT_NEAR(b30.z1, Slope(100, 30) + 2.5, 1e-9);
  // The bounds: every band's union.
  EXPECT_EQ(g->Bounds().min.z, 0.5);
  EXPECT_NEAR(g->Bounds().max.z, Slope(100, 100) + 2.5, 1e-9);
  // The spec's band stays what it was: the band above the ground.
  EXPECT_EQ(g->base_z(), 0.5);
  EXPECT_EQ(g->height(), 2.0);
}

TEST(ViewcellGrid, BandsOfABumpyTinHoldItsPeaksAndEdgeCrossings) {
  // A peak of 8 m at (10, 10) in a 2 m plain, 10 m quads; cells of 6 m from 0.
  auto peak = [](double x, double y) { return x == 10.0 && y == 10.0 ? 8.0 : 2.0; };
  const scenes::Scene s = testing::TerrainScene(peak, {0, 0}, {20, 20}, 2, 2);
  const ViewcellGrid g = *ViewcellGrid::Create(s, {.size_m = 6, .height_m = 2.0, .base_m = 0.5});
  // Cell (1, 1), [6, 12]^2, holds the peak vertex.
  EXPECT_EQ(g.Band(g.Id({1, 1})).z1, 8.0 + 2.5);
  // Cell (0, 1), [0, 6] x [6, 12]: the edge (0, 10)-(10, 10) crosses x = 6 at 2 + 0.6 * 6.
  EXPECT_NEAR(g.Band(g.Id({0, 1})).z1, 5.6 + 2.5, 1e-9);
  EXPECT_EQ(g.Band(g.Id({0, 1})).z0, 2.5);
  // Cell (3, 3), [18, 24]^2: partly past the terrain's edge at 20, where the ground is 0; its
  // highest ground at (18, 18) on the peak's diagonal, 2 + 0.2 * 6.
  EXPECT_EQ(g.Band(g.Id({3, 3})).z0, 0.5);
  EXPECT_NEAR(g.Band(g.Id({3, 3})).z1, 3.2 + 2.5, 1e-9);
}

TEST(ViewcellGrid, WithBandsRefusesTheWrongCountAndEmptyBands) {
  const ViewcellGrid flat = Grid();
  EXPECT_FALSE(ViewcellGrid::WithBands(flat, {}).ok());
  std::vector<CellBand> bands(flat.CellCount(), CellBand{1.0, 3.0});
  EXPECT_TRUE(ViewcellGrid::WithBands(flat, bands).ok());
  bands[3] = {3.0, 3.0};
  EXPECT_FALSE(ViewcellGrid::WithBands(flat, bands).ok());
  bands[3] = {NAN, 3.0};
  EXPECT_FALSE(ViewcellGrid::WithBands(flat, bands).ok());
}

}  // namespace
}  // namespace vistream::visibility
