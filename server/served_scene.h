#pragma once
// What every session of a server reads: the scene, its viewcell grid, its geometry encoded once
// for the wire, the ε-superset engine, and the scheduler that computes (or looks up) viewcell
// PVSs. Built once at start-up; read-only afterwards except for the scheduler's cache.

#include <memory>
#include <string>
#include <vector>

#include <absl/status/statusor.h>

#include "gl/pvs_backend.h"
#include "proto/walkthrough.pb.h"
#include "scenes/catalog.h"
#include "scenes/geometry_codec.h"
#include "scenes/level_choice.h"
#include "scenes/progress.h"
#include "scenes/terrain.h"
#include "server/pvs_scheduler.h"
#include "server/pvs_store.h"
#include "server/task_queue.h"
#include "visibility/epsilon_superset.h"
#include "visibility/kdtree.h"
#include "visibility/pvs.h"
#include "visibility/pvs_file.h"
#include "visibility/viewcell_grid.h"

namespace vistream::server {

struct ServedSceneOptions {
  std::string scene;        // catalog name, catalog .json or glTF file
  std::string name;         // what Hello.scene names it; empty: the scene's own name
  std::string catalog_dir;  // empty: scenes::CatalogDir()
  double cell_size = 0.0;   // metres; 0: the catalog entry's
  uint32_t res = 128;       // the dual ray space's finest raster
  std::string backend = "cpu";  // cpu | gl | exact (see gl::PvsBackend)
  std::string pvs_file;     // serve these sets instead of computing them
  unsigned threads = 0;     // PVS workers; 0: one per core (gl: always one); ignored with `pool`
  size_t cache_bytes = size_t{256} << 20;
  // Workers shared with the server's other scenes (not owned; must outlive the scene); null:
  // the scene starts `threads` workers of its own.
  PvsWorkerPool* pool = nullptr;
  // The PVS store shared with other replicas (not owned; must outlive the scene); null: none.
  // Not used with `pvs_file`.
  PvsStore* store = nullptr;
  // ε-mask threads at SCHED_IDLE, so that they never take CPU from PVS work (server/task_queue.h).
  // False: ordinary threads, for tests whose machine other work shares, where idle threads
  // would wait for it (what they test is which masks are sent and drawn, not their priority).
  bool idle_priority_masks = true;
  // Levels of detail (issue 45): a scene without levels of its own gets them at start
  // (scenes/levels.h MakeLevels, SessionLevelOptions); false: only a scene's own are served.
  bool make_levels = false;
  // With make_levels: cluster levels too (clients that ask for them get them); false: objects'
  // levels only (faster and smaller at start, for runs whose clients never ask).
  bool make_clusters = true;
};

class ServedScene {
 public:
  // Loads and prepares everything. Errors name what failed: the scene (NOT_FOUND, ...), the
  // grid, the PVS file (another scene's or grid's: INVALID_ARGUMENT), the backend.
  static absl::StatusOr<std::unique_ptr<ServedScene>> Create(const ServedSceneOptions& options,
                                                             const scenes::RunControl& run = {});

  // What Hello.scene names (ServedSceneOptions::name, else the scene's own name).
  const std::string& name() const { return name_; }
  const scenes::Scene& scene() const { return scene_; }
  const visibility::ViewcellGrid& grid() const { return *grid_; }
  // The scene's terrain heights (walks put the eye above them); null: flat ground at z = 0.
  const std::shared_ptr<const scenes::TerrainHeight>& terrain() const { return terrain_; }
  const scenes::ViewcellSpec& viewcell() const { return viewcell_; }
  const vistream::v1::SceneInfo& scene_info() const { return scene_info_; }
  const scenes::EncodedMesh& geometry(uint32_t object) const { return geometry_[object]; }
  // Levels of detail: null when the scene has none (every session then gets full detail).
  const scenes::LevelIndex* levels() const { return level_index_.get(); }
  // Object `object`'s level `level` >= 1 encoded for the wire (EncodeLevelMesh).
  const scenes::EncodedLevelMesh& level_geometry(uint32_t object, uint32_t level) const {
    return level_index_->ObjectLevel(object, level);
  }
  // What object `object` at `level` (0: full) takes decoded (RawMeshBytes: the memory budget's unit).
  uint64_t RawBytes(uint32_t object, uint32_t level) const;
  // Cluster `cluster`'s level `level` >= 1 encoded for the wire, and what it takes decoded.
  const scenes::EncodedLevelMesh& cluster_geometry(uint32_t cluster, uint32_t level) const {
    return level_index_->ClusterLevel(cluster, level);
  }
  uint64_t ClusterRawBytes(uint32_t cluster, uint32_t level) const;
  const visibility::EpsilonSuperset* epsilon() const { return epsilon_.get(); }
  PvsScheduler& scheduler() { return *scheduler_; }
  // Where ε-masks are computed: idle-priority threads, one per core.
  MaskQueue& masks() { return *masks_; }
  // Computes (or, with a PVS file, looks up) the PVS of `cell` as scheduler worker `worker`
  // does, on the calling thread; compute_s is the backend's own time (0 for a file's sets).
  // The simulator calls it on its own thread with worker 0 (the CPU raster when that worker's
  // backend is OpenGL, whose context is current on the worker thread only).
  CellPvs ComputePvs(CellId cell, unsigned worker) const;
  // The PVS of `cell` as a scheduler worker makes it: from the store when it holds a good
  // entry (from_store set), else ComputePvs, written back to the store.
  CellPvs StoredOrComputedPvs(CellId cell, unsigned worker) const;
  // This scene's key space in the store (PvsStoreNamespace); empty without a store.
  const std::string& store_namespace() const { return store_ns_; }
  // The shared PVS store this scene uses; null: none.
  PvsStore* store() const { return store_; }
  // "dual ray space (cpu, 128^2)" or "PVS file F (agvs)".
  const std::string& pvs_source() const { return pvs_source_; }
  double load_seconds() const { return load_seconds_; }

 private:
  ServedScene() = default;

  std::string name_;
  scenes::Scene scene_;
  scenes::ViewcellSpec viewcell_;
  std::unique_ptr<visibility::ViewcellGrid> grid_;
  std::shared_ptr<const scenes::TerrainHeight> terrain_;
  std::unique_ptr<visibility::KdTree> tree_;
  std::unique_ptr<visibility::PvsComputer> computer_;
  std::vector<std::unique_ptr<gl::PvsBackend>> backends_;  // one per worker (null: the CPU raster)
  visibility::CellQueryOptions query_;
  std::unique_ptr<visibility::PvsFile> file_;
  std::vector<scenes::EncodedMesh> geometry_;
  std::unique_ptr<scenes::LevelIndex> level_index_;  // also the levels encoded for the wire
  std::unique_ptr<visibility::EpsilonSuperset> epsilon_;
  vistream::v1::SceneInfo scene_info_;
  std::string pvs_source_;
  PvsStore* store_ = nullptr;
  std::string store_ns_;
  double load_seconds_ = 0.0;
  std::unique_ptr<MaskQueue> masks_;
  std::unique_ptr<PvsScheduler> scheduler_;  // last: its workers read the members above
};

}  // namespace vistream::server
