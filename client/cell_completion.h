#pragma once
// When a viewcell is complete (DESIGN.md "Server and client": a *stall* is a frame drawn inside
// a viewcell that is not): its PVS list is held and so is every object on it. The rule is
// stated once here, as CellComplete (for a holder that can look at its objects) and as
// CellCompletion (the same rule kept up to date message by message, with arrival times, for
// holders that are asked often: the scripted sessions of client/session_stream.h and the
// simulator's client). "Held" is the caller's word: received, or received and uploaded for a
// client that draws (client/frame_loop.cpp, client/cell_margins.h, client/minimap.cpp).

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

namespace vistream::client {

// The objects of `list` that `held` says are not held.
template <typename Held>
size_t MissingObjects(const std::vector<uint32_t>& list, Held&& held) {
  size_t n = 0;
  for (uint32_t o : list) n += held(o) ? 0 : 1;
  return n;
}

// The objects of `list` drawn at a coarser level of detail than the list asks (a coarse frame
// draws them until the finer level arrives; issue 45): `levels` one per object of `list` (the
// level each needs, 0 full), `held_level(o)` the level held, or none when not held.
template <typename HeldLevel>
size_t CoarseObjects(const std::vector<uint32_t>& list, const std::vector<uint32_t>& levels, HeldLevel&& held_level) {
  size_t n = 0;
  for (size_t k = 0; k < list.size() && k < levels.size(); ++k) {
    const std::optional<uint32_t> held = held_level(list[k]);
    n += held.has_value() && *held > levels[k] ? 1 : 0;
  }
  return n;
}

// Whether a cell whose PVS list is `list` (null: not held) is complete: the list is held and
// `held` holds for every object on it.
template <typename Held>
bool CellComplete(const std::vector<uint32_t>* list, Held&& held) {
  if (list == nullptr) return false;
  for (uint32_t o : *list) {
    if (!held(o)) return false;
  }
  return true;
}

// CellComplete kept up to date as messages arrive: objects held with their arrival times, the
// latest PVS list of each cell, and per cell how many of its objects are missing, so that each
// question is answered in constant time. Times are the caller's seconds (steady or simulated),
// never decreasing from one call to the next. Object ids and cells are whatever the server
// sent; nothing is assumed dense.
class CellCompletion {
 public:
  struct Object {
    double arrival_s = 0.0;  // the latest arrival (a finer level of a held object does not move it)
    bool held = false;       // now
    bool ever = false;       // at some time
    uint32_t level = 0;      // the level of detail held (0: full; issue 45)
  };

  // Hears of every cell that becomes complete (a list arriving whole, or the last object of
  // a list arriving), with the time it did; may be empty.
  std::function<void(uint32_t cell, double t_s)> on_complete;

  // The PVS list of `cell` (object ids, distinct) arrived at `t_s`, replacing an earlier one;
  // `levels`, when not empty, the level each object needs there (ViewcellPvs.object_levels,
  // one per object; empty: full detail); `cluster_ids` and `cluster_levels` (one per id) the
  // clusters chosen for the cell and the level each needs (ViewcellPvs.cluster_ids: an object
  // of the list a held chosen cluster stands for is complete when the cluster is held at its
  // level or finer, drawable when it is held at all).
  void SetList(uint32_t cell, std::span<const uint32_t> objects, double t_s, std::span<const uint32_t> levels = {},
               std::span<const uint32_t> cluster_ids = {}, std::span<const uint32_t> cluster_levels = {});
  // The caller forgot `cell`'s list (nothing: no list is held).
  void DropList(uint32_t cell);
  // Object `id` arrived at `t_s` at `level` (0: full). Again at the same level while held: its
  // arrival moves to `t_s`; at another level while held: the level changes, the arrival stays
  // (a level replaces the one held, which was drawable all along). Returns true the first time
  // the object is held in this tracker's life.
  bool Arrive(uint32_t id, double t_s, uint32_t level = 0);
  // The caller dropped object `id` (not held: nothing happens).
  void Drop(uint32_t id);
  // Cluster `id` arrived at `t_s` at `level` (>= 1), standing for `objects` (ClusterGeometry:
  // ascending); it replaces a level held.
  void ArriveCluster(uint32_t id, double t_s, uint32_t level, std::span<const uint32_t> objects);
  // The caller dropped cluster `id` (not held: nothing happens).
  void DropCluster(uint32_t id);
  struct Cluster {
    uint32_t level = 0;      // held (>= 1)
    double arrival_s = 0.0;  // the latest arrival
    std::vector<uint32_t> objects;
  };
  // Cluster `id` while held, else null.
  const Cluster* HeldCluster(uint32_t id) const;
  // The held cluster that `cell`'s list chose for object `o` (drawn in its place), or none.
  std::optional<uint32_t> CoveringCluster(uint32_t cell, uint32_t o) const;
  // The clusters `cell`'s list chose, with the level each needs (empty without a list).
  std::span<const std::pair<uint32_t, uint32_t>> ListClusters(uint32_t cell) const;

  // The object's entry while held, else null.
  const Object* Held(uint32_t id) const;
  // Calls fn(id, object) for every object held now, in no particular order.
  template <typename Fn>
  void ForEachHeld(Fn&& fn) const {
    for (const auto& [id, e] : entries_) {
      if (e.state.held) fn(id, e.state);
    }
  }
  // The list of `cell`, or null when none is held.
  const std::vector<uint32_t>* List(uint32_t cell) const;
  // Whether `cell` is complete (CellComplete with "arrived and not dropped").
  bool Complete(uint32_t cell) const;
  // The objects of `cell`'s list not held (0 without a list).
  size_t Missing(uint32_t cell) const;
  // The objects of `cell`'s list held at a coarser level than the list asks (drawn until the
  // finer one arrives: a coarse frame; 0 without a list).
  size_t Coarse(uint32_t cell) const;
  // When `cell` is complete: the latest arrival among its list and the objects it names.
  std::optional<double> CompleteAt(uint32_t cell) const;

 private:
  struct CellList {
    std::vector<uint32_t> objects;
    std::vector<uint32_t> levels;                          // one per object (0 without levels)
    std::vector<std::pair<uint32_t, uint32_t>> clusters;   // chosen (cluster, level), ascending
    std::unordered_map<uint32_t, uint32_t> cover;          // object -> the held chosen cluster standing for it
    size_t missing = 0;
    size_t coarse = 0;
    double latest_s = 0.0;  // the latest arrival among the list, its held objects and clusters
  };
  struct ObjectEntry {
    Object state;
    std::vector<std::pair<uint32_t, uint32_t>> cells;  // cells whose list names it, and the level each needs
  };
  // How an object of a list stands there: not drawable, drawn coarser than needed, complete.
  enum class Standing : uint8_t { kMissing, kCoarse, kComplete };
  Standing StandingOf(const CellList& list, uint32_t o, uint32_t needed, const Object& state) const;
  // Rebuilds `cell`'s cover and counts after a cluster event at `t_s`.
  void Recount(uint32_t cell, double t_s);
  std::unordered_map<uint32_t, ObjectEntry> entries_;  // every object held or named by a list
  std::unordered_map<uint32_t, CellList> lists_;
  std::unordered_map<uint32_t, Cluster> clusters_;                      // held clusters
  std::unordered_map<uint32_t, std::vector<uint32_t>> cluster_cells_;  // cluster -> cells whose list chose it
};

}  // namespace vistream::client
