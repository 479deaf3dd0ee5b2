// Visibility proven by given lines, without blockers: DualRaySpace::ProvenVisibleAlong, which
// only the batch calls (PvsComputer::ComputeAdjacent) use, to try for one viewcell the free
// ray found for its neighbour; and DualRaySpace::FreeRayFromPool, the lines found before from
// the same viewcell.
#include "visibility/dual_ray_space.h"

namespace vistream::visibility {

namespace {

// The ray (u, v) of `pr` along `line`, if the line crosses both s1 and s2 (as the hint of
// DualRaySpace::PlanarOccluded is mapped).
bool RayAlongLine(const PlanarProblem& pr, const FreeLine& line, double* u, double* v) {
  const glm::dvec2 a = pr.PlanarFromScene(line.from), b = pr.PlanarFromScene(line.to);
  if (!(b.x != a.x) || !(pr.l1 > pr.r1) || !(pr.l2 > pr.r2)) return false;
  const double k = (b.y - a.y) / (b.x - a.x);
  *u = (a.y + k * (pr.x1 - a.x) - pr.r1) / (pr.l1 - pr.r1);
  *v = (a.y + k * (pr.x2 - a.x) - pr.r2) / (pr.l2 - pr.r2);
  return *u >= 0 && *u <= 1 && *v >= 0 && *v <= 1;
}

}  // namespace

bool DualRaySpace::ProvenVisibleAlong(const scenes::Aabb& a, const scenes::Aabb& b, const FreeLine& line,
                                      CellQueryStats* stats) {
  PlanarProblem pr[2];
  const int count = SeparatingPlanes(a, b, pr);
  // Visible answers true for boxes that no plane separates.
  if (count == 0) {
    if (stats != nullptr) ++stats->queries, ++stats->non_separable;
    return true;
  }
  if (!line.valid) return false;
  // A plane on which the ray is free cannot prove B hidden (its raster is conservative, and
  // the ray lies in a pixel that is then not wholly blocked). The other plane can, unless the
  // ray, extended, is a free segment from A to B: then nothing hides B from A.
  int free_planes = 0;
  bool proven = false;
  for (int k = 0; k < count && !proven; ++k) {
    double u = 0, v = 0;
    if (!RayAlongLine(pr[k], line, &u, &v) || !FreeRayTraced(pr[k], u, v)) continue;
    ++free_planes;
    if (stats != nullptr) ++stats->planar_tests, ++stats->free_rays;
    SetWitness(pr[k], u, v, nullptr);  // WitnessJoinsBoxes reads the ray from there
    proven = count == 1 || WitnessJoinsBoxes(a, b, pr[k]);
  }
  proven = proven || free_planes == count;
  if (proven && stats != nullptr) ++stats->queries;
  return proven;
}

bool DualRaySpace::FreeRayFromPool(const PlanarProblem& pr, const FreeLinePool& pool, const FreeLine& hint, double* u,
                                   double* v) {
  if (pool.size() == 0) return false;
  // The directions of the rays from s1 to s2 span the cone between these two.
  const glm::dvec2 d0 = pr.SceneFromPlanar(pr.x2, pr.r2) - pr.SceneFromPlanar(pr.x1, pr.l1);
  const glm::dvec2 d1 = pr.SceneFromPlanar(pr.x2, pr.l2) - pr.SceneFromPlanar(pr.x1, pr.r1);
  pool_lines_.clear();
  pool.Candidates(d0, d1, &pool_lines_);
  for (uint32_t i : pool_lines_) {
    const FreeLine& line = pool.line(i);
    // The hint was traced already.
    if (hint.valid && line.from == hint.from && line.to == hint.to) continue;
    if (RayAlongLine(pr, line, u, v) && FreeRayTraced(pr, *u, *v)) return true;
  }
  return false;
}

}  // namespace vistream::visibility
