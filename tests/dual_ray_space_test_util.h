#pragma once
// Random dual-ray-space queries for the tests: a viewcell kCell at the origin, RandomGridScenes
// and random boxes B in them (tests/test_util.h), each with its query engine.

#include <cstdint>

#include "scenes/random.h"
#include "scenes/scene.h"
#include "tests/test_util.h"
#include "visibility/dual_ray_space.h"
#include "visibility/occluder_set.h"

namespace vistream::visibility::test_queries {

// The viewcell the random queries look from (scene-local metres).
inline const scenes::Aabb kCell = vistream::testing::Box(0, 0, 0.5, 10, 10, 2.5);

// One random query from kCell: a RandomGridScene, its query engine, and a box B in it.
struct RandomQuery {
  uint64_t seed;
  int q;            // the query's number within its seed
  scenes::Rng& rng;  // the seed's generator, for the test's own draws
  const scenes::Scene& s;
  DualRaySpace& drs;
  scenes::Aabb b;
};

// Calls f(query) for `per_seed` random boxes B in each RandomGridScene, seeds [first, last].
template <typename F>
void ForEachRandomQuery(uint64_t first, uint64_t last, int per_seed, F&& f) {
  for (uint64_t seed = first; seed <= last; ++seed) {
    scenes::Rng rng(seed);
    const scenes::Scene s = testing::RandomGridScene(rng);
    const OccluderSet set = OccluderSet::Build(s);
    DualRaySpace drs(set);
    for (int q = 0; q < per_seed; ++q) f(RandomQuery{seed, q, rng, s, drs, testing::RandomGridBox(rng)});
  }
}

// Calls f(query, problem, blockers) for each planar problem of those queries, its blockers
// built.
template <typename F>
void ForEachRandomPlanarProblem(uint64_t first, uint64_t last, int per_seed, F&& f) {
  ForEachRandomQuery(first, last, per_seed, [&](const RandomQuery& r) {
    for (int axis = 0; axis < 2; ++axis) {
      for (double sign : {1.0, -1.0}) {
        PlanarProblem pr;
        if (!MakePlanarProblem(kCell, r.b, axis, sign, &pr)) continue;
        r.drs.BuildBlockers(pr);
        f(r, pr, r.drs.blockers());
      }
    }
  });
}

}  // namespace vistream::visibility::test_queries
