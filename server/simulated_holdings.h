#pragma once
// What the simulator's modelled client holds: objects by id with their arrival times, and the
// PVS lists it received per viewcell; when a viewcell became complete (its list and every
// object of it held). Asked after every message while the client waits to walk, and at every
// crossing, so it keeps per-cell progress instead of scanning whole lists (the radius
// baseline's lists hold the whole city). Times in simulated seconds.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

#include "visibility/viewcell_grid.h"

namespace vistream::server {

class SimulatedHoldings {
 public:
  struct Held {
    double arrival_s = 0.0;
    uint64_t triangles = 0;
    bool held = false;  // now
    bool ever = false;  // at some time of the run
  };

  // Object `id` arrived at `t` with `triangles`; a later arrival of a held object replaces it.
  // Returns true when the object is held for the first time in the run.
  bool Receive(uint32_t id, double t, uint64_t triangles);
  // The client dropped `id` (not held: nothing happens).
  void Evict(uint32_t id);
  // The PVS list of `cell` (object ids, any order) arrived at `t`, replacing an earlier one.
  void SetList(visibility::CellId cell, std::span<const uint32_t> objects, double t);

  // The object's entry while held, else null.
  const Held* Of(uint32_t id) const { return id < held_.size() && held_[id].held ? &held_[id] : nullptr; }
  // Every object id below this bound may be held (for scanning all of them).
  uint32_t IdBound() const { return static_cast<uint32_t>(held_.size()); }
  // The list of `cell`, or null when none arrived.
  const std::vector<uint32_t>* ListOf(visibility::CellId cell) const {
    auto it = lists_.find(cell);
    return it == lists_.end() ? nullptr : &it->second.objects;
  }
  // The latest arrival among `cell`'s list and the objects it names, when all of them are
  // held now; nullopt otherwise.
  std::optional<double> CompleteAt(visibility::CellId cell);

 private:
  struct List {
    std::vector<uint32_t> objects;
    double arrival_s = 0.0;
    // How many of the first objects are known held, and the latest of their arrivals. Valid
    // while nothing held is evicted or received again (those reset every list's).
    size_t prefix_held = 0;
    double prefix_arrival_s = 0.0;
  };
  void ResetPrefixes();

  std::vector<Held> held_;  // by object id
  std::unordered_map<visibility::CellId, List> lists_;
  bool prefixes_dirty_ = false;  // some list's prefix is non-empty (a reset has work to do)
};

}  // namespace vistream::server
