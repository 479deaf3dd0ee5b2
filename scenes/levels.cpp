#include "scenes/levels.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <thread>

// The kernel first: CGAL's distance header uses its 3D functions without including them.
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Polygon_mesh_processing/distance.h>
#include <absl/strings/str_cat.h>
#include <glm/geometric.hpp>
#include <meshoptimizer.h>

#include "scenes/cluster_triangles.h"
#include "scenes/geometry_codec.h"

namespace vistream::scenes {

namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using SurfaceMesh = CGAL::Surface_mesh<Kernel::Point_3>;

// The union of `meshes`, welded (WeldPositions).
WeldedMesh Weld(const std::vector<const Mesh*>& meshes) {
  std::vector<glm::vec3> positions;
  std::vector<uint32_t> indices;
  for (const Mesh* m : meshes) {
    const auto base = static_cast<uint32_t>(positions.size());
    positions.insert(positions.end(), m->positions.begin(), m->positions.end());
    for (uint32_t i : m->indices) indices.push_back(base + i);
  }
  return WeldPositions(positions, indices);
}

// The triangles of `w` simplified to within `error_m` (meshoptimizer's own estimate): the
// topology-preserving simplifier, or the sloppy one (which merges nearby parts) when `sloppy`.
std::vector<uint32_t> Simplify(const WeldedMesh& w, double error_m, bool sloppy) {
  if (w.indices.empty()) return {};
  const float scale = meshopt_simplifyScale(&w.positions[0].x, w.positions.size(), sizeof(glm::vec3));
  const float relative = scale > 0.0f ? static_cast<float>(error_m / scale) : 0.0f;
  std::vector<uint32_t> out(w.indices.size());
  size_t n = 0;
  if (sloppy) {
    n = meshopt_simplifySloppy(out.data(), w.indices.data(), w.indices.size(), &w.positions[0].x, w.positions.size(),
                               sizeof(glm::vec3), 0, relative);
  } else {
    n = meshopt_simplify(out.data(), w.indices.data(), w.indices.size(), &w.positions[0].x, w.positions.size(),
                         sizeof(glm::vec3), 0, relative);
  }
  out.resize(n);
  return out;
}

// The power-of-two step positions of a level with target error `target_m` snap to: rounding
// moves a point by at most step * sqrt(3) / 2, which is kept within half the target.
double SnapStep(double target_m) {
  const double q = std::exp2(std::floor(std::log2(target_m / std::sqrt(3.0))));
  return std::clamp(q, std::ldexp(1.0, -10), 1.0);
}

// A drawable level mesh from welded positions and a triangle list: positions snapped to
// multiples of `step_m` (scene-local) and welded again, normals by creases (ShadeByCreases, as
// the wire's receiver rebuilds them: EncodeLevelMesh and DecodeLevelMesh give this mesh back).
Mesh BuildLevelMesh(const std::vector<glm::vec3>& welded, const std::vector<uint32_t>& indices, double step_m) {
  std::vector<glm::vec3> pos(welded.size());
  for (size_t i = 0; i < welded.size(); ++i) {
    for (int a = 0; a < 3; ++a) pos[i][a] = static_cast<float>(std::round(welded[i][a] / step_m) * step_m);
  }
  const WeldedMesh snapped = WeldPositions(pos, indices);
  return ShadeByCreases(snapped.positions, snapped.indices);
}

// Adds the non-degenerate triangles of `mesh` to `out`, each with its own three vertices,
// relative to `ref`. Returns how many it added.
size_t AddTriangles(const Mesh& mesh, const glm::dvec3& ref, SurfaceMesh* out) {
  size_t added = 0;
  for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
    glm::dvec3 p[3];
    for (int k = 0; k < 3; ++k) p[k] = glm::dvec3(mesh.positions[mesh.indices[t + k]]) - ref;
    if (!(glm::length(glm::cross(p[1] - p[0], p[2] - p[0])) > 0.0)) continue;
    SurfaceMesh::Vertex_index v[3];
    for (int k = 0; k < 3; ++k) v[k] = out->add_vertex(Kernel::Point_3(p[k].x, p[k].y, p[k].z));
    out->add_face(v[0], v[1], v[2]);
    ++added;
  }
  return added;
}

// Runs task(i) for i in [0, count) on `threads` threads; the calling thread reports progress
// and polls the cancel flag. With `weights` (one per task, the units `progress` counts), a task
// adds its weight when done, else 1. False when cancelled.
bool ParallelFor(size_t count, unsigned threads, Progress& progress, const std::function<void(size_t)>& task,
                 const std::vector<uint64_t>* weights = nullptr) {
  std::atomic<size_t> next{0}, done{0};
  std::atomic<bool> stop{false};
  std::vector<std::thread> pool;
  const unsigned n = std::max(1u, std::min<unsigned>(threads, static_cast<unsigned>(std::max<size_t>(count, 1))));
  for (unsigned k = 0; k < n; ++k) {
    pool.emplace_back([&] {
      for (size_t i; !stop.load() && (i = next.fetch_add(1)) < count;) {
        task(i);
        done.fetch_add(weights != nullptr ? (*weights)[i] : 1);
      }
    });
  }
  const size_t total = weights != nullptr ? std::accumulate(weights->begin(), weights->end(), size_t{0}) : count;
  size_t reported = 0;
  while (reported < total) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (progress.Cancelled()) {
      stop = true;
      break;
    }
    const size_t d = done.load();
    progress.Advance(d - reported);
    reported = d;
  }
  for (std::thread& t : pool) t.join();
  return !stop.load();
}

// A chain of levels of the union of `originals`, one per target error: the first the welded
// triangles themselves (snapped: far fewer bytes, the same triangles in the same order, so an
// ε-mask's triangle bits still apply), each later one simplified (topology-preserving first
// unless `sloppy_first`, the other simplifier where that keeps too many triangles) and kept when
// it has at most max_share of the triangles before it. Every level is measured; a level whose
// error is not above the level before replaces it.
std::vector<MeshLevel> MakeChain(const std::vector<const Mesh*>& originals, const std::vector<double>& targets_m,
                                 double max_share, bool sloppy_first) {
  const WeldedMesh w = Weld(originals);
  size_t previous = w.indices.size() / 3;
  std::vector<MeshLevel> chain;
  for (size_t t = 0; t < targets_m.size(); ++t) {
    const double target = targets_m[t];
    const auto limit = t == 0 ? previous : static_cast<size_t>(max_share * static_cast<double>(previous));
    std::vector<uint32_t> idx;
    if (t == 0) {
      idx = w.indices;
    } else {
      idx = Simplify(w, target, sloppy_first);
      if (idx.size() / 3 > limit) {
        std::vector<uint32_t> other = Simplify(w, target, !sloppy_first);
        if (other.size() < idx.size()) idx = std::move(other);
      }
    }
    if (idx.empty() || idx.size() / 3 > limit) continue;
    Mesh mesh = BuildLevelMesh(w.positions, idx, SnapStep(target));
    const double error = MeasureLevelError(mesh, originals, std::max(0.002, target / 20.0));
    if (!std::isfinite(error)) continue;
    while (!chain.empty() && chain.back().error_m >= error) chain.pop_back();
    previous = mesh.TriangleCount();
    chain.push_back({std::move(mesh), error});
  }
  return chain;
}

}  // namespace

double MeasureLevelError(const Mesh& level, const std::vector<const Mesh*>& originals, double tolerance_m) {
  Aabb box;
  for (const Mesh* m : originals) box.Extend(m->Bounds());
  const glm::dvec3 ref = box.Empty() ? glm::dvec3(0.0) : box.min;
  SurfaceMesh a, b;
  const size_t na = AddTriangles(level, ref, &a);
  size_t nb = 0;
  for (const Mesh* m : originals) nb += AddTriangles(*m, ref, &b);
  if (na == 0 && nb == 0) return 0.0;
  if (na == 0 || nb == 0) return std::numeric_limits<double>::infinity();
  namespace PMP = CGAL::Polygon_mesh_processing;
  const double d = PMP::bounded_error_symmetric_Hausdorff_distance<CGAL::Sequential_tag>(a, b, tolerance_m);
  return d + tolerance_m;
}

absl::StatusOr<SceneLevels> MakeLevels(const Scene& scene, const LevelOptions& options, const RunControl& run) {
  auto ascending_positive = [](const std::vector<double>& v) {
    if (v.empty()) return false;
    for (size_t i = 0; i < v.size(); ++i) {
      if (!(std::isfinite(v[i]) && v[i] > 0.0) || (i > 0 && !(v[i] > v[i - 1]))) return false;
    }
    return true;
  };
  if (!ascending_positive(options.object_errors_m)) {
    return absl::InvalidArgumentError("levels: object errors must be positive, finite and ascending");
  }
  if (!options.cluster_tiles_m.empty() &&
      (!ascending_positive(options.cluster_tiles_m) || !ascending_positive(options.cluster_errors_m))) {
    return absl::InvalidArgumentError("levels: cluster tiles and errors must be positive, finite and ascending");
  }
  if (!(options.max_triangle_share > 0.0 && options.max_triangle_share < 1.0)) {
    return absl::InvalidArgumentError("levels: the largest triangle share of a level must lie in (0, 1)");
  }
  const unsigned threads = options.threads != 0 ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  SceneLevels levels;
  levels.objects.resize(scene.objects.size());
  {
    Progress progress(run, "levels: objects", scene.objects.size());
    const bool whole = ParallelFor(scene.objects.size(), threads, progress, [&](size_t i) {
      levels.objects[i] = MakeChain({&scene.objects[i].mesh}, options.object_errors_m, options.max_triangle_share,
                                    /*sloppy_first=*/false);
    });
    progress.Finish();
    if (!whole) return absl::CancelledError("levels: cancelled while making the objects' levels");
  }
  // Tiles: each object (but the terrain's) in the tile of its box centre, per tile size.
  struct Pending {
    std::vector<uint32_t> objects;
    double scale = 1.0;
  };
  std::vector<Pending> pending;
  for (const double tile : options.cluster_tiles_m) {
    std::map<std::pair<int64_t, int64_t>, std::vector<uint32_t>> tiles;
    for (const Object& o : scene.objects) {
      if (std::binary_search(scene.terrain.begin(), scene.terrain.end(), o.id)) continue;
      const glm::dvec3 c = o.bounds.Centre() - scene.bounds.min;
      tiles[{static_cast<int64_t>(std::floor(c.x / tile)), static_cast<int64_t>(std::floor(c.y / tile))}].push_back(o.id);
    }
    for (auto& [key, ids] : tiles) {
      if (ids.size() >= 2) pending.push_back({std::move(ids), tile / options.cluster_tiles_m.front()});
    }
  }
  std::vector<Cluster> clusters(pending.size());
  {
    // The largest clusters first (a 1 km tile holds sixteen 250 m ones: started last, they left
    // the threads idle and the progress at 90% for minutes); progress counts their triangles.
    std::vector<uint64_t> weights(pending.size()), order_weights(pending.size());  // by tile, by task
    for (size_t i = 0; i < pending.size(); ++i) {
      for (uint32_t o : pending[i].objects) weights[i] += scene.objects[o].mesh.TriangleCount();
    }
    std::vector<size_t> order(pending.size());
    std::iota(order.begin(), order.end(), size_t{0});
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return weights[a] > weights[b]; });
    for (size_t k = 0; k < order.size(); ++k) order_weights[k] = weights[order[k]];
    Progress progress(run, "levels: clusters (triangles)", std::accumulate(weights.begin(), weights.end(), uint64_t{0}));
    const bool whole = ParallelFor(pending.size(), threads, progress, [&](size_t k) {
      const size_t i = order[k];  // ids stay in the tiles' order: the result does not depend on it
      Cluster& c = clusters[i];
      c.objects = pending[i].objects;
      std::vector<const Mesh*> meshes;
      for (uint32_t o : c.objects) {
        meshes.push_back(&scene.objects[o].mesh);
        c.bounds.Extend(scene.objects[o].bounds);
      }
      std::vector<double> targets = options.cluster_errors_m;
      for (double& t : targets) t *= pending[i].scale;
      c.levels = MakeChain(meshes, targets, options.max_triangle_share, /*sloppy_first=*/true);
      for (const MeshLevel& l : c.levels) c.bounds.Extend(l.mesh.Bounds());
    }, &order_weights);
    progress.Finish();
    if (!whole) return absl::CancelledError("levels: cancelled while making the clusters");
  }
  for (Cluster& c : clusters) {
    if (!c.levels.empty()) levels.clusters.push_back(std::move(c));
  }
  GroupClusterTriangles(scene, &levels);
  return levels;
}

absl::Status ValidateLevels(const SceneLevels& levels, const Scene& scene, const std::string& where) {
  if (!levels.objects.empty() && levels.objects.size() != scene.objects.size()) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": levels for ", levels.objects.size(), " objects, but the scene has ",
                                                   scene.objects.size()));
  }
  auto check_chain = [&](const std::vector<MeshLevel>& chain, size_t full_triangles, const std::string& what) {
    double previous_error = 0.0;
    size_t previous_triangles = full_triangles;
    for (size_t k = 0; k < chain.size(); ++k) {
      const MeshLevel& l = chain[k];
      const std::string lw = absl::StrCat(what, ", level ", k + 1);
      if (!std::isfinite(l.error_m) || !(l.error_m > 0.0)) {
        return absl::InvalidArgumentError(absl::StrCat(lw, ": error ", l.error_m, " m is not finite and positive"));
      }
      if (!(l.error_m > previous_error)) {
        return absl::InvalidArgumentError(absl::StrCat(lw, ": error ", l.error_m, " m is not above the finer level's ",
                                                       previous_error, " m"));
      }
      const Mesh& m = l.mesh;
      if (absl::Status st = ValidateMesh(m, lw); !st.ok()) return st;
      if (m.indices.empty()) return absl::InvalidArgumentError(absl::StrCat(lw, ": no triangles"));
      if (m.TriangleCount() > previous_triangles) {
        return absl::InvalidArgumentError(absl::StrCat(lw, ": ", m.TriangleCount(),
                                                       " triangles, more than the finer level's ", previous_triangles));
      }
      previous_error = l.error_m;
      previous_triangles = m.TriangleCount();
    }
    return absl::OkStatus();
  };
  for (size_t i = 0; i < levels.objects.size(); ++i) {
    const std::string what = absl::StrCat(where, ": object ", i, " ('", scene.objects[i].name, "')");
    if (absl::Status s = check_chain(levels.objects[i], scene.objects[i].mesh.TriangleCount(), what); !s.ok()) return s;
  }
  for (size_t c = 0; c < levels.clusters.size(); ++c) {
    const Cluster& cl = levels.clusters[c];
    const std::string what = absl::StrCat(where, ": cluster ", c);
    if (cl.objects.size() < 2) {
      return absl::InvalidArgumentError(absl::StrCat(what, ": stands for ", cl.objects.size(), " objects (at least 2)"));
    }
    size_t triangles = 0;
    for (size_t k = 0; k < cl.objects.size(); ++k) {
      if (cl.objects[k] >= scene.objects.size()) {
        return absl::InvalidArgumentError(absl::StrCat(what, ": object ", cl.objects[k], " does not exist (",
                                                       scene.objects.size(), " objects)"));
      }
      if (k > 0 && !(cl.objects[k] > cl.objects[k - 1])) {
        return absl::InvalidArgumentError(absl::StrCat(what, ": objects are not sorted and distinct at ", cl.objects[k]));
      }
      triangles += scene.objects[cl.objects[k]].mesh.TriangleCount();
    }
    if (cl.levels.empty()) return absl::InvalidArgumentError(absl::StrCat(what, ": has no level"));
    if (absl::Status s = check_chain(cl.levels, triangles, what); !s.ok()) return s;
  }
  return absl::OkStatus();
}

uint64_t LevelBytes(const SceneLevels& levels) {
  uint64_t bytes = 0;
  for (const auto& chain : levels.objects) {
    for (const MeshLevel& l : chain) bytes += RawMeshBytes(l.mesh.positions.size(), l.mesh.indices.size());
  }
  for (const Cluster& c : levels.clusters) {
    for (const MeshLevel& l : c.levels) bytes += RawMeshBytes(l.mesh.positions.size(), l.mesh.indices.size());
  }
  return bytes;
}

}  // namespace vistream::scenes
