#pragma once
// Levels of detail of a scene (DESIGN.md "Levels of detail"; issue 45): for every object a chain
// of coarser meshes, and for groups of nearby objects merged cluster meshes (HLOD), each with its
// geometric error in metres. The types only: scenes/levels.h makes and checks them,
// scenes/level_choice.h picks among them for a viewcell. Part of Scene (Scene::levels), saved to
// and loaded from glTF (scenes/gltf_io.h, MSFT_lod); never part of SceneFingerprint: levels
// change what is drawn, never what is visible.

#include <cstdint>
#include <vector>

#include "scenes/aabb.h"
#include "scenes/mesh.h"

namespace vistream::scenes {

// One coarser stand-in for a mesh (an object's, or the union of a cluster's objects').
struct MeshLevel {
  Mesh mesh;  // scene-local metres, z up; at least one triangle
  // An upper bound, in metres, on the symmetric Hausdorff distance between this mesh and what
  // it stands for (every point of either surface lies within error_m of the other), measured by
  // scenes/levels.h MeasureLevelError, not the simplifier's estimate. Finite, > 0.
  double error_m = 0.0;
};

// A group of nearby objects drawn as one mesh far away (hierarchical levels of detail).
struct Cluster {
  std::vector<uint32_t> objects;  // the object ids it stands for: sorted, distinct, at least 2
  Aabb bounds;                    // of the objects' full meshes and of every level's mesh
  // Coarser and coarser: error_m strictly increasing, triangles never increasing; at least one.
  std::vector<MeshLevel> levels;
};

struct SceneLevels {
  // Indexed by object id; for each object its levels, finest first (error_m strictly increasing,
  // triangles never increasing; the full mesh, error 0, is the object's own and not listed).
  // Empty (size 0) when the scene has no levels; an object may have none.
  std::vector<std::vector<MeshLevel>> objects;
  // Clusters; one object may belong to several (a small tile and the large tile holding it).
  std::vector<Cluster> clusters;

  bool empty() const { return objects.empty() && clusters.empty(); }
};

}  // namespace vistream::scenes
