#pragma once
// Which level of detail to draw of each object a region's PVS holds (issue 45; DESIGN.md
// "Levels of detail"): conservatively for every eye point of the region (a viewcell's eye band,
// or an ε-neighbourhood's box), the coarsest level whose geometric error projects to at most τ
// pixels of the client's viewport; a cluster (HLOD) where that holds for the whole cluster and it
// costs no more bytes and no more triangles than what it replaces. Levels never change what is
// visible, only what is drawn: every object of the PVS stays drawn, at some level or within a
// chosen cluster.

#include <cstdint>
#include <span>
#include <vector>

#include "scenes/aabb.h"
#include "scenes/geometry_codec.h"
#include "scenes/level_types.h"
#include "scenes/scene.h"

namespace vistream::scenes {

// The client's viewport (Hello).
struct ScreenSpec {
  uint32_t width_px = 1280;
  uint32_t height_px = 720;
  double vertical_fov_rad = 1.0471975511965976;  // 60 degrees

  // The most pixels a small length at distance 1 m, perpendicular to the view ray, spans
  // anywhere on this screen: the focal length in pixels, (height / 2) / tan(fov / 2), times
  // 1 + tan^2 of the screen corner's angle off the axis (a perspective projection stretches the
  // image towards the corners by that much). Pixels per metre at distance d is this over d.
  double MaxPixelsPerRadian() const;
};

// The most pixels a geometric error of `error_m` can shift the image of a surface whose
// original lies at least `distance_m` from the eye: error * MaxPixelsPerRadian / (distance -
// error); infinity when distance <= error.
double ErrorPixels(double error_m, double distance_m, const ScreenSpec& screen);

// What the choice reads, built once per scene: every level encoded for the wire (EncodeLevelMesh:
// the server sends these, the choice weighs their bytes), the full meshes' encoded sizes, and per
// object the clusters that stand for it, smallest first.
class LevelIndex {
 public:
  // `scene` and `levels` must outlive the index. levels.objects empty: every object full.
  // `full_bytes`: each object's full mesh's encoded bytes (EncodeMesh) where the caller has them
  // encoded already (one per object); empty: encoded here.
  LevelIndex(const Scene& scene, const SceneLevels& levels, std::vector<uint64_t> full_bytes = {});

  const Scene& scene() const { return *scene_; }
  const SceneLevels& levels() const { return *levels_; }
  // Encoded bytes of object `o` at `level` (0: the full mesh, EncodeMesh).
  uint64_t ObjectBytes(uint32_t o, uint32_t level) const {
    return level == 0 ? full_bytes_[o] : object_levels_[o][level - 1].EncodedBytes();
  }
  // Object `o`'s level `level` >= 1 encoded for the wire.
  const EncodedLevelMesh& ObjectLevel(uint32_t o, uint32_t level) const { return object_levels_[o][level - 1]; }
  // Encoded bytes of cluster `c` at `level` (1 .. levels.size()).
  uint64_t ClusterBytes(uint32_t c, uint32_t level) const { return cluster_levels_[c][level - 1].EncodedBytes(); }
  // Cluster `c`'s level `level` >= 1 encoded for the wire.
  const EncodedLevelMesh& ClusterLevel(uint32_t c, uint32_t level) const { return cluster_levels_[c][level - 1]; }
  // The clusters standing for `o`, fewest objects first.
  std::span<const uint32_t> ClustersOf(uint32_t o) const;
  // Whether cluster `c`'s `level` keeps its objects' full triangles in their order (objects
  // ascending, each one's triangles in its own order; positions only snapped): an ε-mask's
  // triangle bits for its objects then apply to it.
  bool ClusterKeepsTriangles(uint32_t c, uint32_t level) const { return cluster_keeps_[c][level - 1]; }
  // Per object of cluster `c` (its objects' order), its triangles in `level`, each object's in one
  // run (scenes/cluster_triangles.h; the levels must be grouped: GroupClusterTriangles).
  const std::vector<uint32_t>& ClusterObjectTriangles(uint32_t c, uint32_t level) const {
    return cluster_pieces_[c][level - 1];
  }

 private:
  const Scene* scene_;
  const SceneLevels* levels_;
  std::vector<uint64_t> full_bytes_;                           // [object]
  std::vector<std::vector<EncodedLevelMesh>> object_levels_;   // [object][level - 1]
  std::vector<std::vector<EncodedLevelMesh>> cluster_levels_;  // [cluster][level - 1]
  std::vector<std::vector<std::vector<uint32_t>>> cluster_pieces_;  // [cluster][level - 1][object]
  std::vector<std::vector<bool>> cluster_keeps_;                    // [cluster][level - 1]
  std::vector<uint32_t> cluster_offsets_;                      // CSR over objects
  std::vector<uint32_t> cluster_ids_;
};

// One thing to draw: an object at a level (0: its full mesh; k: levels.objects[id][k - 1]) or a
// cluster at a level (k >= 1: levels.clusters[id].levels[k - 1]).
struct DrawItem {
  enum class Kind : uint8_t { kObject, kCluster };
  Kind kind = Kind::kObject;
  uint32_t id = 0;
  uint32_t level = 0;
  friend bool operator==(const DrawItem&, const DrawItem&) = default;
  friend auto operator<=>(const DrawItem&, const DrawItem&) = default;
};

// The levels to draw for `pvs` (sorted object ids) seen from anywhere in `eye_region` (scene-local
// box: a viewcell's eye band or a neighbourhood) on `screen` at screen error `tau_px` (> 0):
// objects of the PVS not in a chosen cluster at the coarsest level with ErrorPixels(error,
// BoxDistance(eye_region, object bounds)) <= tau_px; a cluster at the coarsest such level (with
// its bounds) that passes these, where every object of the PVS it stands for is not already in another chosen
// cluster it does not contain, that level's bytes are at most those of what it replaces, and a
// masked frame may draw no more of its triangles than of what it replaces (a level keeping the
// full triangles draws at most those that may face the region; another is drawn whole).
// Clusters are considered fewest objects first. Sorted; every PVS object is drawn by exactly one item.
// With `clusters` false only objects' own levels are chosen.
std::vector<DrawItem> ChooseLevels(const LevelIndex& index, std::span<const uint32_t> pvs, const Aabb& eye_region,
                                   const ScreenSpec& screen, double tau_px, bool clusters = true);

}  // namespace vistream::scenes
