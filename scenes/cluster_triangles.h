#pragma once
// Which object each triangle of a cluster level draws (issue 45; proto ClusterGeometry's
// object_triangles): a client draws a cluster as pieces, one per object it stands for, so that
// an ε-mask's word on an object applies to its piece and a frame's object-id buffer names an
// object at every pixel. A level that keeps its objects' triangles (the union of their full
// meshes, snapped) gives each object its own triangles; a simplified level gives each triangle
// to the object whose box is nearest its centroid (ties: the lower object id). Levels are stored
// with each object's triangles in one run, objects ascending (GroupClusterTriangles), so that a
// piece is a range.

#include <cstdint>
#include <vector>

#include "scenes/level_types.h"
#include "scenes/mesh.h"
#include "scenes/scene.h"

namespace vistream::scenes {

// For every triangle of `level` (one of `cluster`'s level meshes), the position in
// cluster.objects of the object it draws. Computed relative to the cluster's box corner.
std::vector<uint32_t> ClusterTriangleOwners(const Scene& scene, const Cluster& cluster, const Mesh& level);

// Reorders every cluster level's triangles stably by owner (positions untouched), so that each
// object's are one run, objects in ascending order. Levels already so are left as they are.
void GroupClusterTriangles(const Scene& scene, SceneLevels* levels);

// Per object of `cluster` (in cluster.objects' order), how many triangles of `level` it owns:
// with grouped triangles, object k's are those from the sum of the counts before it.
std::vector<uint32_t> ClusterObjectTriangles(const Scene& scene, const Cluster& cluster, const Mesh& level);

}  // namespace vistream::scenes
