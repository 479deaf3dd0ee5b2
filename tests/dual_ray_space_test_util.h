#pragma once
// Random dual-ray-space queries for the tests: a viewcell kCell at the origin, RandomGridScenes
// and random boxes B in them (tests/test_util.h), each with its query engine; and the
// brute-force oracles the dual-ray-space tests share.

#include <cstdint>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <glm/vec3.hpp>

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

// --- Oracles and helpers of the dual-ray-space tests. ---

// The oracle: 3D segments against the prisms, by brute force (tests/test_util.h).
inline bool SegmentFree(const glm::dvec3& p, const glm::dvec3& q, const std::vector<scenes::Occluder25D>& occluders) {
  return testing::SegmentClearOfPrisms(p, q, occluders, 1e-6);
}

inline glm::dvec3 RandomIn(const scenes::Aabb& box, scenes::Rng& rng) {
  return {rng.Uniform(box.min.x, box.max.x), rng.Uniform(box.min.y, box.max.y), rng.Uniform(box.min.z, box.max.z)};
}

// Samples segments from A to B (corners, edges and random points); returns a free one.
inline std::optional<std::pair<glm::dvec3, glm::dvec3>> FindFreeSegment(const scenes::Aabb& a, const scenes::Aabb& b, const scenes::Scene& s,
                                                                 uint64_t seed, int samples) {
  scenes::Rng rng(seed);
  auto corner = [](const scenes::Aabb& box, int k) {
    return glm::dvec3(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z);
  };
  for (int i = 0; i < 8; ++i) {
    for (int j = 0; j < 8; ++j) {
      if (SegmentFree(corner(a, i), corner(b, j), s.occluders)) return std::pair{corner(a, i), corner(b, j)};
    }
  }
  for (int k = 0; k < samples; ++k) {
    glm::dvec3 p = RandomIn(a, rng), q = RandomIn(b, rng);
    p.z = a.max.z;  // the upper rims see the most (Observation 1); sample there mostly
    if (k % 3 == 0) q.z = b.max.z;
    if (SegmentFree(p, q, s.occluders)) return std::pair{p, q};
  }
  return std::nullopt;
}

inline scenes::Scene Translated(scenes::Scene s, const glm::dvec2& t) {
  for (auto& oc : s.occluders) {
    for (auto& p : oc.footprint) p += t;
  }
  return s;
}

// The query and the scene, to 17 digits, for a failure message.
inline std::string Describe(const scenes::Scene& s, const scenes::Aabb& a, const scenes::Aabb& b) {
  std::ostringstream out;
  out.precision(17);
  out << "A = [" << a.min.x << ", " << a.min.y << ", " << a.min.z << "] - [" << a.max.x << ", " << a.max.y << ", "
      << a.max.z << "], B = [" << b.min.x << ", " << b.min.y << ", " << b.min.z << "] - [" << b.max.x << ", "
      << b.max.y << ", " << b.max.z << "], " << s.occluders.size() << " occluders:";
  for (const auto& oc : s.occluders) {
    out << " {h " << oc.height;
    for (const auto& p : oc.footprint) out << " (" << p.x << ", " << p.y << ")";
    out << "}";
  }
  return out.str();
}

}  // namespace vistream::visibility::test_queries
