#include "visibility/pvs.h"

#include <algorithm>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include "scenes/city_generator.h"
#include "scenes/mesh.h"
#include "scenes/progress.h"
#include "scenes/random.h"
#include "tests/terrain_test_util.h"
#include "tests/test_util.h"
#include "visibility/viewcell_grid.h"

namespace vistream::visibility {
namespace {

// The oracle (tests/test_util.h), free only with a clear margin.
bool SegmentFree(const glm::dvec3& p, const glm::dvec3& q, const scenes::Scene& scene) {
  return testing::SegmentClearOfPrisms(p, q, scene.occluders, 1e-4);
}

class Pvs : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scenes::LondonOptions o;
    o.width_m = o.depth_m = 900;
    o.seed = 11;
    scene_ = new scenes::Scene(scenes::GenerateLondon(o));
    tree_ = new KdTree(KdTree::Build(*scene_));
  }
  static void TearDownTestSuite() {
    delete tree_;
    delete scene_;
  }
  static scenes::Scene* scene_;
  static KdTree* tree_;
};
scenes::Scene* Pvs::scene_ = nullptr;
KdTree* Pvs::tree_ = nullptr;

TEST_F(Pvs, CulledObjectsAreNeverSeenFromTheCell) {
  const PvsComputer computer(*scene_, *tree_);
  const auto grid = ViewcellGrid::Create(scene_->bounds, 100.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  scenes::Rng rng(5);
  size_t culled_total = 0, seen_free = 0;
  for (int c = 0; c < 6; ++c) {
    const Aabb cell = grid->CellBox(CellCoord{1 + c, 2 + (c * 5) % 6});
    const PvsResult pvs = computer.Compute(cell, {});
    std::vector<bool> in(scene_->objects.size(), false);
    for (ObjectId id : pvs.objects) in[id] = true;
    for (const scenes::Object& o : scene_->objects) {
      if (in[o.id]) {
        // The oracle must be able to say "free", or the check below proves nothing.
        const glm::dvec3 eye = cell.Centre();
        const glm::dvec3 top(o.bounds.Centre().x, o.bounds.Centre().y, o.bounds.max.z + 0.5);
        seen_free += SegmentFree(eye, top, *scene_);
        continue;
      }
      ++culled_total;
      // Points just outside the object's surface, seen from points of the cell.
      for (int s = 0; s < 48; ++s) {
        // Half the targets on roofs, which are seen from farthest.
        size_t t = rng.Below(o.mesh.TriangleCount());
        for (int tries = 0; tries < 8 && s % 2 == 0 && o.mesh.normals[o.mesh.indices[3 * t]].z < 0.5f; ++tries) {
          t = rng.Below(o.mesh.TriangleCount());
        }
        const glm::dvec3 v0(o.mesh.positions[o.mesh.indices[3 * t]]), v1(o.mesh.positions[o.mesh.indices[3 * t + 1]]),
            v2(o.mesh.positions[o.mesh.indices[3 * t + 2]]);
        double r1 = rng.Uniform(), r2 = rng.Uniform();
        if (r1 + r2 > 1) r1 = 1 - r1, r2 = 1 - r2;
        const glm::dvec3 on = v0 + r1 * (v1 - v0) + r2 * (v2 - v0);
        const glm::dvec3 target = on + 0.01 * glm::dvec3(o.mesh.normals[o.mesh.indices[3 * t]]);
        if (target.z <= 0.0) continue;  // a floor: seen from underground only
        // Eyes on the cell's upper rim see the most (the paper's Observation 1).
        glm::dvec3 eye(rng.Uniform(cell.min.x, cell.max.x), rng.Uniform(cell.min.y, cell.max.y), cell.max.z);
        const int side = static_cast<int>(rng.Below(4));
        if (side == 0) eye.x = cell.min.x;
        if (side == 1) eye.x = cell.max.x;
        if (side == 2) eye.y = cell.min.y;
        if (side == 3) eye.y = cell.max.y;
        ASSERT_FALSE(SegmentFree(eye, target, *scene_))
            << "object " << o.id << " culled from cell " << c << " but seen: eye (" << eye.x << ", " << eye.y << ", "
            << eye.z << ") target (" << target.x << ", " << target.y << ", " << target.z << ")";
      }
    }
  }
  EXPECT_GT(culled_total, scene_->objects.size() / 4) << "too little culled for the test to mean much";
  EXPECT_GT(seen_free, 20u) << "the oracle never finds a free segment";
}

TEST_F(Pvs, BatchEqualsOneByOneWhateverTheThreads) {
  const PvsComputer computer(*scene_, *tree_);
  const auto grid = ViewcellGrid::Create(scene_->bounds, 100.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  std::vector<Aabb> cells;
  for (int k = 0; k < 5; ++k) cells.push_back(grid->CellBox(CellCoord{1 + k, 4}));
  const auto one = computer.ComputeBatch(cells, {}, 1);
  const auto two = computer.ComputeBatch(cells, {}, 2);
  ASSERT_EQ(one.size(), cells.size());
  for (size_t k = 0; k < cells.size(); ++k) {
    EXPECT_EQ(one[k].objects, two[k].objects) << "cell " << k;
    EXPECT_EQ(one[k].objects, computer.Compute(cells[k], {}).objects) << "cell " << k;
    EXPECT_TRUE(std::is_sorted(one[k].objects.begin(), one[k].objects.end()));
  }
}

// The five cells a client crossing from `to` - (1, 1) into `to` comes to border (an L around
// to's far corner), as the batch benchmark takes them.
std::vector<Aabb> DiagonalCrossing(const ViewcellGrid& grid, CellCoord to) {
  std::vector<Aabb> cells;
  for (CellId id : grid.NewlyAdjacent(grid.Id(CellCoord{to.i - 1, to.j - 1}), grid.Id(to))) {
    cells.push_back(grid.CellBox(id));
  }
  return cells;
}

// The batch call shares work but no answer: each cell gets exactly what Compute gives it,
// whatever the thread count. With the union box's culling on, a set may only lose objects,
// and never one that the exact test sees.
void ExpectAdjacentMatchesSingleCalls(const PvsComputer& computer, std::span<const Aabb> cells) {
  const auto one = computer.ComputeAdjacent(cells, {}, 1);
  const auto two = computer.ComputeAdjacent(cells, {}, 2);
  const auto culled = computer.ComputeAdjacent(cells, {}, 2, /*union_cull=*/true);
  ASSERT_EQ(one.size(), cells.size());
  ASSERT_EQ(culled.size(), cells.size());
  for (size_t k = 0; k < cells.size(); ++k) {
    const PvsResult single = computer.Compute(cells[k], {});
    EXPECT_EQ(one[k].objects, single.objects) << "cell " << k;
    EXPECT_EQ(two[k].objects, single.objects) << "cell " << k;
    EXPECT_EQ(one[k].triangles, single.triangles) << "cell " << k;
    EXPECT_GT(single.objects.size(), 0u);
    EXPECT_LT(single.objects.size(), computer.occluders().pieces().size()) << "nothing culled: a weak check";
    const auto& c = culled[k].objects;
    EXPECT_TRUE(std::includes(single.objects.begin(), single.objects.end(), c.begin(), c.end())) << "cell " << k;
    const PvsResult exact = computer.Compute(cells[k], CellQueryOptions{.exact = true});
    EXPECT_TRUE(std::includes(c.begin(), c.end(), exact.objects.begin(), exact.objects.end())) << "cell " << k;
  }
}

TEST_F(Pvs, AdjacentCellsGetExactlyWhatSingleCallsGive) {
  const PvsComputer computer(*scene_, *tree_);
  const auto grid = ViewcellGrid::Create(scene_->bounds, 100.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  for (const CellCoord to : {CellCoord{3, 3}, CellCoord{5, 2}}) {
    const std::vector<Aabb> cells = DiagonalCrossing(*grid, to);
    ASSERT_EQ(cells.size(), 5u);
    ExpectAdjacentMatchesSingleCalls(computer, cells);
  }
}

TEST(PvsBatch, CityOneAdjacentCellsGetExactlyWhatSingleCallsGive) {
  const scenes::Scene scene = scenes::GenerateTestCity(/*dense=*/true, 1);
  const KdTree tree = KdTree::Build(scene);
  const PvsComputer computer(scene, tree);
  const auto grid = ViewcellGrid::Create(scene.bounds, 50.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  const std::vector<Aabb> cells = DiagonalCrossing(*grid, CellCoord{4, 6});
  ASSERT_EQ(cells.size(), 5u);
  ExpectAdjacentMatchesSingleCalls(computer, cells);
}

TEST_F(Pvs, FinerRasterNeverAddsObjects) {
  // A finer raster blocks at least what a coarser one does: PVS(128) is a subset of PVS(4),
  // and smaller somewhere.
  const PvsComputer computer(*scene_, *tree_);
  const auto grid = ViewcellGrid::Create(scene_->bounds, 100.0, 0.5, 2.0);
  size_t coarse_total = 0, fine_total = 0;
  for (const CellCoord c : {CellCoord{4, 4}, CellCoord{1, 6}, CellCoord{7, 2}}) {
    const Aabb cell = grid->CellBox(c);
    const auto coarse = computer.Compute(cell, CellQueryOptions{.min_res = 4, .max_res = 4}).objects;
    const auto fine = computer.Compute(cell, CellQueryOptions{.max_res = 128}).objects;
    EXPECT_TRUE(std::includes(coarse.begin(), coarse.end(), fine.begin(), fine.end()));
    coarse_total += coarse.size();
    fine_total += fine.size();
  }
  EXPECT_LT(fine_total, coarse_total);
}

// The widened property, over the hard case: terraced districts (party walls, closes whose end
// house touches both rows, sheds below eye level, turned blocks), on the 1/256 m grid and off
// it; viewcells from 2 to 300 m anywhere, against and inside buildings; kd leaves of 1 and 4
// objects; the cpu raster at random resolutions and the exact test. No culled object may be
// seen: a segment from the cell to a point just off its surface, clear of every prism.
// A point 1 cm off a random triangle of `o` (walls, roofs and floors alike), on its front.
glm::dvec3 PointOffSurface(const scenes::Object& o, scenes::Rng& rng) {
  const size_t t = rng.Below(o.mesh.TriangleCount());
  const glm::dvec3 v0(o.mesh.positions[o.mesh.indices[3 * t]]), v1(o.mesh.positions[o.mesh.indices[3 * t + 1]]),
      v2(o.mesh.positions[o.mesh.indices[3 * t + 2]]);
  double r1 = rng.Uniform(), r2 = rng.Uniform();
  if (r1 + r2 > 1) r1 = 1 - r1, r2 = 1 - r2;
  return v0 + r1 * (v1 - v0) + r2 * (v2 - v0) + 0.01 * glm::dvec3(o.mesh.normals[o.mesh.indices[3 * t]]);
}

TEST(PvsProperty, NothingCulledIsSeenWhateverTheCellSizeLeafSizeAndGrid) {
  size_t culled = 0, checked_cells = 0, seen_free = 0;
  static constexpr double kSizes[] = {2, 4, 8, 16, 50, 100, 300};
  for (uint64_t seed = 1; seed <= 16; ++seed) {
    scenes::StreetsOptions so;
    so.seed = seed;
    so.width_m = so.depth_m = 240;
    so.snap = seed % 2 == 1;
    const scenes::Scene scene = scenes::GenerateStreets(so);
    scenes::Rng rng(seed * 7919);
    for (uint32_t leaf : {1u, 4u}) {
      const KdTree tree = KdTree::Build(scene, KdTreeOptions{.leaf_size = leaf});
      const PvsComputer computer(scene, tree);
      for (int c = 0; c < 8; ++c) {
        const double size = kSizes[rng.Below(std::size(kSizes))];
        const glm::dvec2 at(rng.Uniform(scene.bounds.min.x, scene.bounds.max.x),
                            rng.Uniform(scene.bounds.min.y, scene.bounds.max.y));
        const Aabb cell{glm::dvec3(at - 0.5 * size, 0.5), glm::dvec3(at + 0.5 * size, 2.5)};
        const bool exact = rng.Chance(0.3);
        const CellQueryOptions options{.max_res = 16u << rng.Below(5), .exact = exact};
        const PvsResult pvs = computer.Compute(cell, options);
        ++checked_cells;
        std::vector<bool> in(scene.objects.size(), false);
        for (ObjectId id : pvs.objects) in[id] = true;
        for (const scenes::Object& o : scene.objects) {
          const glm::dvec3 eye = cell.Centre();
          if (in[o.id]) {
            seen_free += SegmentFree(eye, glm::dvec3(o.bounds.Centre().x, o.bounds.Centre().y, o.bounds.max.z + 0.5), scene);
            continue;
          }
          ++culled;
          for (int k = 0; k < 24; ++k) {
            // A point 1 cm off the surface, seen from the cell's upper rim half the time
            // (Observation 1), else from anywhere in it.
            const glm::dvec3 target = PointOffSurface(o, rng);
            if (target.z <= 0.0) continue;  // a floor
            glm::dvec3 from(rng.Uniform(cell.min.x, cell.max.x), rng.Uniform(cell.min.y, cell.max.y),
                            k % 2 == 0 ? cell.max.z : rng.Uniform(cell.min.z, cell.max.z));
            ASSERT_FALSE(SegmentFree(from, target, scene))
                << "seed " << seed << (so.snap ? "" : " (off the grid)") << ", leaf " << leaf << ", " << size
                << " m cell at (" << at.x << ", " << at.y << "), res " << options.max_res
                << (exact ? " exact" : " cpu") << ": " << o.name << " culled but seen along (" << from.x << ", "
                << from.y << ", " << from.z << ") - (" << target.x << ", " << target.y << ", " << target.z << ")";
          }
        }
      }
    }
  }
  EXPECT_EQ(checked_cells, 256u);
  EXPECT_GT(culled, 10000u) << "too little culled for the test to mean much";
  EXPECT_GT(seen_free, 200u) << "the oracle never finds a free segment";
}

// Viewcells whose floor lies on the ground or beneath it: the dual ray space treats the ground
// as solid (a footprint blocks the rays beneath its prism too), so such cells cull what the
// same cells raised above the ground cull, and nothing culled is seen from above the ground.
TEST(PvsProperty, CellsOnOrAcrossTheGroundCullOnlyWhatTheyCannotSee) {
  size_t culled = 0, culled_raised = 0, checked_cells = 0;
  for (uint64_t seed = 21; seed <= 26; ++seed) {
    scenes::StreetsOptions so;
    so.seed = seed;
    so.width_m = so.depth_m = 200;
    const scenes::Scene scene = scenes::GenerateStreets(so);
    scenes::Rng rng(seed * 104729);
    const KdTree tree = KdTree::Build(scene);
    const PvsComputer computer(scene, tree);
    for (int c = 0; c < 8; ++c) {
      const double size = c % 2 == 0 ? 4.0 : 16.0;
      const glm::dvec2 at(rng.Uniform(scene.bounds.min.x, scene.bounds.max.x),
                          rng.Uniform(scene.bounds.min.y, scene.bounds.max.y));
      const double floor = c % 4 < 2 ? 0.0 : -1.0;
      const Aabb cell{glm::dvec3(at - 0.5 * size, floor), glm::dvec3(at + 0.5 * size, 2.5)};
      const Aabb raised{glm::dvec3(at - 0.5 * size, 0.01), glm::dvec3(at + 0.5 * size, 2.5)};
      const PvsResult pvs = computer.Compute(cell, {});
      culled_raised += scene.objects.size() - computer.Compute(raised, {}).objects.size();
      ++checked_cells;
      std::vector<bool> in(scene.objects.size(), false);
      for (ObjectId id : pvs.objects) in[id] = true;
      for (const scenes::Object& o : scene.objects) {
        if (in[o.id]) continue;
        ++culled;
        for (int k = 0; k < 16; ++k) {
          const glm::dvec3 target = PointOffSurface(o, rng);
          if (target.z <= 0.0) continue;  // a floor
          // From the floor of the cell above the ground (the ground-level rays) half the time.
          const glm::dvec3 from(rng.Uniform(cell.min.x, cell.max.x), rng.Uniform(cell.min.y, cell.max.y),
                                k % 2 == 0 ? 0.0 : rng.Uniform(0.0, cell.max.z));
          ASSERT_FALSE(SegmentFree(from, target, scene))
              << "seed " << seed << ", " << size << " m cell at (" << at.x << ", " << at.y << ") from z " << floor
              << ": " << o.name << " culled but seen along (" << from.x << ", " << from.y << ", " << from.z << ") - ("
              << target.x << ", " << target.y << ", " << target.z << ")";
        }
      }
    }
  }
  EXPECT_EQ(checked_cells, 48u);
  EXPECT_GT(culled, 2000u) << "too little culled for the test to mean much";
  EXPECT_GE(culled, culled_raised) << "a cell on the ground culled less than the same cell 1 cm up";
}

// Terrain occludes: from a viewcell in one valley (its band following the ground) the ridge
// hides a shed in the other valley, through the terrain's own ground-up prisms alone.
TEST(PvsTerrain, ARidgeHidesTheOtherValley) {
  const scenes::Scene flat = testing::TwoSheds();
  scenes::Scene s = testing::OnTheRidge(flat);
  ASSERT_TRUE(scenes::ValidateScene(s, "ridge").ok());
  const ViewcellGrid grid = *ViewcellGrid::Create(s, {.size_m = 8, .height_m = 2.0, .base_m = 0.5});
  ASSERT_TRUE(grid.has_bands());
  const CellId cell = *grid.CellAt({-100, 4});
  const Aabb box = grid.CellBox(cell);
  EXPECT_GT(box.min.z, 1.0);  // the valley floor is above z = 0
  const KdTree tree = KdTree::Build(s, {.leaf_size = 1});  // each object its own leaf
  const PvsComputer computer(s, tree);
  const PvsResult r = computer.Compute(box, {});
  EXPECT_EQ(r.objects, (std::vector<ObjectId>{0, 2})) << "the west shed and the ground, not the east shed";
  // Without the terrain's occluders nothing hides the east shed: the ridge is what did.
  scenes::Scene bare = s;
  std::erase_if(bare.occluders, [](const scenes::Occluder25D& o) { return o.object == 2; });
  const KdTree bare_tree = KdTree::Build(bare, {.leaf_size = 1});
  const PvsComputer bare_computer(bare, bare_tree);
  EXPECT_EQ(bare_computer.Compute(box, {}).objects, (std::vector<ObjectId>{0, 1, 2}));
}

}  // namespace
}  // namespace vistream::visibility
