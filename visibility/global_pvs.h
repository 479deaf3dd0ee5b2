#pragma once
// The potentially visible sets of every viewcell of a grid at once. What global visibility
// sampling fills in, and what a PVS file stores.
//
// Two levels, so that memory follows the entries rather than cells × objects: each cell's
// object range is cut into blocks of 512 ids (one 64-byte line of bits), and a cell holds only
// the blocks it has an object in. London (16,380 cells, 146,325 objects) took 300 MB as one
// flat bitset per cell; a block index costs 4 bytes per cell and 512 ids (19 MB there) and a
// block 64 bytes. A lookup reads the index slot and the block: two loads where the flat set
// read one, but both from far less memory (see PrefetchIndex for the sampler's way of
// overlapping them).

#include <array>
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
  static constexpr size_t kBlockBits = 512;  // ids per block: one cache line of bits

  GlobalPvs() = default;
  // `cells` empty sets over ids [0, objects).
  GlobalPvs(size_t cells, size_t objects);

  size_t cell_count() const { return cells_; }
  size_t object_count() const { return objects_; }
  // Preconditions for all below: cell < cell_count(), object < object_count().
  bool Contains(CellId cell, scenes::ObjectId object) const {
    const uint32_t b = index_[Slot(cell, object)];
    return b != 0 && ((blocks_[b - 1].words[object % kBlockBits / 64] >> (object % 64)) & 1u);
  }
  // Start loading what Contains(cell, object) reads, so that a caller about to test many
  // cells waits for their cache misses together rather than one after another: first
  // PrefetchIndex for all of them, then PrefetchBlock (which reads the index slot) for all,
  // then Contains. No effect on the set; same preconditions as Contains.
  void PrefetchIndex(CellId cell, scenes::ObjectId object) const { __builtin_prefetch(&index_[Slot(cell, object)]); }
  void PrefetchBlock(CellId cell, scenes::ObjectId object) const {
    const uint32_t b = index_[Slot(cell, object)];
    if (b != 0) __builtin_prefetch(&blocks_[b - 1].words[object % kBlockBits / 64]);
  }
  // Returns true when the object was not yet in the cell's set. Not thread-safe with any
  // other call (it may add a block).
  bool Insert(CellId cell, scenes::ObjectId object);
  void Erase(CellId cell, scenes::ObjectId object) {
    const uint32_t b = index_[Slot(cell, object)];
    if (b != 0) blocks_[b - 1].words[object % kBlockBits / 64] &= ~(uint64_t{1} << (object % 64));
  }
  // Sets the object range to [0, objects): new objects are in no set, objects past it leave
  // every set.
  void ResizeObjects(size_t objects);

  // The cell's objects, ascending.
  std::vector<scenes::ObjectId> Objects(CellId cell) const;
  size_t Size(CellId cell) const;
  // Sum of the set sizes over all cells.
  uint64_t TotalEntries() const;
  double MeanSize() const { return cells_ == 0 ? 0.0 : static_cast<double>(TotalEntries()) / cells_; }
  // Sets `cell` to `objects` (ids < object_count()).
  void Assign(CellId cell, std::span<const scenes::ObjectId> objects);

  // Bytes held by the index and the blocks (for reports: the sets' memory).
  size_t MemoryBytes() const { return index_.capacity() * sizeof(uint32_t) + blocks_.capacity() * sizeof(Block); }

  // Equal when every cell holds the same objects (however the blocks were allocated).
  friend bool operator==(const GlobalPvs& a, const GlobalPvs& b);

 private:
  // A cache line each (aligned so that a lookup touches one line).
  struct alignas(64) Block {
    std::array<uint64_t, kBlockBits / 64> words{};
    bool operator==(const Block&) const = default;
  };
  size_t Slot(CellId cell, scenes::ObjectId object) const { return size_t{cell} * blocks_per_cell_ + object / kBlockBits; }

  size_t cells_ = 0, objects_ = 0, blocks_per_cell_ = 0;
  // cells × blocks_per_cell_ slots: 0 where the cell has no object of that block, else the
  // block's index in blocks_ plus one.
  std::vector<uint32_t> index_;
  std::vector<Block> blocks_;
};

}  // namespace vistream::visibility
