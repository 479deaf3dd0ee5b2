#include "server/served_scene.h"

#include <thread>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "proto/scene_info.h"
#include "scenes/cluster_triangles.h"
#include "scenes/levels.h"
#include "server/wire.h"
#include "visibility/parallel.h"

namespace vistream::server {

absl::StatusOr<std::unique_ptr<ServedScene>> ServedScene::Create(const ServedSceneOptions& options,
                                                                 const scenes::RunControl& run) {
  if (options.res < 1 || options.res > 256 || (options.res & (options.res - 1)) != 0) {
    return absl::InvalidArgumentError(absl::StrCat("--res ", options.res, ": expected a power of two, 1 to 256"));
  }
  std::unique_ptr<ServedScene> s(new ServedScene());
  scenes::LoadOptions load;
  load.catalog_dir = options.catalog_dir;
  load.run = run;
  absl::StatusOr<scenes::LoadedScene> loaded = scenes::LoadScene(options.scene, load);
  if (!loaded.ok()) return loaded.status();
  s->scene_ = std::move(loaded->scene);
  s->name_ = options.name.empty() ? s->scene_.name : options.name;
  s->load_seconds_ = loaded->seconds;
  s->viewcell_ = loaded->viewcell;
  if (options.cell_size > 0.0) s->viewcell_.size_m = options.cell_size;
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(s->scene_, s->viewcell_);
  if (!grid.ok()) return grid.status();
  s->grid_ = std::make_unique<visibility::ViewcellGrid>(*grid);
  if (!s->scene_.terrain.empty()) s->terrain_ = std::make_shared<const scenes::TerrainHeight>(s->scene_);
  const size_t objects = s->scene_.objects.size();

  unsigned threads = options.pool != nullptr ? options.pool->threads()
                    : options.threads != 0    ? options.threads
                                              : std::max(1u, std::thread::hardware_concurrency());
  if (!options.pvs_file.empty()) {
    absl::StatusOr<visibility::PvsFile> f = visibility::LoadPvsFile(options.pvs_file, *s->grid_, s->scene_);
    if (!f.ok()) return f.status();
    s->file_ = std::make_unique<visibility::PvsFile>(std::move(*f));
    s->pvs_source_ = absl::StrCat("PVS file ", options.pvs_file, " (", s->file_->strategy, ")");
  } else {
    s->tree_ = std::make_unique<visibility::KdTree>(visibility::KdTree::Build(s->scene_));
    s->computer_ = std::make_unique<visibility::PvsComputer>(s->scene_, *s->tree_);
    s->query_ = gl::QueryOptionsFor(options.res);
    // One OpenGL context per worker, made current on that worker's thread (init below); alone,
    // the scene has one worker.
    if (options.backend == "gl" && options.pool == nullptr) threads = 1;
    s->backends_.resize(threads);
    if (options.backend != "gl") {
      for (unsigned w = 0; w < threads; ++w) {
        absl::StatusOr<gl::PvsBackend> b = gl::PvsBackend::Create(options.backend);
        if (!b.ok()) return b.status();
        s->backends_[w] = std::make_unique<gl::PvsBackend>(std::move(*b));
      }
    }
    s->pvs_source_ = absl::StrFormat("dual ray space (%s, %u^2)", options.backend, options.res);
    if (options.store != nullptr) {
      s->store_ = options.store;
      s->store_ns_ = PvsStoreNamespace(options.store->key_prefix(), scenes::SceneFingerprint(s->scene_), *s->grid_,
                                       options.res, options.backend);
      absl::StrAppend(&s->pvs_source_, " with the PVS store at ", options.store->address());
    }
  }

  // Geometry, encoded once for every session.
  s->geometry_.resize(objects);
  visibility::ParallelFor(objects, 0, [&] {
    return [&](size_t i) { s->geometry_[i] = scenes::EncodeMesh(s->scene_.objects[i].mesh); };
  });
  // Levels of detail: the scene's own, or made now; encoded once like the full meshes.
  if (s->scene_.levels.empty() && options.make_levels) {
    scenes::LevelOptions lo = scenes::SessionLevelOptions();
    if (!options.make_clusters) lo.cluster_tiles_m.clear();
    absl::StatusOr<scenes::SceneLevels> made = scenes::MakeLevels(s->scene_, lo, run);
    if (!made.ok()) return made.status();
    s->scene_.levels = *std::move(made);
  }
  if (!s->scene_.levels.objects.empty()) {
    // Each cluster level's pieces in runs (levels saved before runs were kept are grouped here).
    scenes::GroupClusterTriangles(s->scene_, &s->scene_.levels);
    std::vector<uint64_t> full_bytes(objects);
    for (size_t i = 0; i < objects; ++i) full_bytes[i] = s->geometry_[i].EncodedBytes();
    s->level_index_ = std::make_unique<scenes::LevelIndex>(s->scene_, s->scene_.levels, std::move(full_bytes));
  }
  absl::StatusOr<std::unique_ptr<visibility::EpsilonSuperset>> eps = visibility::EpsilonSuperset::Create(s->scene_);
  if (!eps.ok()) return eps.status();
  s->epsilon_ = std::move(*eps);

  s->scene_info_ = MakeSceneInfo(s->scene_, *s->grid_, s->name_);
  // Every walk of the scene, the catalog entry's first (LoadedScene::walks): a client without
  // the catalog (the browser's) follows them by name.
  s->scene_info_.clear_paths();
  for (const scenes::WalkPath& w : loaded->walks) {
    vistream::v1::ScenePathInfo* out = s->scene_info_.add_paths();
    out->set_name(w.name);
    for (const glm::dvec2& p : w.waypoints) {
      out->add_xy(p.x);
      out->add_xy(p.y);
    }
  }

  s->masks_ = std::make_unique<MaskQueue>(std::max(1u, std::thread::hardware_concurrency()), 4096,
                                          options.idle_priority_masks);
  ServedScene* self = s.get();
  std::function<void(unsigned)> init;
  if (!options.pvs_file.empty()) {
    if (options.pool == nullptr) threads = 1;  // lookups
  } else if (options.backend == "gl") {
    // The context must be created on the thread that draws: each worker makes its own.
    init = [self](unsigned worker) {
      absl::StatusOr<gl::PvsBackend> b = gl::PvsBackend::Create("gl");
      if (b.ok()) self->backends_[worker] = std::make_unique<gl::PvsBackend>(std::move(*b));
    };
  }
  auto compute = [self](CellId cell, unsigned worker) { return self->StoredOrComputedPvs(cell, worker); };
  s->scheduler_ = options.pool != nullptr
                      ? std::make_unique<PvsScheduler>(compute, options.pool, options.cache_bytes, init)
                      : std::make_unique<PvsScheduler>(compute, threads, options.cache_bytes, init);
  if (options.backend == "gl" && options.pvs_file.empty()) {
    // Fail at start-up, not on the first request, when there is no OpenGL.
    absl::StatusOr<gl::PvsBackend> probe = gl::PvsBackend::Create("gl");
    if (!probe.ok()) return probe.status();
  }
  return s;
}

uint64_t ServedScene::RawBytes(uint32_t object, uint32_t level) const {
  if (level == 0) return geometry_[object].RawBytes();
  const scenes::Mesh& m = scene_.levels.objects[object][level - 1].mesh;
  return scenes::RawMeshBytes(m.positions.size(), m.indices.size());
}

uint64_t ServedScene::ClusterRawBytes(uint32_t cluster, uint32_t level) const {
  const scenes::Mesh& m = scene_.levels.clusters[cluster].levels[level - 1].mesh;
  return scenes::RawMeshBytes(m.positions.size(), m.indices.size());
}

CellPvs ServedScene::ComputePvs(CellId cell, unsigned worker) const {
  CellPvs out;
  out.cell = cell;
  if (file_ != nullptr) {
    out.objects = file_->sets.Objects(cell);
    return out;
  }
  if (worker >= backends_.size() || backends_[worker] == nullptr) {
    // No backend on this worker (the OpenGL context failed): the CPU raster instead.
    out.objects = computer_->Compute(grid_->CellBox(cell), query_).objects;
    return out;
  }
  const visibility::PvsResult r = backends_[worker]->Compute(*computer_, grid_->CellBox(cell), query_);
  out.objects = r.objects;
  out.compute_s = r.ms / 1000.0;
  return out;
}

CellPvs ServedScene::StoredOrComputedPvs(CellId cell, unsigned worker) const {
  if (store_ == nullptr) return ComputePvs(cell, worker);
  CellPvs stored;
  stored.cell = cell;
  if (store_->Get(store_ns_, cell, scene_.objects.size(), &stored.objects) == PvsStore::Read::kHit) {
    stored.from_store = true;
    return stored;
  }
  CellPvs computed = ComputePvs(cell, worker);
  store_->PutLater(store_ns_, cell, computed.objects);
  return computed;
}

}  // namespace vistream::server
