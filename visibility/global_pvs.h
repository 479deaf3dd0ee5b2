#pragma once
// The potentially visible sets of every viewcell of a grid at once: one bitset of objects per
// cell. What global visibility sampling fills in, and what a PVS file stores.

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>

#include "scenes/scene.h"
#include "visibility/viewcell_grid.h"

namespace vistream::visibility {

class GlobalPvs {
 public:
  GlobalPvs() = default;
  GlobalPvs(size_t cells, size_t objects);

  size_t cell_count() const { return cells_; }
  size_t object_count() const { return objects_; }
  // Preconditions for all below: cell < cell_count(), object < object_count().
  bool Contains(CellId cell, scenes::ObjectId object) const {
    return (bits_[cell * words_ + object / 64] >> (object % 64)) & 1u;
  }
  // Returns true when the object was not yet in the cell's set.
  bool Insert(CellId cell, scenes::ObjectId object) {
    uint64_t& w = bits_[cell * words_ + object / 64];
    const uint64_t m = uint64_t{1} << (object % 64);
    const bool added = (w & m) == 0;
    w |= m;
    return added;
  }
  void Erase(CellId cell, scenes::ObjectId object) {
    bits_[cell * words_ + object / 64] &= ~(uint64_t{1} << (object % 64));
  }
  // Grows the object range (new objects are in no set).
  void ResizeObjects(size_t objects);

  // The cell's objects, ascending.
  std::vector<scenes::ObjectId> Objects(CellId cell) const;
  size_t Size(CellId cell) const;
  // Sum of the set sizes over all cells.
  uint64_t TotalEntries() const;
  double MeanSize() const { return cells_ == 0 ? 0.0 : static_cast<double>(TotalEntries()) / cells_; }
  // Sets `cell` to `objects` (ids < object_count()).
  void Assign(CellId cell, std::span<const scenes::ObjectId> objects);

  friend bool operator==(const GlobalPvs&, const GlobalPvs&) = default;

 private:
  size_t cells_ = 0, objects_ = 0, words_ = 0;
  std::vector<uint64_t> bits_;
};

}  // namespace vistream::visibility
