#pragma once
// The client's local copy of what the server streamed (DESIGN.md "Server and client"): decoded
// objects within a memory budget, the PVS list of each viewcell it was sent, and the ε-masks of
// the neighbourhoods around the eye. The render loop owns it and feeds it the connection's
// events; nothing here waits.
//
// Masks: held and chosen by the client model's rule (client/mask_holdings.h): kept while their
// cell is the current cell or one of its eight neighbours, at most kMaxMasks (the oldest dropped
// first); a frame may draw one once every object it lists is held (ChooseMask).
//
// Memory: the server keeps the client within Hello.memory_budget_bytes by the same accounting
// (24 bytes a vertex, 4 an index) and sends Evict hints for objects outside the current and
// adjacent PVSs; the store obeys them. Should it still be over budget, it evicts on its own:
// objects outside the current and adjacent PVSs first (least recently drawn first), then
// objects of adjacent cells only; never the current cell's.

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <glm/vec3.hpp>

#include "client/connection.h"
#include "client/mask_holdings.h"
#include "proto/walkthrough.pb.h"
#include "visibility/viewcell_grid.h"

namespace vistream::client {

struct StoredObject {
  ReceivedObject data;
  uint64_t last_drawn_frame = 0;
};

// A cluster level held (issue 45): drawn as pieces, one per object of a list that chooses it.
struct StoredCluster {
  ReceivedCluster data;
  // Each piece's bounds (scene-local metres), one per data.objects; a piece without triangles
  // has an empty box at the origin.
  std::vector<std::pair<glm::dvec3, glm::dvec3>> piece_bounds;
};

class ObjectStore {
 public:
  explicit ObjectStore(uint64_t memory_budget_bytes) : budget_(memory_budget_bytes) {}

  // Applies the connection's events in order. Returns the ids the store evicted on its own to
  // stay within budget (tell the connection with Forget).
  std::vector<uint32_t> Apply(std::vector<Event> events, std::optional<uint32_t> current_cell);

  bool has_scene_info() const { return scene_info_.has_value(); }
  const vistream::v1::SceneInfo& scene_info() const { return *scene_info_; }
  // The viewcell grid SceneInfo describes (proto/scene_info.h GridFromSceneInfo): the server's
  // cells, ids and bands; empty before SceneInfo.
  const visibility::ViewcellGrid& grid() const { return grid_; }

  const StoredObject* Find(uint32_t id) const;
  StoredObject* Find(uint32_t id);
  const std::unordered_map<uint32_t, StoredObject>& objects() const { return objects_; }
  // The latest PVS list of `cell`, if the server sent one.
  const std::vector<uint32_t>* Pvs(uint32_t cell) const;
  // Every PVS list held, by cell.
  const std::map<uint32_t, std::vector<uint32_t>>& pvs_lists() const { return pvs_; }
  // With levels of detail (issue 45): the level each object of `cell`'s list needs there
  // (ViewcellPvs.object_levels, one per object); null without levels or without the list.
  const std::vector<uint32_t>* PvsLevels(uint32_t cell) const;
  // Whether `cell`'s PVS list and every object on it are held (an object a held cluster the list
  // chose stands for counts as held: ViewcellPvs.cluster_ids' rule).
  bool CellComplete(uint32_t cell) const;

  // Cluster levels (issue 45): those held, by cluster id.
  const std::unordered_map<uint32_t, StoredCluster>& clusters() const { return clusters_; }
  const StoredCluster* FindCluster(uint32_t id) const;
  // The clusters `cell`'s list chose, with the level each needs there (none: empty).
  const std::vector<std::pair<uint32_t, uint32_t>>* PvsClusters(uint32_t cell) const;
  // The held cluster `cell`'s list chose that stands for object `o` there (drawn as its piece),
  // or none; and `o`'s position among that cluster's objects.
  std::optional<std::pair<uint32_t, size_t>> CoveringCluster(uint32_t cell, uint32_t o) const;
  // Cluster ids stored or removed since the last call: the renderer uploads or frees them.
  std::vector<uint32_t> TakeAddedClusters();
  std::vector<uint32_t> TakeRemovedClusters();

  // At most this many masks are held.
  static constexpr size_t kMaxMasks = MaskHoldings::kMaxMasks;
  // Every mask held, by the server's mask id.
  const std::map<uint32_t, EpsilonMaskSet>& masks() const { return masks_.masks(); }
  // The mask a frame at `eye` (scene-local metres) may draw: among held masks whose box holds
  // the eye and all of whose objects are held and pass `ready` (the renderer's Uploaded; none:
  // held is enough), the one with the fewest triangles (ties: the lower mask id). Also whether
  // the eye is in any held mask's box at all.
  // An object a held cluster chosen by the mask's cell's list stands for is held when
  // `cluster_ready` (the renderer's ClusterUploaded; none: held is enough) says so of the cluster.
  MaskChoice ChooseMask(const glm::dvec3& eye, const std::function<bool(uint32_t)>& ready = {},
                        const std::function<bool(uint32_t)>& cluster_ready = {}) const;
  // Keys (EpsilonMaskSet::key) of masks dropped or replaced since the last call: the renderer
  // frees what it built for them.
  std::vector<uint64_t> TakeDroppedMasks();

  // Ids removed since the last call (by Evict hints, budget, or replaced): the renderer frees
  // their GPU buffers.
  std::vector<uint32_t> TakeRemoved();
  // Ids stored since the last call: the renderer uploads them.
  std::vector<uint32_t> TakeAdded();

  uint64_t held_bytes() const { return held_bytes_; }
  uint64_t max_held_bytes() const { return max_held_bytes_; }
  uint64_t budget() const { return budget_; }
  uint64_t evicted_by_server() const { return evicted_by_server_; }
  uint64_t evicted_by_budget() const { return evicted_by_budget_; }
  // Why nothing more can be trusted: the session ended for good (its status), or the server sent
  // data that does not decode ("mask 7 (cell 12): ..." with the decoder's message). None: fine.
  std::optional<std::string> failure() const { return failure_; }
  // Whether failure() is bad data from the server rather than the session's end.
  bool failure_is_bad_data() const { return bad_data_; }

 private:
  void Remove(uint32_t id);
  std::vector<uint32_t> EnforceBudget(std::optional<uint32_t> current_cell);
  void AddMask(const vistream::v1::EpsilonMask& m);

  uint64_t budget_;
  std::optional<vistream::v1::SceneInfo> scene_info_;
  visibility::ViewcellGrid grid_;
  std::unordered_map<uint32_t, StoredObject> objects_;
  std::map<uint32_t, std::vector<uint32_t>> pvs_;
  std::map<uint32_t, std::vector<uint32_t>> pvs_levels_;  // cells whose list came with levels
  std::map<uint32_t, std::vector<std::pair<uint32_t, uint32_t>>> pvs_clusters_;  // cells whose list chose clusters
  std::unordered_map<uint32_t, StoredCluster> clusters_;
  std::vector<uint32_t> added_clusters_, removed_clusters_;
  void RemoveCluster(uint32_t id);
  MaskHoldings masks_;
  std::vector<uint32_t> removed_, added_;
  uint64_t held_bytes_ = 0, max_held_bytes_ = 0;
  uint64_t evicted_by_server_ = 0, evicted_by_budget_ = 0;
  std::optional<std::string> failure_;
  bool bad_data_ = false;
};

}  // namespace vistream::client
