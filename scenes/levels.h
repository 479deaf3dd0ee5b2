#pragma once
// Making and checking levels of detail (issue 45; DESIGN.md "Levels of detail"). An object's
// levels come from meshoptimizer's simplifiers (meshopt_simplify, then meshopt_simplifySloppy
// where topology stops it) at a geometric sequence of target errors; a cluster merges the objects
// whose boxes' centres fall in one square tile and simplifies the union. Every kept level's
// error is measured against the full meshes (CGAL's bounded-error symmetric Hausdorff distance,
// plus its bound), so error_m bounds the true distance both ways.

#include <string>
#include <vector>

#include <absl/status/status.h>
#include <absl/status/statusor.h>

#include "scenes/level_types.h"
#include "scenes/progress.h"
#include "scenes/scene.h"

namespace vistream::scenes {

struct LevelOptions {
  // Target errors of an object's levels, metres, ascending and > 0. The first level is the full
  // mesh's own triangles with positions snapped to a power-of-two step within the target (sent
  // without normals: scenes/geometry_codec.h EncodeLevelMesh); each later level is simplified
  // and kept only when it has at most `max_triangle_share` of the triangles of the level before
  // it. A level's measured error may differ from its target.
  std::vector<double> object_errors_m{1.0 / 32.0, 0.25, 1.0, 4.0, 16.0};
  // Square tiles of clusters, edge in metres, ascending; each tile's objects (by box centre) form
  // one cluster of at least 2 objects, with levels at cluster_errors_m scaled by the tile's edge
  // over the first tile's edge.
  std::vector<double> cluster_tiles_m{250.0, 1000.0};
  std::vector<double> cluster_errors_m{1.0 / 32.0, 0.25, 0.5, 1.0, 2.0, 4.0};
  double max_triangle_share = 0.8;
  // Terrain objects (Scene::terrain) get object levels but join no cluster.
  unsigned threads = 0;  // 0: one per core
};

// The levels a server makes at start for a scene without its own (vistream-server --levels),
// which a client checking its frames (--verify) makes alike: object levels and clusters.
inline LevelOptions SessionLevelOptions() { return LevelOptions{}; }

// An upper bound, in metres, on the symmetric Hausdorff distance between the surface of `level`
// and the union of the surfaces of `originals` (scene-local metres; zero-area triangles carry no
// surface and are ignored): CGAL's bounded-error estimate computed to within `tolerance_m`, plus
// tolerance_m. Infinity when one side has no surface and the other has. Computed relative to the
// originals' box corner (translation-invariant).
double MeasureLevelError(const Mesh& level, const std::vector<const Mesh*>& originals, double tolerance_m);

// The levels of every object and the clusters of `scene` (LevelOptions). Progress: "levels:
// objects" then "levels: clusters"; CANCELLED when the run's flag is raised; INVALID_ARGUMENT for
// options out of range (naming the option).
absl::StatusOr<SceneLevels> MakeLevels(const Scene& scene, const LevelOptions& options, const RunControl& run = {});

// Checks levels read from `where` (a file) against `scene`: one list per object or none at all;
// every level's error finite and > 0 and larger than the previous level's, its triangles fewer
// than the previous level's (the full mesh's first), indices in range, positions finite, normals
// per position; every cluster of at least 2 sorted, distinct, existing objects with at least one
// level. INVALID_ARGUMENT naming `where`, the object (id and name) or cluster, and the level.
absl::Status ValidateLevels(const SceneLevels& levels, const Scene& scene, const std::string& where);

// Bytes the levels add to a scene held in memory (RawMeshBytes of every level's mesh).
uint64_t LevelBytes(const SceneLevels& levels);

}  // namespace vistream::scenes
