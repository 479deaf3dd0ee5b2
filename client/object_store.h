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

// The viewcell grid as SceneInfo describes it (scene-local metres).
struct GridInfo {
  double cell_size = 0.0, x0 = 0.0, y0 = 0.0, base_z = 0.0, height = 0.0;
  int nx = 0, ny = 0;
  // Each cell's band, z0 then z1, in cell id order (ViewcellGrid.band_z) where cells follow
  // terrain; empty: every cell's band is base_z to base_z + height.
  std::vector<double> band_z;

  static GridInfo From(const vistream::v1::ViewcellGrid& g);
  // The cell whose ground square holds (x, y), as the server decides it (points on a shared
  // edge belong to the cell above and to the right); none outside the grid.
  std::optional<uint32_t> CellAt(double x, double y) const;
  // The cell itself and its up to eight neighbours.
  std::vector<uint32_t> Neighbourhood(uint32_t cell) const;
  bool has_bands() const { return !band_z.empty(); }
  // Cell `cell`'s z range [first, second], scene-local metres. Precondition: cell < nx ny.
  std::pair<double, double> Band(uint32_t cell) const {
    if (band_z.empty()) return {base_z, base_z + height};
    return {band_z[2 * size_t{cell}], band_z[2 * size_t{cell} + 1]};
  }
  // Whether an eye height is inside the band cell `cell`'s PVS holds for (the server's check).
  bool InBand(uint32_t cell, double z) const {
    const auto [z0, z1] = Band(cell);
    return z >= z0 && z <= z1;
  }
};

struct StoredObject {
  ReceivedObject data;
  uint64_t last_drawn_frame = 0;
};

class ObjectStore {
 public:
  explicit ObjectStore(uint64_t memory_budget_bytes) : budget_(memory_budget_bytes) {}

  // Applies the connection's events in order. Returns the ids the store evicted on its own to
  // stay within budget (tell the connection with Forget).
  std::vector<uint32_t> Apply(std::vector<Event> events, std::optional<uint32_t> current_cell);

  bool has_scene_info() const { return scene_info_.has_value(); }
  const vistream::v1::SceneInfo& scene_info() const { return *scene_info_; }
  const GridInfo& grid() const { return grid_; }

  const StoredObject* Find(uint32_t id) const;
  StoredObject* Find(uint32_t id);
  const std::unordered_map<uint32_t, StoredObject>& objects() const { return objects_; }
  // The latest PVS list of `cell`, if the server sent one.
  const std::vector<uint32_t>* Pvs(uint32_t cell) const;
  // Every PVS list held, by cell.
  const std::map<uint32_t, std::vector<uint32_t>>& pvs_lists() const { return pvs_; }
  // Whether `cell`'s PVS list and every object on it are held.
  bool CellComplete(uint32_t cell) const;

  // At most this many masks are held.
  static constexpr size_t kMaxMasks = MaskHoldings::kMaxMasks;
  // Every mask held, by the server's mask id.
  const std::map<uint32_t, EpsilonMaskSet>& masks() const { return masks_.masks(); }
  // The mask a frame at `eye` (scene-local metres) may draw: among held masks whose box holds
  // the eye and all of whose objects are held and pass `ready` (the renderer's Uploaded; none:
  // held is enough), the one with the fewest triangles (ties: the lower mask id). Also whether
  // the eye is in any held mask's box at all.
  MaskChoice ChooseMask(const glm::dvec3& eye, const std::function<bool(uint32_t)>& ready = {}) const;
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
  GridInfo grid_;
  visibility::ViewcellGrid cell_grid_;  // the same grid (GridFromSceneInfo)
  std::unordered_map<uint32_t, StoredObject> objects_;
  std::map<uint32_t, std::vector<uint32_t>> pvs_;
  MaskHoldings masks_;
  std::vector<uint32_t> removed_, added_;
  uint64_t held_bytes_ = 0, max_held_bytes_ = 0;
  uint64_t evicted_by_server_ = 0, evicted_by_budget_ = 0;
  std::optional<std::string> failure_;
  bool bad_data_ = false;
};

}  // namespace vistream::client
