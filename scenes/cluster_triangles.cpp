#include "scenes/cluster_triangles.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <glm/common.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace vistream::scenes {

namespace {

// The members' boxes binned on a grid over the cluster's xy extent, for nearest-box queries.
class BoxGrid {
 public:
  BoxGrid(const Scene& scene, const Cluster& cluster) : ref_(cluster.bounds.min) {
    for (uint32_t o : cluster.objects) {
      const Aabb& b = scene.objects[o].bounds;
      boxes_.push_back({b.min - ref_, b.max - ref_});
    }
    const glm::dvec3 size = cluster.bounds.max - cluster.bounds.min;
    n_ = std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(boxes_.size())))));
    cell_ = {std::max(size.x / n_, 1e-6), std::max(size.y / n_, 1e-6)};
    bins_.resize(static_cast<size_t>(n_) * n_);
    for (uint32_t k = 0; k < boxes_.size(); ++k) {
      const auto [i0, j0] = Bin(boxes_[k].min);
      const auto [i1, j1] = Bin(boxes_[k].max);
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) bins_[static_cast<size_t>(j) * n_ + i].push_back(k);
      }
    }
  }

  // The member whose box is nearest `p` (scene-local), ties to the lower position.
  uint32_t Nearest(const glm::dvec3& p_scene) const {
    const glm::dvec3 p = p_scene - ref_;
    const auto [pi, pj] = Bin(p);
    double best = std::numeric_limits<double>::infinity();
    uint32_t owner = 0;
    for (int r = 0; r <= n_; ++r) {
      // Every box not yet seen lies in bins at least r rings out: at least (r - 1) bins away.
      if (r > 0 && best < (r - 1) * std::min(cell_.x, cell_.y)) break;
      for (int j = pj - r; j <= pj + r; ++j) {
        for (int i = pi - r; i <= pi + r; ++i) {
          if (std::max(std::abs(i - pi), std::abs(j - pj)) != r || i < 0 || j < 0 || i >= n_ || j >= n_) continue;
          for (uint32_t k : bins_[static_cast<size_t>(j) * n_ + i]) {
            const double d = Distance(boxes_[k], p);
            if (d < best || (d == best && k < owner)) {
              best = d;
              owner = k;
            }
          }
        }
      }
    }
    return owner;
  }

 private:
  std::pair<int, int> Bin(const glm::dvec3& p) const {
    return {std::clamp(static_cast<int>(std::floor(p.x / cell_.x)), 0, n_ - 1),
            std::clamp(static_cast<int>(std::floor(p.y / cell_.y)), 0, n_ - 1)};
  }
  static double Distance(const Aabb& b, const glm::dvec3& p) {
    const glm::dvec3 d = glm::max(glm::max(b.min - p, p - b.max), glm::dvec3(0.0));
    return std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  }

  glm::dvec3 ref_;
  std::vector<Aabb> boxes_;
  int n_ = 1;
  glm::dvec2 cell_{1.0};
  std::vector<std::vector<uint32_t>> bins_;
};

}  // namespace

std::vector<uint32_t> ClusterTriangleOwners(const Scene& scene, const Cluster& cluster, const Mesh& level) {
  const size_t triangles = level.TriangleCount();
  std::vector<uint32_t> owners;
  owners.reserve(triangles);
  size_t full = 0;
  for (uint32_t o : cluster.objects) full += scene.objects[o].mesh.TriangleCount();
  if (full == triangles) {
    for (uint32_t k = 0; k < cluster.objects.size(); ++k) {
      owners.insert(owners.end(), scene.objects[cluster.objects[k]].mesh.TriangleCount(), k);
    }
    return owners;
  }
  const BoxGrid grid(scene, cluster);
  for (size_t t = 0; t < triangles; ++t) {
    glm::dvec3 c(0.0);
    for (int v = 0; v < 3; ++v) c += glm::dvec3(level.positions[level.indices[3 * t + v]]);
    owners.push_back(grid.Nearest(c / 3.0));
  }
  return owners;
}

void GroupClusterTriangles(const Scene& scene, SceneLevels* levels) {
  for (Cluster& cluster : levels->clusters) {
    for (MeshLevel& l : cluster.levels) {
      const std::vector<uint32_t> owners = ClusterTriangleOwners(scene, cluster, l.mesh);
      if (std::is_sorted(owners.begin(), owners.end())) continue;
      std::vector<uint32_t> order(owners.size());
      std::iota(order.begin(), order.end(), 0u);
      std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return owners[a] < owners[b]; });
      std::vector<uint32_t> indices;
      indices.reserve(l.mesh.indices.size());
      for (uint32_t t : order) {
        for (int v = 0; v < 3; ++v) indices.push_back(l.mesh.indices[3 * t + v]);
      }
      l.mesh.indices = std::move(indices);
    }
  }
}

std::vector<uint32_t> ClusterObjectTriangles(const Scene& scene, const Cluster& cluster, const Mesh& level) {
  std::vector<uint32_t> counts(cluster.objects.size(), 0);
  for (uint32_t k : ClusterTriangleOwners(scene, cluster, level)) ++counts[k];
  return counts;
}

}  // namespace vistream::scenes
