#include "client/verification.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include <absl/strings/str_cat.h>

#include "scenes/cluster_triangles.h"
#include "visibility/mask_codec.h"

namespace vistream::client {

namespace {

// Stands for "no source pixel": far above any squared distance of a frame (8192^2 * 2), and
// finite, so that the envelope's intersections stay numbers.
constexpr double kFar = 1e20;

// The 1-D squared distance transform of `f` (n samples) into `d` (Felzenszwalb & Huttenlocher,
// section 2.1): d[q] = min over p of (q - p)^2 + f[p]. `v`, `z` are scratch of n and n + 1.
void Transform1d(const double* f, int n, double* d, std::vector<int>& v, std::vector<double>& z) {
  auto meet = [&](int q, int p) { return ((f[q] + double(q) * q) - (f[p] + double(p) * p)) / (2.0 * q - 2.0 * p); };
  int k = 0;
  v[0] = 0;
  z[0] = -std::numeric_limits<double>::infinity();
  z[1] = std::numeric_limits<double>::infinity();
  for (int q = 1; q < n; ++q) {
    double s = meet(q, v[k]);
    while (s <= z[k]) {
      --k;
      s = meet(q, v[k]);
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = std::numeric_limits<double>::infinity();
  }
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[k + 1] < q) ++k;
    const double dq = double(q) - v[k];
    d[q] = std::min(kFar, dq * dq + f[v[k]]);
  }
}

}  // namespace

std::vector<double> SquaredDistanceTransform(const std::vector<uint8_t>& source, int width, int height) {
  const auto w = static_cast<size_t>(width), h = static_cast<size_t>(height);
  std::vector<double> out(w * h);
  for (size_t k = 0; k < out.size(); ++k) out[k] = source[k] != 0 ? 0.0 : kFar;
  const int n = std::max(width, height);
  std::vector<double> f(n), d(n), z(n + 1);
  std::vector<int> v(n);
  for (size_t x = 0; x < w; ++x) {  // columns
    for (size_t y = 0; y < h; ++y) f[y] = out[y * w + x];
    Transform1d(f.data(), height, d.data(), v, z);
    for (size_t y = 0; y < h; ++y) out[y * w + x] = d[y];
  }
  for (size_t y = 0; y < h; ++y) {  // rows
    Transform1d(&out[y * w], width, d.data(), v, z);
    std::copy(d.begin(), d.begin() + width, out.begin() + static_cast<std::ptrdiff_t>(y * w));
  }
  return out;
}

absl::StatusOr<PixelComparison> CompareWithFullScene(gl::IdRenderer& ids, const scenes::Scene& scene,
                                                     const Camera& camera, const std::vector<DrawnObject>& drawn,
                                                     const EpsilonMaskSet* mask) {
  std::vector<uint8_t> flags(ids.triangle_count(), 0);
  for (const DrawnObject& d : drawn) {
    if (d.id >= scene.objects.size()) continue;
    if (d.cluster.has_value()) {
      // A cluster level's piece: the object's run of the local cluster level's triangles.
      if (!ids.has_levels() || *d.cluster >= scene.levels.clusters.size() ||
          d.level > scene.levels.clusters[*d.cluster].levels.size()) {
        return absl::FailedPreconditionError(absl::StrCat("--verify: object ", d.id, " was drawn as its piece of ",
                                                          "cluster ", *d.cluster, ", level ", d.level,
                                                          ", which the local scene's levels do not have"));
      }
      const scenes::Cluster& cluster = scene.levels.clusters[*d.cluster];
      const auto at = std::lower_bound(cluster.objects.begin(), cluster.objects.end(), d.id);
      if (at == cluster.objects.end() || *at != d.id) continue;
      const std::vector<uint32_t> counts =
          scenes::ClusterObjectTriangles(scene, cluster, cluster.levels[d.level - 1].mesh);
      const size_t k = static_cast<size_t>(at - cluster.objects.begin());
      uint64_t first = ids.FirstClusterTriangle(*d.cluster, d.level);
      for (size_t j = 0; j < k; ++j) first += counts[j];
      const std::vector<uint8_t>* bits = d.masked && mask != nullptr ? mask->Bits(d.id) : nullptr;
      for (size_t t = 0; t < counts[k]; ++t) {
        flags[first + t] = bits == nullptr || visibility::MaskBit(*bits, t) ? 1 : 0;
      }
      continue;
    }
    size_t n = scene.objects[d.id].mesh.TriangleCount();
    if (d.level > 0) {
      const size_t levels = d.id < scene.levels.objects.size() ? scene.levels.objects[d.id].size() : 0;
      if (!ids.has_levels() || d.level > levels) {
        return absl::FailedPreconditionError(absl::StrCat(
            "--verify: object ", d.id, " was drawn at level ", d.level, ", which the local scene ",
            d.level > levels ? absl::StrCat("does not have (it has ", levels, ")") : "holds but the check was not given"));
      }
      n = scene.levels.objects[d.id][d.level - 1].mesh.TriangleCount();
    }
    const uint64_t first = ids.FirstTriangle(d.id, d.level);
    const std::vector<uint8_t>* bits = nullptr;
    if (d.masked && mask != nullptr) bits = mask->Bits(d.id);
    for (size_t t = 0; t < n; ++t) {
      flags[first + t] = bits == nullptr || visibility::MaskBit(*bits, t) ? 1 : 0;
    }
  }
  const glm::dvec3 forward = camera.Forward(), up = camera.Up();
  absl::StatusOr<std::vector<uint32_t>> full =
      ids.RenderView(camera.eye, forward, up, camera.fov_y_rad, camera.width, camera.height, nullptr);
  if (!full.ok()) return full.status();
  absl::StatusOr<std::vector<uint32_t>> part =
      ids.RenderView(camera.eye, forward, up, camera.fov_y_rad, camera.width, camera.height, &flags);
  if (!part.ok()) return part.status();
  // A pixel of a cluster level's piece counts as any of the objects the cluster stands for
  // (issue 45): a simplified level's triangle may lie where another of them is.
  std::unordered_map<uint32_t, uint32_t> piece_of;  // object drawn as a piece -> its cluster
  for (const DrawnObject& d : drawn) {
    if (d.cluster.has_value() && *d.cluster < scene.levels.clusters.size()) piece_of[d.id] = *d.cluster;
  }
  auto same = [&](uint32_t f, uint32_t p) {
    if (f == p) return true;
    if (piece_of.empty() || f == gl::kNothing || p == gl::kNothing || (f & gl::kBackFace) != 0 ||
        (p & gl::kBackFace) != 0) {
      return false;
    }
    const auto c = piece_of.find(p - 1);
    if (c == piece_of.end()) return false;
    const std::vector<uint32_t>& members = scene.levels.clusters[c->second].objects;
    return std::binary_search(members.begin(), members.end(), f - 1);
  };
  PixelComparison c;
  for (size_t k = 0; k < full->size(); ++k) c.differ += same((*full)[k], (*part)[k]) ? 0 : 1;
  c.pixels = full->size();
  if (c.differ == 0) return c;
  // How far the differing pixels lie from the full frame's silhouettes: where the object seen
  // changes, and where one surface of an object passes behind another of it (a building's lower
  // block in front of its upper one): neighbouring pixels see triangles that do not join, or
  // join across a contour (one faces the eye, the other away). Triangles join when they share
  // an edge (two corners at the same position) and face alike.
  absl::StatusOr<std::vector<uint32_t>> tris =
      ids.RenderViewTriangles(camera.eye, forward, up, camera.fov_y_rad, camera.width, camera.height);
  if (!tris.ok()) return tris.status();
  std::unordered_map<uint64_t, bool> joined_pairs;
  auto joined = [&](uint32_t a, uint32_t b) {
    if (a == b) return true;
    if (a == gl::kNothing || b == gl::kNothing || (a & gl::kBackFace) != (b & gl::kBackFace)) return false;
    const uint64_t ta = (a & ~gl::kBackFace) - 1, tb = (b & ~gl::kBackFace) - 1;
    const uint64_t key = std::min(ta, tb) << 32 | std::max(ta, tb);
    if (const auto it = joined_pairs.find(key); it != joined_pairs.end()) return it->second;
    const uint32_t oa = ids.ObjectOfTriangle(ta), ob = ids.ObjectOfTriangle(tb);
    bool shared_edge = false;
    if (oa == ob) {
      const scenes::Mesh& m = scene.objects[oa].mesh;
      const size_t la = 3 * (ta - ids.FirstTriangle(oa)), lb = 3 * (tb - ids.FirstTriangle(ob));
      int common = 0;
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) common += m.positions[m.indices[la + i]] == m.positions[m.indices[lb + j]] ? 1 : 0;
      }
      shared_edge = common >= 2;
    }
    joined_pairs.emplace(key, shared_edge);
    return shared_edge;
  };
  const int w = camera.width, h = camera.height;
  std::vector<uint8_t> edge(full->size(), 0);
  bool any = false;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t k = static_cast<size_t>(y) * w + x;
      const bool right = x + 1 < w && ((*full)[k] != (*full)[k + 1] || !joined((*tris)[k], (*tris)[k + 1]));
      const bool above = y + 1 < h && ((*full)[k] != (*full)[k + w] || !joined((*tris)[k], (*tris)[k + w]));
      if (right) edge[k] = edge[k + 1] = 1;
      if (above) edge[k] = edge[k + w] = 1;
      any = any || right || above;
    }
  }
  if (!any) {
    c.max_silhouette_px = std::hypot(double(w), double(h));
    return c;
  }
  const std::vector<double> d2 = SquaredDistanceTransform(edge, w, h);
  double worst = 0.0;
  for (size_t k = 0; k < full->size(); ++k) {
    if (!same((*full)[k], (*part)[k])) worst = std::max(worst, d2[k]);
  }
  c.max_silhouette_px = std::sqrt(worst);
  return c;
}

}  // namespace vistream::client
