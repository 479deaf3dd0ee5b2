#include "scenes/level_choice.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include <glm/geometric.hpp>

#include "scenes/cluster_triangles.h"

namespace vistream::scenes {

double ScreenSpec::MaxPixelsPerRadian() const {
  const double t = std::tan(0.5 * vertical_fov_rad);
  const double focal_px = 0.5 * static_cast<double>(height_px) / t;
  const double aspect = height_px > 0 ? static_cast<double>(width_px) / static_cast<double>(height_px) : 1.0;
  const double corner_tan2 = t * t * (1.0 + aspect * aspect);
  return focal_px * (1.0 + corner_tan2);
}

double ErrorPixels(double error_m, double distance_m, const ScreenSpec& screen) {
  if (!(distance_m > error_m)) return std::numeric_limits<double>::infinity();
  return error_m * screen.MaxPixelsPerRadian() / (distance_m - error_m);
}

LevelIndex::LevelIndex(const Scene& scene, const SceneLevels& levels, std::vector<uint64_t> full_bytes)
    : scene_(&scene), levels_(&levels), full_bytes_(std::move(full_bytes)) {
  if (full_bytes_.size() != scene.objects.size()) {
    full_bytes_.clear();
    for (const Object& o : scene.objects) full_bytes_.push_back(EncodeMesh(o.mesh).EncodedBytes());
  }
  object_levels_.resize(scene.objects.size());
  for (size_t o = 0; o < levels.objects.size(); ++o) {
    for (const MeshLevel& l : levels.objects[o]) object_levels_[o].push_back(EncodeLevelMesh(l.mesh));
  }
  cluster_levels_.resize(levels.clusters.size());
  cluster_pieces_.resize(levels.clusters.size());
  cluster_keeps_.resize(levels.clusters.size());
  std::vector<uint32_t> count(scene.objects.size() + 1, 0);
  for (size_t c = 0; c < levels.clusters.size(); ++c) {
    size_t full = 0;
    for (uint32_t o : levels.clusters[c].objects) full += scene.objects[o].mesh.TriangleCount();
    for (const MeshLevel& l : levels.clusters[c].levels) {
      cluster_keeps_[c].push_back(l.mesh.TriangleCount() == full);
      cluster_levels_[c].push_back(EncodeLevelMesh(l.mesh));
      cluster_pieces_[c].push_back(scenes::ClusterObjectTriangles(scene, levels.clusters[c], l.mesh));
    }
    for (uint32_t o : levels.clusters[c].objects) ++count[o + 1];
  }
  cluster_offsets_.assign(scene.objects.size() + 1, 0);
  for (size_t o = 0; o < scene.objects.size(); ++o) cluster_offsets_[o + 1] = cluster_offsets_[o] + count[o + 1];
  cluster_ids_.resize(cluster_offsets_.back());
  std::vector<uint32_t> fill(cluster_offsets_.begin(), cluster_offsets_.end() - 1);
  std::vector<uint32_t> by_size(levels.clusters.size());
  for (uint32_t c = 0; c < by_size.size(); ++c) by_size[c] = c;
  std::stable_sort(by_size.begin(), by_size.end(), [&](uint32_t a, uint32_t b) {
    return levels.clusters[a].objects.size() < levels.clusters[b].objects.size();
  });
  for (uint32_t c : by_size) {
    for (uint32_t o : levels.clusters[c].objects) cluster_ids_[fill[o]++] = c;
  }
}

std::span<const uint32_t> LevelIndex::ClustersOf(uint32_t o) const {
  return {cluster_ids_.data() + cluster_offsets_[o], cluster_ids_.data() + cluster_offsets_[o + 1]};
}

namespace {

// The triangles of `mesh` whose front may face some point of `region` (a corner of the box in
// front of the triangle's plane; degenerate ones count as seen): an upper bound on what an
// ε-mask of a neighbourhood inside the region keeps of it. Relative to each triangle's first
// corner (translation-invariant).
uint64_t FrontFacingTriangles(const Mesh& mesh, const Aabb& region) {
  uint64_t n = 0;
  for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
    const glm::dvec3 a(mesh.positions[mesh.indices[t]]);
    const glm::dvec3 b(mesh.positions[mesh.indices[t + 1]]), c(mesh.positions[mesh.indices[t + 2]]);
    const glm::dvec3 normal = glm::cross(b - a, c - a);
    // The largest of dot(normal, corner - a) over the box's corners.
    double best = 0.0;
    for (int k = 0; k < 3; ++k) {
      best += std::max(normal[k] * (region.min[k] - a[k]), normal[k] * (region.max[k] - a[k]));
    }
    n += best > 0.0 || normal == glm::dvec3(0.0) ? 1 : 0;
  }
  return n;
}

}  // namespace

std::vector<DrawItem> ChooseLevels(const LevelIndex& index, std::span<const uint32_t> pvs, const Aabb& eye_region,
                                   const ScreenSpec& screen, double tau_px, bool clusters) {
  const Scene& scene = index.scene();
  const SceneLevels& levels = index.levels();
  // Each PVS object's own coarsest allowed level.
  std::unordered_map<uint32_t, uint32_t> own_level;
  own_level.reserve(pvs.size());
  for (const uint32_t o : pvs) {
    uint32_t level = 0;
    if (o < levels.objects.size()) {
      const double d = BoxDistance(eye_region, scene.objects[o].bounds);
      const auto& chain = levels.objects[o];
      for (size_t k = chain.size(); k > 0; --k) {
        if (ErrorPixels(chain[k - 1].error_m, d, screen) <= tau_px) {
          level = static_cast<uint32_t>(k);
          break;
        }
      }
    }
    own_level.emplace(o, level);
  }
  // Clusters, fewest objects first: chosen where allowed, self-contained and no dearer.
  std::vector<uint32_t> candidates;
  for (const uint32_t o : clusters ? pvs : std::span<const uint32_t>()) {
    const auto cs = index.ClustersOf(o);
    candidates.insert(candidates.end(), cs.begin(), cs.end());
  }
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  std::stable_sort(candidates.begin(), candidates.end(), [&](uint32_t a, uint32_t b) {
    return levels.clusters[a].objects.size() < levels.clusters[b].objects.size();
  });
  std::unordered_map<uint32_t, uint32_t> owner;              // PVS object -> chosen cluster
  std::unordered_map<uint32_t, uint32_t> chosen;             // chosen cluster -> its level
  std::unordered_map<uint32_t, uint64_t> inner_triangles;    // chosen cluster -> the triangles it may draw
  std::vector<uint32_t> members;
  for (const uint32_t c : candidates) {
    const Cluster& cluster = levels.clusters[c];
    const double d = BoxDistance(eye_region, cluster.bounds);
    uint32_t coarsest = 0;
    for (size_t k = cluster.levels.size(); k > 0; --k) {
      if (ErrorPixels(cluster.levels[k - 1].error_m, d, screen) <= tau_px) {
        coarsest = static_cast<uint32_t>(k);
        break;
      }
    }
    if (coarsest == 0) continue;
    members.clear();
    std::set_intersection(cluster.objects.begin(), cluster.objects.end(), pvs.begin(), pvs.end(),
                          std::back_inserter(members));
    // Triangles a masked frame may draw: a level that keeps an object's triangles draws those the
    // mask names, at most the full mesh's that may face the region; another is drawn whole.
    uint64_t replaced = 0, replaced_triangles = 0, kept_triangles = 0;
    std::vector<uint32_t> inner;  // chosen clusters it would replace
    bool contained = true;
    for (const uint32_t o : members) {
      const uint64_t facing = FrontFacingTriangles(scene.objects[o].mesh, eye_region);
      kept_triangles += facing;
      const auto it = owner.find(o);
      if (it == owner.end()) {
        const uint32_t own = own_level.at(o);
        replaced += index.ObjectBytes(o, own);
        const size_t drawn = own == 0 ? scene.objects[o].mesh.TriangleCount()
                                      : levels.objects[o][own - 1].mesh.TriangleCount();
        replaced_triangles += drawn == scene.objects[o].mesh.TriangleCount() ? facing : drawn;
        continue;
      }
      if (std::find(inner.begin(), inner.end(), it->second) != inner.end()) continue;
      const Cluster& other = levels.clusters[it->second];
      if (!std::includes(cluster.objects.begin(), cluster.objects.end(), other.objects.begin(), other.objects.end())) {
        contained = false;
        break;
      }
      inner.push_back(it->second);
      replaced += index.ClusterBytes(it->second, chosen.at(it->second));
      replaced_triangles += inner_triangles.at(it->second);
    }
    if (!contained) continue;
    // The coarsest allowed level that is no dearer in bytes and draws no more triangles.
    uint32_t level = coarsest;
    uint64_t triangles = 0;
    for (; level > 0; --level) {
      triangles = index.ClusterKeepsTriangles(c, level) ? kept_triangles
                                                        : cluster.levels[level - 1].mesh.TriangleCount();
      if (index.ClusterBytes(c, level) <= replaced && triangles <= replaced_triangles) break;
    }
    if (level == 0) continue;
    inner_triangles[c] = triangles;
    for (const uint32_t r : inner) chosen.erase(r);
    for (const uint32_t o : members) owner[o] = c;
    chosen[c] = level;
  }
  std::vector<DrawItem> items;
  items.reserve(pvs.size() - owner.size() + chosen.size());
  for (const uint32_t o : pvs) {
    if (!owner.contains(o)) items.push_back({DrawItem::Kind::kObject, o, own_level.at(o)});
  }
  for (const auto& [c, level] : chosen) items.push_back({DrawItem::Kind::kCluster, c, level});
  std::sort(items.begin(), items.end());
  return items;
}

}  // namespace vistream::scenes
