#pragma once
// The potentially visible sets of every viewcell of a grid at once. What global visibility
// sampling fills in, and what a PVS file stores.
//
// Two levels, so that memory follows the entries rather than cells × objects: each cell's
// object range is cut into blocks of 512 ids (one 64-byte line of bits), and a cell holds only
// the blocks it has an object in, in block order, with one bit per block saying which it
// holds. London (16,380 cells, 146,325 objects) took 300 MB as one flat bitset per cell; the
// bits saying which blocks a cell holds take 40 bytes a cell there (under 1 MB for the city,
// so they stay in cache) and a block 64 bytes. A lookup reads those bits and one block: one
// likely cache miss, as with the flat bitset.

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
    const int64_t at = Find(cell, object / kBlockBits);
    return at >= 0 && ((blocks_[cell][at].words[object % kBlockBits / 64] >> (object % 64)) & 1u);
  }
  // Asks for the cache line Contains(cell, object) will read, if the cell holds a block for
  // the object: a caller about to test many (cell, object) pairs prefetches them all first,
  // so that their misses overlap.
  void Prefetch(CellId cell, scenes::ObjectId object) const {
    const int64_t at = Find(cell, object / kBlockBits);
    if (at >= 0) __builtin_prefetch(&blocks_[cell][at]);
  }
  // Returns true when the object was not yet in the cell's set. Not thread-safe with any
  // other call on the same cell (it may add a block).
  bool Insert(CellId cell, scenes::ObjectId object);
  void Erase(CellId cell, scenes::ObjectId object) {
    const int64_t at = Find(cell, object / kBlockBits);
    if (at >= 0) blocks_[cell][at].words[object % kBlockBits / 64] &= ~(uint64_t{1} << (object % 64));
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

  // Bytes held: the bits saying which blocks each cell holds, the cells' block lists and their
  // blocks (for reports: the sets' memory, allocator overhead aside).
  size_t MemoryBytes() const;

  // Equal when every cell holds the same objects (however its blocks were allocated).
  friend bool operator==(const GlobalPvs& a, const GlobalPvs& b);

 private:
  // A cache line each (aligned so that a lookup touches one line).
  struct alignas(64) Block {
    std::array<uint64_t, kBlockBits / 64> words{};
    bool operator==(const Block&) const = default;
  };
  static int Popcount(uint64_t x) {
    // Without -mpopcnt, std::popcount is a library call; this is a few instructions.
    x = x - ((x >> 1) & 0x5555555555555555ULL);
    x = (x & 0x3333333333333333ULL) + ((x >> 2) & 0x3333333333333333ULL);
    x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0fULL;
    return static_cast<int>((x * 0x0101010101010101ULL) >> 56);
  }
  // Where block `k` lies in the cell's list, or -1 if the cell has no object of it.
  int64_t Find(CellId cell, size_t k) const {
    const uint64_t* held = held_.data() + size_t{cell} * held_words_;
    const uint64_t bit = uint64_t{1} << (k % 64), w = held[k / 64];
    if ((w & bit) == 0) return -1;
    int64_t rank = Popcount(w & (bit - 1));
    for (size_t i = 0; i < k / 64; ++i) rank += Popcount(held[i]);
    return rank;
  }

  size_t cells_ = 0, objects_ = 0, blocks_per_cell_ = 0, held_words_ = 0;
  std::vector<uint64_t> held_;               // cells × held_words_: bit k set when the cell holds block k
  std::vector<std::vector<Block>> blocks_;   // per cell, the blocks it holds, by block number
};

}  // namespace vistream::visibility
