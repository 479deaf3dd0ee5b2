#include "gl/gl_planar_raster.h"

#include <gtest/gtest.h>

#include "scenes/city_generator.h"
#include "scenes/progress.h"
#include "tests/test_util.h"
#include "visibility/dual_ray_space.h"
#include "visibility/kdtree.h"
#include "visibility/pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream::gl {
namespace {

using scenes::Aabb;
using visibility::Blockers;
using visibility::DualRaySpace;
using visibility::OccluderSet;
using visibility::PlanarProblem;

class GlRaster : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    absl::StatusOr<std::unique_ptr<GlPlanarRaster>> r = GlPlanarRaster::Create();
    ASSERT_TRUE(r.ok()) << r.status();
    raster_ = r->release();
  }
  static void TearDownTestSuite() { delete raster_; }

  // Draws `blockers` with both backends at every resolution and counts what differs.
  void Compare(const Blockers& blockers, const std::string& what) {
    for (uint32_t n = 16; n <= 256; n *= 2) {
      cpu_.Draw(blockers, n, &cpu_pixels_);
      raster_->Draw(blockers, n, &gl_pixels_);
      ASSERT_EQ(cpu_pixels_.size(), gl_pixels_.size());
      for (size_t k = 0; k < cpu_pixels_.size(); ++k) {
        set_ += cpu_pixels_[k];
        ++pixels_;
        EXPECT_EQ(cpu_pixels_[k], gl_pixels_[k]) << what << ", n " << n << ", pixel (" << k % n << ", " << k / n << ")";
        if (cpu_pixels_[k] != gl_pixels_[k] && ++differing_ > 20) {
          FAIL() << "too many differences";
        }
      }
      // Full() agrees too, on every row and on every other row, and names the same gaps.
      for (uint32_t first : {0u, 1u}) {
        std::vector<uint32_t> rows, cpu_gaps, gl_gaps;
        for (uint32_t j = first; j < n; j += 1 + first) rows.push_back(j);
        const bool cpu_full = cpu_.Full(blockers, n, rows, &cpu_gaps);
        ASSERT_EQ(cpu_full, raster_->Full(blockers, n, rows, &gl_gaps)) << what << ", n " << n;
        EXPECT_EQ(cpu_gaps, gl_gaps) << what << ", n " << n;
        EXPECT_EQ(cpu_full, cpu_gaps.empty()) << what << ", n " << n;
      }
    }
  }

  static GlPlanarRaster* raster_;
  visibility::CpuRaster cpu_;
  std::vector<uint8_t> cpu_pixels_, gl_pixels_;
  uint64_t set_ = 0, pixels_ = 0, differing_ = 0;
};
GlPlanarRaster* GlRaster::raster_ = nullptr;

scenes::Scene SmallLondon(double size_m, uint64_t seed) {
  scenes::LondonOptions o;
  o.width_m = o.depth_m = size_m;
  o.seed = seed;
  return scenes::GenerateLondon(o);
}

// The blockers of every separating direction between A and B.
template <typename F>
void ForEachPlanarProblem(DualRaySpace& drs, const Aabb& a, const Aabb& b, F&& f) {
  for (int axis = 0; axis < 2; ++axis) {
    for (double sign : {1.0, -1.0}) {
      PlanarProblem pr;
      if (!visibility::MakePlanarProblem(a, b, axis, sign, &pr)) continue;
      drs.BuildBlockers(pr);
      if (!drs.blockers().groups.empty()) f(drs.blockers());
    }
  }
}

TEST_F(GlRaster, AgreesWithTheCpuPixelForPixelOnRandomScenes) {
  const Aabb a{glm::dvec3(0, 0, 0.5), glm::dvec3(10, 10, 2.5)};
  for (uint64_t seed = 1; seed <= 40; ++seed) {
    scenes::Rng rng(seed);
    const scenes::Scene s = testing::RandomGridScene(rng);
    const OccluderSet set = OccluderSet::Build(s);
    DualRaySpace drs(set);
    for (int q = 0; q < 3; ++q) {
      const Aabb b = testing::RandomGridBox(rng);
      ForEachPlanarProblem(drs, a, b, [&](const Blockers& blockers) {
        Compare(blockers, "seed " + std::to_string(seed) + " query " + std::to_string(q));
      });
      if (HasFatalFailure()) return;
    }
  }
  EXPECT_EQ(differing_, 0u);
  // Meaningful only with plenty of both kinds of pixel.
  EXPECT_GT(set_, pixels_ / 5) << set_ << " of " << pixels_;
  EXPECT_LT(set_, pixels_ * 4 / 5) << set_ << " of " << pixels_;
}

TEST_F(GlRaster, AgreesWithTheCpuPixelForPixelInACity) {
  const scenes::Scene s = SmallLondon(700, 3);
  const visibility::KdTree tree = visibility::KdTree::Build(s);
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  const Aabb a{s.bounds.Centre() + glm::dvec3(-50, -50, 0), s.bounds.Centre() + glm::dvec3(50, 50, 0)};
  const Aabb cell{glm::dvec3(a.min.x, a.min.y, 0.5), glm::dvec3(a.max.x, a.max.y, 2.5)};
  // Kd nodes of every size: the root's children down to leaves.
  const auto& nodes = tree.nodes();
  for (size_t k = 1; k < nodes.size(); k += nodes.size() / 60 + 1) {
    ForEachPlanarProblem(drs, cell, nodes[k].bounds,
                         [&](const Blockers& blockers) { Compare(blockers, "node " + std::to_string(k)); });
    if (HasFatalFailure()) return;
  }
  EXPECT_EQ(differing_, 0u);
  EXPECT_GT(set_, pixels_ / 10) << set_ << " of " << pixels_;
  EXPECT_LT(set_, pixels_) << set_ << " of " << pixels_;
}

TEST_F(GlRaster, GivesTheSamePvsAsTheCpu) {
  const scenes::Scene s = SmallLondon(600, 9);
  const visibility::KdTree tree = visibility::KdTree::Build(s);
  const visibility::PvsComputer computer(s, tree);
  DualRaySpace gl_engine(computer.occluders(), raster_);
  const auto grid = visibility::ViewcellGrid::Create(s.bounds, 100.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  for (int c = 0; c < 3; ++c) {
    const Aabb cell = grid->CellBox(visibility::CellCoord{1 + c, 2 + c});
    const visibility::PvsResult cpu = computer.Compute(cell, {});
    const visibility::PvsResult gl = computer.Compute(cell, {}, &gl_engine);
    EXPECT_EQ(cpu.objects, gl.objects) << "cell " << c;
    EXPECT_EQ(cpu.stats.raster_rows, gl.stats.raster_rows) << "cell " << c;
    EXPECT_LT(cpu.objects.size(), s.objects.size()) << "nothing culled: the comparison proves little";
  }
}

}  // namespace
}  // namespace vistream::gl
