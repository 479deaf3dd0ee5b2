#include "visibility/agvs.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <fstream>
#include <set>

#include <absl/strings/str_cat.h>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include "scenes/building.h"
#include "scenes/mesh.h"
#include "scenes/progress.h"
#include "scenes/random.h"
#include "visibility/bytes.h"
#include "tests/temp_dir.h"
#include "visibility/pvs_file.h"

namespace vistream::visibility {
namespace {

using scenes::Aabb;
using scenes::ObjectId;

std::vector<glm::dvec2> Rect(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

scenes::Mesh BoxMesh(double x0, double y0, double x1, double y1, double h) {
  scenes::Mesh m;
  const std::vector<glm::dvec2> f = Rect(x0, y0, x1, y1);
  scenes::AppendConvexPrism(f, 0.0, h, &m);
  return m;
}

// The known-answer scene: box A (object 0) west of a high wall W (object 1) that spans the
// whole grid north to south, box B (object 2) east of it; everything shifted by `shift`. Cells
// of 10 m over x in [0, 40], y in [-50, 50], eyes 0.5 to 2.5 m up: the wall stands in column
// i = 2 (x 22 to 23), so columns 0 and 1 see exactly {A, W}, column 2 all three, column 3
// {W, B}. Coordinates are whole metres: exact in float even 5,000 km from the origin.
constexpr ObjectId kA = 0, kW = 1, kB = 2;
scenes::Scene WallScene(const glm::dvec2& shift = glm::dvec2(0.0), bool with_wall = true) {
  scenes::Scene s;
  s.name = "wall";
  auto add = [&](const char* name, double x0, double y0, double x1, double y1, double h) {
    scenes::AddBuilding(&s, name, {scenes::Prism{Rect(x0 + shift.x, y0 + shift.y, x1 + shift.x, y1 + shift.y), 0.0, h}});
  };
  add("A", 5, 0, 8, 3, 3);
  if (with_wall) {
    add("W", 22, -50, 23, 50, 30);
  } else {
    add("low", 22, -50, 23, -49, 1);  // keeps the ids and the grid: a post in the corner
  }
  add("B", 35, 0, 38, 3, 3);
  return s;
}

// The grid of WallScene(shift), whichever objects it holds.
ViewcellGrid Grid(const glm::dvec2& shift = glm::dvec2(0.0)) {
  const glm::dvec3 t(shift, 0.0);
  absl::StatusOr<ViewcellGrid> g =
      ViewcellGrid::Create(Aabb{glm::dvec3(5, -50, 0) + t, glm::dvec3(38, 49, 30) + t}, 10.0, 0.5, 2.0);
  EXPECT_TRUE(g.ok()) << g.status();
  return *g;
}

std::unique_ptr<GlobalSampler> Sampler(const scenes::Scene& s, const ViewcellGrid& g, AgvsOptions o = {}) {
  o.batch_samples = 8192;
  if (o.threads == 0) o.threads = 2;
  absl::StatusOr<std::unique_ptr<GlobalSampler>> r = GlobalSampler::Create(s, g, o);
  EXPECT_TRUE(r.ok()) << r.status();
  return std::move(*r);
}

std::set<ObjectId> Exact(const ViewcellGrid& g, CellId c) {
  const int i = g.Coord(c).i;
  if (i <= 1) return {kA, kW};
  if (i == 2) return {kA, kW, kB};
  return {kW, kB};
}

std::set<ObjectId> SetOf(const GlobalSampler& s, CellId c) {
  const std::vector<ObjectId> v = s.pvs().Objects(c);
  return {v.begin(), v.end()};
}

class Agvs : public ::testing::Test {
 protected:
};

// The quads Embree reads are the mesh's triangles exactly: each quad's two triangles, as
// Embree splits it (v0, v1, v3) and (v2, v3, v1), are the ones it names, corner for corner up
// to rotation; a prism's walls pair up.
TEST(PairTriangles, QuadsSplitBackIntoTheMeshTriangles) {
  scenes::Mesh m;
  scenes::AppendConvexPrism(std::vector<glm::dvec2>{{0, 0}, {4, 0}, {5, 3}, {2, 5}, {-1, 3}}, 0.0, 9.0, &m);
  m.indices.insert(m.indices.end(), {0, 1, 2});  // a lone triangle at the end
  const EmbreeQuads q = PairTriangles(m.indices);
  const size_t triangles = m.indices.size() / 3;
  ASSERT_EQ(q.indices.size(), 4 * q.first.size());
  ASSERT_EQ(q.pair.size(), q.first.size());
  auto same = [](std::array<uint32_t, 3> a, std::array<uint32_t, 3> b) {
    for (int r = 0; r < 3; ++r) {
      if (a == b) return true;
      std::rotate(a.begin(), a.begin() + 1, a.end());
    }
    return false;
  };
  auto tri = [&](size_t t) { return std::array<uint32_t, 3>{m.indices[3 * t], m.indices[3 * t + 1], m.indices[3 * t + 2]}; };
  size_t covered = 0, pairs = 0;
  for (size_t k = 0; k < q.first.size(); ++k) {
    const uint32_t* v = &q.indices[4 * k];
    EXPECT_TRUE(same({v[0], v[1], v[3]}, tri(q.first[k]))) << "quad " << k;
    if (q.pair[k]) {
      EXPECT_TRUE(same({v[2], v[3], v[1]}, tri(q.first[k] + 1))) << "quad " << k;
      ++pairs;
    } else {
      EXPECT_EQ(v[2], v[3]) << "quad " << k;  // a lone triangle: its second is empty
    }
    EXPECT_EQ(q.first[k], covered);
    covered += q.pair[k] ? 2 : 1;
  }
  EXPECT_EQ(covered, triangles);
  // The 5 walls pair up; the roof's and floor's fans take turns (roof, floor, roof, ...), so
  // their triangles stay single, as does the lone one.
  EXPECT_EQ(pairs, 5u);
}

TEST_F(Agvs, KnownAnswerSceneConvergesToTheExactSetsAndNeverPast) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  ASSERT_EQ(g.nx(), 4);
  ASSERT_EQ(g.ny(), 10);
  for (SamplingStrategy strategy : {SamplingStrategy::kAgvs, SamplingStrategy::kSgvs, SamplingStrategy::kRef}) {
    AgvsOptions o;
    o.strategy = strategy;
    auto sampler = Sampler(s, g, o);
    // Never past the exact sets, at every stage. REF sees one object per sample, SGVS only
    // from uniform points: they need more samples.
    const int rounds = strategy == SamplingStrategy::kAgvs ? 40 : strategy == SamplingStrategy::kSgvs ? 60 : 150;
    for (int round = 0; round < rounds; ++round) {
      sampler->RunBatch();
      for (CellId c = 0; c < g.CellCount(); ++c) {
        for (ObjectId obj : SetOf(*sampler, c)) {
          ASSERT_TRUE(Exact(g, c).count(obj)) << StrategyName(strategy) << ": cell " << c << " sees object " << obj;
        }
      }
    }
    for (CellId c = 0; c < g.CellCount(); ++c) {
      EXPECT_EQ(SetOf(*sampler, c), Exact(g, c)) << StrategyName(strategy) << ": cell " << c;
    }
    // The silhouette mutation casts a second sample behind a depth discontinuity.
    EXPECT_GE(sampler->stats().samples, rounds * 8192u);
    if (strategy != SamplingStrategy::kAgvs) {
      EXPECT_EQ(sampler->stats().samples, rounds * 8192u);
    }
    EXPECT_EQ(sampler->stats().entries, sampler->pvs().TotalEntries());
  }
}

// Silhouettes searched with discovery rays (as for objects of thousands of triangles) instead
// of exactly: the sets still converge to the exact ones and never pass them.
TEST_F(Agvs, DiscoveryRaySilhouettesConvergeToTheExactSetsToo) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  AgvsOptions o;
  o.discovery_triangles = 0;  // every object
  auto sampler = Sampler(s, g, o);
  for (int round = 0; round < 40; ++round) {
    sampler->RunBatch();
    for (CellId c = 0; c < g.CellCount(); ++c) {
      for (ObjectId obj : SetOf(*sampler, c)) ASSERT_TRUE(Exact(g, c).count(obj)) << "cell " << c << " sees object " << obj;
    }
  }
  for (CellId c = 0; c < g.CellCount(); ++c) EXPECT_EQ(SetOf(*sampler, c), Exact(g, c)) << "cell " << c;
  const DistributionStats& mutation = sampler->stats().distributions[static_cast<int>(Distribution::kSilhouetteMutation)];
  EXPECT_GT(mutation.samples, 0u);
}

TEST_F(Agvs, AdaptiveMixtureUsesEveryDistribution) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  auto sampler = Sampler(s, g);
  for (int round = 0; round < 10; ++round) sampler->RunBatch();
  const AgvsStats& st = sampler->stats();
  double total_probability = 0.0;
  for (Distribution d : {Distribution::kViewSpaceDirection, Distribution::kObjectDirection, Distribution::kTwoPoint,
                         Distribution::kTwoPointMutation, Distribution::kSilhouetteMutation}) {
    const DistributionStats& ds = st.distributions[static_cast<size_t>(d)];
    EXPECT_GT(ds.samples, 0u) << DistributionName(d);
    EXPECT_GE(ds.probability, 0.04) << DistributionName(d);  // the floor keeps each alive
    total_probability += ds.probability;
  }
  EXPECT_NEAR(total_probability, 1.0, 1e-9);
  EXPECT_EQ(st.distributions[static_cast<size_t>(Distribution::kRef)].samples, 0u);
  EXPECT_GT(st.mutation_candidates, 0u);
}

TEST_F(Agvs, PixelErrorTargetStopsSamplingWhenTheSetsAreComplete) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  AgvsOptions o;
  o.resolution = 1000;  // a 1 px error is a share of 1e-3: 40,000 camera rays tell it
  auto sampler = Sampler(s, g, o);
  sampler->RunBatch();
  const double first = sampler->stats().estimated_pixel_error;
  EXPECT_GT(first, 1.0);
  sampler->Run({.pixel_error = 1.0});
  const AgvsStats& st = sampler->stats();
  EXPECT_TRUE(st.estimate_settled);
  EXPECT_LE(st.estimated_pixel_error, 1.0);
  EXPECT_GE(st.estimate_rays, 39000u);
  EXPECT_LT(st.batches, 200u);
  for (CellId c = 0; c < g.CellCount(); ++c) EXPECT_EQ(SetOf(*sampler, c), Exact(g, c)) << "cell " << c;
}

TEST_F(Agvs, ResultsDependOnTheSeedOnlyNotOnTheThreads) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  AgvsOptions one, two;
  one.threads = 1;
  two.threads = 2;
  auto a = Sampler(s, g, one), b = Sampler(s, g, two);
  for (int round = 0; round < 3; ++round) {
    a->RunBatch();
    b->RunBatch();
  }
  EXPECT_EQ(a->pvs(), b->pvs());
  EXPECT_EQ(a->stats().rays, b->stats().rays);
  EXPECT_EQ(a->stats().mutation_candidates, b->stats().mutation_candidates);
  EXPECT_EQ(a->SaveState().size(), b->SaveState().size());
}

TEST_F(Agvs, TranslatingTheSceneFarAwayChangesNothing) {
  const scenes::Scene near_scene = WallScene(), far_scene = WallScene({500000, 5000000});
  const ViewcellGrid gn = Grid(), gf = Grid({500000, 5000000});
  auto a = Sampler(near_scene, gn), b = Sampler(far_scene, gf);
  for (int round = 0; round < 4; ++round) {
    a->RunBatch();
    b->RunBatch();
  }
  EXPECT_EQ(a->pvs(), b->pvs());
  EXPECT_EQ(a->stats().rays, b->stats().rays);
  EXPECT_EQ(a->stats().estimated_pixel_error, b->stats().estimated_pixel_error);
}

TEST_F(Agvs, ResumingFromASavedStateEqualsRunningOnce) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  auto straight = Sampler(s, g);
  for (int round = 0; round < 5; ++round) straight->RunBatch();
  auto first = Sampler(s, g);
  for (int round = 0; round < 2; ++round) first->RunBatch();
  const std::string state = first->SaveState();
  auto resumed = Sampler(s, g);
  ASSERT_TRUE(resumed->LoadState(state, "state.bin").ok());
  EXPECT_EQ(resumed->pvs(), first->pvs());
  for (int round = 0; round < 3; ++round) resumed->RunBatch();
  EXPECT_EQ(resumed->pvs(), straight->pvs());
  EXPECT_EQ(resumed->stats().samples, straight->stats().samples);
  EXPECT_EQ(resumed->stats().rays, straight->stats().rays);
  EXPECT_EQ(resumed->stats().mutation_candidates, straight->stats().mutation_candidates);
}

TEST_F(Agvs, BadStatesAreRejectedNamingTheSourceAndOffset) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  auto a = Sampler(s, g);
  a->RunBatch();
  const std::string state = a->SaveState();
  auto b = Sampler(s, g);
  // Every truncation fails, and leaves the sampler as it was.
  for (size_t n = 0; n < state.size(); n += std::max<size_t>(1, state.size() / 300)) {
    const absl::Status st = b->LoadState(std::string_view(state).substr(0, n), "cut.state");
    ASSERT_FALSE(st.ok()) << "a state cut to " << n << " bytes loaded";
    EXPECT_NE(st.message().find("cut.state"), std::string::npos) << st;
  }
  EXPECT_EQ(b->pvs().TotalEntries(), 0u);
  EXPECT_FALSE(b->LoadState(state + "x", "long.state").ok());
  std::string bad = state;
  bad[0] = 'X';
  EXPECT_NE(b->LoadState(bad, "bad.state").message().find("magic"), std::string::npos);
  // Another seed, another grid.
  AgvsOptions other_seed;
  other_seed.seed = 9;
  const absl::Status seed = Sampler(s, g, other_seed)->LoadState(state, "s");
  EXPECT_NE(seed.message().find("made with strategy agvs and seed 1; this run has strategy agvs and seed 9"),
            std::string::npos)
      << seed;
  AgvsOptions other_strategy;
  other_strategy.strategy = SamplingStrategy::kRef;
  const absl::Status strategy = Sampler(s, g, other_strategy)->LoadState(state, "s");
  EXPECT_NE(strategy.message().find("made with strategy agvs and seed 1; this run has strategy ref"), std::string::npos)
      << strategy;
  const ViewcellGrid g5 = *ViewcellGrid::Create(s.bounds, 5.0, 0.5, 2.0);
  const absl::Status other_grid = Sampler(s, g5)->LoadState(state, "s");
  EXPECT_NE(other_grid.message().find("cells"), std::string::npos) << other_grid;
  // The same cells moved: the corners differ, and the message shows both (not two equal halves).
  const ViewcellGrid shifted = Grid(glm::dvec2(g.cell_size(), 0.0));
  ASSERT_EQ(shifted.CellCount(), g.CellCount());
  ASSERT_NE(shifted.corner().x, g.corner().x);
  const absl::Status other_corner = Sampler(s, shifted)->LoadState(state, "s");
  EXPECT_NE(other_corner.message().find(absl::StrCat("from (", g.corner().x, ", ")), std::string::npos)
      << other_corner;
  EXPECT_NE(other_corner.message().find(absl::StrCat("from (", shifted.corner().x, ", ")), std::string::npos)
      << other_corner;
}

TEST_F(Agvs, InsertingAWallRemovesWhatItHidesAndSamplingRestoresTheRest) {
  const scenes::Scene open = WallScene({0, 0}, /*with_wall=*/false);
  const ViewcellGrid g = Grid();
  auto sampler = Sampler(open, g);
  for (int round = 0; round < 30; ++round) sampler->RunBatch();
  // Without the wall every cell sees A and B.
  for (CellId c = 0; c < g.CellCount(); ++c) {
    ASSERT_TRUE(sampler->pvs().Contains(c, kA)) << "cell " << c;
    ASSERT_TRUE(sampler->pvs().Contains(c, kB)) << "cell " << c;
  }
  absl::StatusOr<ObjectId> wall = sampler->InsertObject(BoxMesh(22, -50, 23, 50, 30));
  ASSERT_TRUE(wall.ok()) << wall.status();
  EXPECT_EQ(*wall, 3u);
  EXPECT_EQ(sampler->object_count(), 4u);
  // Right after the edit nothing the wall hides is left: B west of it, A east of it.
  for (CellId c = 0; c < g.CellCount(); ++c) {
    const int i = g.Coord(c).i;
    if (i <= 1) {
      EXPECT_FALSE(sampler->pvs().Contains(c, kB)) << "cell " << c;
    }
    if (i == 3) {
      EXPECT_FALSE(sampler->pvs().Contains(c, kA)) << "cell " << c;
    }
    if (i == 0) {
      EXPECT_TRUE(sampler->pvs().Contains(c, kA)) << "cell " << c << ": the wall cannot hide A here";
    }
  }
  EXPECT_EQ(sampler->stats().entries, sampler->pvs().TotalEntries());
  // Sampling restores what is still visible and nothing else.
  for (int round = 0; round < 30; ++round) sampler->RunBatch();
  for (CellId c = 0; c < g.CellCount(); ++c) {
    std::set<ObjectId> want = Exact(g, c);
    want.erase(kW);
    want.insert(*wall);
    std::set<ObjectId> got = SetOf(*sampler, c);
    got.erase(1);  // the post, inside the new wall now, was seen before it came
    EXPECT_EQ(got, want) << "cell " << c;
  }
}

TEST_F(Agvs, DeletingAndMovingAWallLetsSamplingFindWhatItHid) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  auto sampler = Sampler(s, g);
  for (int round = 0; round < 20; ++round) sampler->RunBatch();
  const CellId west = g.Id({0, 5}), east = g.Id({3, 5});
  ASSERT_FALSE(sampler->pvs().Contains(west, kB));
  // Move the wall out of the way (north, beyond the grid): B appears from the west.
  ASSERT_TRUE(sampler->MoveObject(kW, glm::dvec3(0, 200, 0)).ok());
  EXPECT_FALSE(sampler->pvs().Contains(west, kW)) << "the wall's old entries stay";
  for (int round = 0; round < 30; ++round) sampler->RunBatch();
  EXPECT_TRUE(sampler->pvs().Contains(west, kB));
  EXPECT_TRUE(sampler->pvs().Contains(east, kA));
  // Delete it: it leaves every set and never comes back.
  ASSERT_TRUE(sampler->DeleteObject(kW).ok());
  for (int round = 0; round < 5; ++round) sampler->RunBatch();
  for (CellId c = 0; c < g.CellCount(); ++c) EXPECT_FALSE(sampler->pvs().Contains(c, kW)) << "cell " << c;
  EXPECT_EQ(sampler->stats().entries, sampler->pvs().TotalEntries());
  // Edits name what is wrong.
  EXPECT_EQ(sampler->DeleteObject(kW).code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(sampler->MoveObject(99, glm::dvec3(1, 0, 0)).code(), absl::StatusCode::kNotFound);
  EXPECT_FALSE(sampler->MoveObject(kA, glm::dvec3(std::nan(""), 0, 0)).ok());
  EXPECT_FALSE(sampler->InsertObject(scenes::Mesh{}).ok());
  scenes::Mesh broken = BoxMesh(0, 0, 1, 1, 1);
  broken.indices[4] = 1000;
  EXPECT_FALSE(sampler->InsertObject(broken).ok());
}

TEST_F(Agvs, FiltersOnlyEverAdd) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  auto sampler = Sampler(s, g);
  sampler->RunBatch();
  EXPECT_EQ(sampler->FilteredAll({}), sampler->pvs());
  const GlobalPvs both = sampler->FilteredAll({.object_space = true, .view_space = true, .k = 4.0});
  size_t grown = 0;
  for (CellId c = 0; c < g.CellCount(); ++c) {
    const std::vector<ObjectId> base = sampler->pvs().Objects(c), f = both.Objects(c);
    EXPECT_TRUE(std::includes(f.begin(), f.end(), base.begin(), base.end())) << "cell " << c;
    grown += f.size() > base.size();
    EXPECT_EQ(sampler->Filtered(c, {.object_space = true, .view_space = true, .k = 4.0}), f);
  }
  EXPECT_GT(grown, 0u) << "the filters added nothing anywhere";
}

TEST_F(Agvs, SampleFromBoxHitsFrontFacesItCanSee) {
  const scenes::Scene s = WallScene();
  const ViewcellGrid g = Grid();
  auto sampler = Sampler(s, g);
  const Aabb box{glm::dvec3(10, 10, 1), glm::dvec3(11, 11, 2)};  // west of the wall
  const std::vector<BoxHit> hits = sampler->SampleFromBox(box, 2000, 3);
  ASSERT_GT(hits.size(), 200u);
  std::set<ObjectId> seen;
  for (const BoxHit& h : hits) {
    seen.insert(h.object);
    EXPECT_TRUE(box.Contains(h.from));
    ASSERT_LT(h.triangle, s.objects[h.object].mesh.TriangleCount());
    // The triangle faces the ray's origin.
    const scenes::Mesh& m = s.objects[h.object].mesh;
    const glm::dvec3 n(m.normals[m.indices[3 * h.triangle]]);
    EXPECT_LT(glm::dot(n, h.to - h.from), 0.0);
    // The hit point lies on that triangle (not just on its quad): barycentric coordinates.
    const glm::dvec3 a(m.positions[m.indices[3 * h.triangle]]), b(m.positions[m.indices[3 * h.triangle + 1]]),
        c(m.positions[m.indices[3 * h.triangle + 2]]);
    const glm::dvec3 e1 = b - a, e2 = c - a, w = h.to - a, nn = glm::cross(e1, e2);
    const double u = glm::dot(glm::cross(w, e2), nn) / glm::dot(nn, nn), v = glm::dot(glm::cross(e1, w), nn) / glm::dot(nn, nn);
    EXPECT_NEAR(glm::dot(w, glm::normalize(nn)), 0.0, 1e-3);
    EXPECT_GT(u, -1e-4);
    EXPECT_GT(v, -1e-4);
    EXPECT_LT(u + v, 1.0 + 1e-4);
  }
  EXPECT_EQ(seen, (std::set<ObjectId>{kA, kW}));
  EXPECT_EQ(sampler->SampleFromBox(box, 2000, 3).size(), hits.size());
}

TEST_F(Agvs, CreateRejectsEmptyScenes) {
  scenes::Scene empty;
  empty.bounds = Aabb{glm::dvec3(0), glm::dvec3(10)};
  const ViewcellGrid g = *ViewcellGrid::Create(empty.bounds, 5.0, 0.5, 2.0);
  EXPECT_FALSE(GlobalSampler::Create(empty, g, {}).ok());
  AgvsOptions zero;
  zero.batch_samples = 0;
  const scenes::Scene s = WallScene();
  EXPECT_FALSE(GlobalSampler::Create(s, Grid(), zero).ok());
}

TEST(AgvsNames, StrategiesRoundTrip) {
  for (SamplingStrategy st : {SamplingStrategy::kAgvs, SamplingStrategy::kSgvs, SamplingStrategy::kRef}) {
    EXPECT_EQ(*StrategyFromName(StrategyName(st)), st);
  }
  const absl::StatusOr<SamplingStrategy> bad = StrategyFromName("gvs");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("'gvs'"), std::string::npos);
}

// --- The penumbra test, against an exact integer oracle. ---

// hull(A ∪ B) meets C iff some t in [0, 1] makes (1 - t) A + t B meet C. With integer boxes,
// every endpoint of the feasible interval of t is k / q with q <= 2 * 8, and scaling by q
// keeps the test in integers.
bool ShaftOracle(const std::array<int, 6>& a, const std::array<int, 6>& b, const std::array<int, 6>& c) {
  for (int q = 1; q <= 16; ++q) {
    for (int k = 0; k <= q; ++k) {
      bool meets = true;
      for (int ax = 0; ax < 3 && meets; ++ax) {
        const int lo = (q - k) * a[ax] + k * b[ax], hi = (q - k) * a[ax + 3] + k * b[ax + 3];
        meets = lo <= q * c[ax + 3] && hi >= q * c[ax];
      }
      if (meets) return true;
    }
  }
  return false;
}

TEST(BoxMeetsShaft, AgreesWithAnExactOracle) {
  scenes::Rng rng(17);
  auto box = [&] {
    std::array<int, 6> b;
    for (int k = 0; k < 3; ++k) {
      const int x = static_cast<int>(rng.Below(9)), y = static_cast<int>(rng.Below(9));
      b[k] = std::min(x, y);
      b[k + 3] = std::max(x, y);
    }
    return b;
  };
  auto aabb = [](const std::array<int, 6>& b) {
    return Aabb{glm::dvec3(b[0], b[1], b[2]), glm::dvec3(b[3], b[4], b[5])};
  };
  int meets = 0, misses = 0;
  for (int n = 0; n < 20000; ++n) {
    const auto a = box(), b = box(), c = box();
    const bool want = ShaftOracle(a, b, c);
    ASSERT_EQ(BoxMeetsShaft(aabb(a), aabb(b), aabb(c)), want)
        << "A " << a[0] << "," << a[1] << "," << a[2] << ".." << a[3] << "," << a[4] << "," << a[5] << " B " << b[0]
        << "," << b[1] << "," << b[2] << ".." << b[3] << "," << b[4] << "," << b[5] << " C " << c[0] << "," << c[1]
        << "," << c[2] << ".." << c[3] << "," << c[4] << "," << c[5];
    (want ? meets : misses)++;
  }
  EXPECT_GT(meets, 2000);
  EXPECT_GT(misses, 2000);
}

// --- The PVS file ---

PvsFile SomeFile() {
  PvsFile f;
  f.scene = "city1";
  f.cell_size = 50;
  f.base_z = 0.5;
  f.height = 2;
  f.corner_x = -100;
  f.corner_y = 50;
  f.nx = 3;
  f.ny = 2;
  f.strategy = "agvs";
  f.samples = 123456789;
  f.seconds = 1.5;
  f.estimated_pixel_error = 0.25;
  f.sets = GlobalPvs(6, 300);
  f.sets.Assign(0, std::vector<ObjectId>{0, 1, 2, 299});
  f.sets.Assign(2, std::vector<ObjectId>{64, 128, 200});
  f.sets.Assign(5, std::vector<ObjectId>{7});
  return f;
}

TEST(PvsFile, RoundTrips) {
  const PvsFile f = SomeFile();
  const absl::StatusOr<PvsFile> g = DecodePvsFile(EncodePvsFile(f), "f.pvs");
  ASSERT_TRUE(g.ok()) << g.status();
  EXPECT_EQ(g->scene, f.scene);
  EXPECT_EQ(g->nx, 3);
  EXPECT_EQ(g->ny, 2);
  EXPECT_EQ(g->corner_x, -100);
  EXPECT_EQ(g->strategy, "agvs");
  EXPECT_EQ(g->samples, f.samples);
  EXPECT_EQ(g->estimated_pixel_error, 0.25);
  EXPECT_EQ(g->sets, f.sets);
  EXPECT_EQ(g->sets.Objects(0), (std::vector<ObjectId>{0, 1, 2, 299}));
  const ViewcellGrid grid = *ViewcellGrid::Create(Aabb{glm::dvec3(-100, 50, 0), glm::dvec3(49, 149, 5)}, 50, 0.5, 2);
  EXPECT_TRUE(g->Matches(grid));
  const ViewcellGrid other = *ViewcellGrid::Create(Aabb{glm::dvec3(-100, 50, 0), glm::dvec3(49, 149, 5)}, 25, 0.5, 2);
  EXPECT_FALSE(g->Matches(other));
}

// Cells that follow terrain: their bands are stored (version 3) and must match; a flat grid's
// file is version 2, byte for byte what writers before bands wrote.
TEST(PvsFile, BandsRoundTripAsVersion3AndFlatFilesStayVersion2) {
  const ViewcellGrid flat = *ViewcellGrid::Create(Aabb{glm::dvec3(-100, 50, 0), glm::dvec3(49, 149, 5)}, 50, 0.5, 2);
  std::vector<CellBand> bands;
  for (int k = 0; k < 6; ++k) bands.push_back({0.5 + k, 2.5 + 2 * k});
  const ViewcellGrid hilly = *ViewcellGrid::WithBands(flat, bands);
  scenes::Scene scene;
  scene.name = "t";
  scene.objects.resize(300);
  const PvsFile made = MakePvsFile(scene, hilly, SomeFile().sets, {"agvs", 10, 1.0, 0.0});
  EXPECT_EQ(made.bands, bands);
  const std::string bytes = EncodePvsFile(made);
  uint32_t version = 0;
  std::memcpy(&version, bytes.data() + 8, 4);
  EXPECT_EQ(version, 3u);
  const absl::StatusOr<PvsFile> g = DecodePvsFile(bytes, "hilly.pvs");
  ASSERT_TRUE(g.ok()) << g.status();
  EXPECT_EQ(g->bands, bands);
  EXPECT_EQ(g->sets, made.sets);
  EXPECT_TRUE(g->Matches(hilly));
  EXPECT_FALSE(g->Matches(flat));  // sets computed for other cells
  const absl::Status refused = CheckPvsFileMatches(*g, flat, scene, "hilly.pvs");
  EXPECT_EQ(refused.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("bands following terrain"), std::string::npos) << refused;
  std::vector<CellBand> other = bands;
  other[4].z1 += 0.25;
  EXPECT_FALSE(g->Matches(*ViewcellGrid::WithBands(flat, other)));
  // Truncated anywhere, or a band empty: a clear error.
  for (size_t n = 0; n < bytes.size(); ++n) {
    ASSERT_FALSE(DecodePvsFile(std::string_view(bytes).substr(0, n), "cut.pvs").ok()) << n;
  }
  std::string empty_band = bytes;
  const size_t band0 = 8 + 4 + 1 + 1 + 8 + 8 + 5 * 8 + 2 * 4;  // magic, version, "t", counts, grid
  const double high = 100.0;
  std::memcpy(empty_band.data() + band0, &high, 8);  // cell 0's z0 above its z1
  const absl::StatusOr<PvsFile> e = DecodePvsFile(empty_band, "band.pvs");
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.status().message().find("cell 0's band"), std::string::npos) << e.status();

  // A flat grid's file: version 2, and exactly the layout writers before bands wrote.
  const PvsFile plain = MakePvsFile(scene, flat, SomeFile().sets, {"agvs", 10, 1.0, 0.0});
  EXPECT_TRUE(plain.bands.empty());
  std::string v2;
  auto raw = [&v2](const auto& v) { v2.append(reinterpret_cast<const char*>(&v), sizeof(v)); };
  v2 += "VSPVS001";
  raw(uint32_t{2});
  v2 += '\x01';
  v2 += 't';
  raw(uint64_t{300});
  raw(plain.scene_fingerprint);
  for (double d : {50.0, 0.5, 2.0, -100.0, 50.0}) raw(d);
  raw(int32_t{3});
  raw(int32_t{2});
  v2 += '\x04';
  v2 += "agvs";
  raw(uint64_t{10});
  raw(1.0);
  raw(0.0);
  // Cells 0 to 5: {0, 1, 2, 299}, {}, {64, 128, 200}, {}, {}, {7} as counts and varint gaps.
  for (int b : {4, 0, 0, 0, 0xa8, 0x02, 0, 3, 0x40, 0x3f, 0x47, 0, 0, 1, 7}) v2 += static_cast<char>(b);
  EXPECT_EQ(EncodePvsFile(plain), v2);
  const absl::StatusOr<PvsFile> old = DecodePvsFile(v2, "old.pvs");
  ASSERT_TRUE(old.ok()) << old.status();
  EXPECT_TRUE(old->bands.empty());
  EXPECT_TRUE(old->Matches(flat));
  EXPECT_FALSE(old->Matches(hilly));  // a flat file is never served for cells that follow terrain
}

TEST(PvsFile, LoadsOnlyForItsOwnGridAndScene) {
  const ViewcellGrid grid = *ViewcellGrid::Create(Aabb{glm::dvec3(-100, 50, 0), glm::dvec3(49, 149, 5)}, 50, 0.5, 2);
  scenes::Scene scene;
  scene.name = "t";
  scene.objects.resize(300);
  const PvsFile made = MakePvsFile(scene, grid, SomeFile().sets, {"dual-ray-space cpu", 0, 2.5, 0.0});
  EXPECT_TRUE(made.Matches(grid));
  EXPECT_EQ(made.strategy, "dual-ray-space cpu");
  EXPECT_NE(made.scene_fingerprint, 0u);
  EXPECT_TRUE(CheckPvsFileMatches(made, grid, scene, "f.pvs").ok());
  scenes::Scene more = scene;
  more.objects.resize(301);
  const absl::Status objects = CheckPvsFileMatches(made, grid, more, "f.pvs");
  EXPECT_EQ(objects.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(objects.message().find("300 objects"), std::string::npos) << objects;
  const ViewcellGrid other = *ViewcellGrid::Create(Aabb{glm::dvec3(-100, 50, 0), glm::dvec3(49, 149, 5)}, 25, 0.5, 2);
  const absl::Status cells = CheckPvsFileMatches(made, other, scene, "f.pvs");
  EXPECT_EQ(cells.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(cells.message().find("f.pvs"), std::string::npos) << cells;
  EXPECT_NE(cells.message().find("6 x 4 cells of 25 m"), std::string::npos) << cells;

  const std::string path = vistream::testing::ProcessTempDir() + "/load.pvs";
  {
    std::ofstream out(path, std::ios::binary);
    out << EncodePvsFile(made);
  }
  const absl::StatusOr<PvsFile> loaded = LoadPvsFile(path, grid, scene);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->sets, made.sets);
  EXPECT_EQ(loaded->scene_fingerprint, made.scene_fingerprint);
  EXPECT_EQ(LoadPvsFile(path, other, scene).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadPvsFile(path + ".missing", grid, scene).status().code(), absl::StatusCode::kNotFound);
  const absl::Status dir = LoadPvsFile(vistream::testing::ProcessTempDir(), grid, scene).status();
  EXPECT_EQ(dir.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(dir.message().find("directory"), std::string::npos) << dir;

  // Same name, same object count, same grid, other geometry (another seed): refused.
  scenes::Scene moved = scene;
  moved.objects[7].mesh.positions.push_back(glm::vec3(1.0f, 2.0f, 3.0f));
  const absl::Status geometry = CheckPvsFileMatches(made, grid, moved, "f.pvs");
  EXPECT_EQ(geometry.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(geometry.message().find("other geometry"), std::string::npos) << geometry;
  // A version 1 file (no fingerprint) is still read, and checked by its counts alone.
  PvsFile old = made;
  old.scene_fingerprint = 0;
  EXPECT_TRUE(CheckPvsFileMatches(old, grid, moved, "old.pvs").ok());
}

TEST(PvsFile, EveryTruncationAndCorruptionIsAClearError) {
  const std::string bytes = EncodePvsFile(SomeFile());
  for (size_t n = 0; n < bytes.size(); ++n) {
    const absl::StatusOr<PvsFile> r = DecodePvsFile(std::string_view(bytes).substr(0, n), "cut.pvs");
    ASSERT_FALSE(r.ok()) << "cut to " << n << " bytes";
    EXPECT_NE(r.status().message().find("cut.pvs"), std::string::npos) << r.status();
  }
  EXPECT_FALSE(DecodePvsFile(bytes + '\0', "long.pvs").ok());
  std::string magic = bytes;
  magic[1] = 'X';
  EXPECT_FALSE(DecodePvsFile(magic, "magic.pvs").ok());
  // An id past the object count: the last byte is cell 5's only id (7); make it 127 + more.
  PvsFile big = SomeFile();
  big.sets = GlobalPvs(6, 8);
  big.sets.Assign(5, std::vector<ObjectId>{7});
  std::string past = EncodePvsFile(big);
  past.back() = 8;
  const absl::StatusOr<PvsFile> r = DecodePvsFile(past, "past.pvs");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("past the scene"), std::string::npos) << r.status();
  EXPECT_NE(r.status().message().find("byte "), std::string::npos) << r.status();
}

// A few dozen bytes may claim 2^32 objects: read for a scene, such a file is refused by its
// object count before its sets (cells x objects bits) are allocated.
TEST(PvsFile, AHeaderClaimingAnotherObjectCountIsRefusedBeforeAllocating) {
  PvsFile claims = SomeFile();
  const size_t cells = claims.sets.cell_count();
  claims.sets = GlobalPvs(cells, 8);
  std::string bytes = EncodePvsFile(claims);
  // The object count follows the magic (8), the version (4) and the name (varint length + bytes).
  const size_t at = 8 + 4 + 1 + claims.scene.size();
  const uint64_t huge = uint64_t{1} << 32;
  ASSERT_EQ(bytes.compare(at, 8, std::string("\x08\0\0\0\0\0\0\0", 8)), 0) << "the layout this test assumes";
  bytes.replace(at, 8, reinterpret_cast<const char*>(&huge), 8);
  const absl::StatusOr<PvsFile> r = DecodePvsFile(bytes, "claims.pvs", 8);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("4294967296 objects; this scene has 8"), std::string::npos) << r.status();
  EXPECT_TRUE(DecodePvsFile(EncodePvsFile(claims), "same.pvs", 8).ok());
}

}  // namespace
}  // namespace vistream::visibility
