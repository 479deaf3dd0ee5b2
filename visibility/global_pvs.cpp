#include "visibility/global_pvs.h"

#include <bit>
#include <cstdlib>
#include <limits>

namespace vistream::visibility {

GlobalPvs::GlobalPvs(size_t cells, size_t objects)
    : cells_(cells),
      objects_(objects),
      blocks_per_cell_((objects + kBlockBits - 1) / kBlockBits),
      index_(cells * blocks_per_cell_, 0) {}

bool GlobalPvs::Insert(CellId cell, scenes::ObjectId object) {
  uint32_t& b = index_[Slot(cell, object)];
  if (b == 0) {
    // Indices are 32-bit: more blocks than that would be 256 GiB of them.
    if (blocks_.size() >= std::numeric_limits<uint32_t>::max()) std::abort();
    blocks_.push_back(Block{});
    b = static_cast<uint32_t>(blocks_.size());
  }
  uint64_t& w = blocks_[b - 1].words[object % kBlockBits / 64];
  const uint64_t m = uint64_t{1} << (object % 64);
  const bool added = (w & m) == 0;
  w |= m;
  return added;
}

void GlobalPvs::ResizeObjects(size_t objects) {
  if (objects < objects_) {
    // Clear the bits of the objects dropped from the range, so equality stays meaningful.
    for (size_t c = 0; c < cells_; ++c) {
      for (size_t o = objects; o < objects_; ++o) Erase(static_cast<CellId>(c), static_cast<scenes::ObjectId>(o));
    }
  }
  const size_t per_cell = (objects + kBlockBits - 1) / kBlockBits;
  if (per_cell != blocks_per_cell_) {
    std::vector<uint32_t> index(cells_ * per_cell, 0);
    const size_t keep = std::min(per_cell, blocks_per_cell_);
    for (size_t c = 0; c < cells_; ++c) {
      std::copy_n(index_.begin() + c * blocks_per_cell_, keep, index.begin() + c * per_cell);
    }
    // Blocks past the new range were cleared above and are no longer indexed; they stay
    // allocated, empty (the range only shrinks when a caller asks for it; edits grow it).
    index_.swap(index);
    blocks_per_cell_ = per_cell;
  }
  objects_ = objects;
}

std::vector<scenes::ObjectId> GlobalPvs::Objects(CellId cell) const {
  std::vector<scenes::ObjectId> out;
  const uint32_t* row = index_.data() + size_t{cell} * blocks_per_cell_;
  for (size_t k = 0; k < blocks_per_cell_; ++k) {
    if (row[k] == 0) continue;
    const Block& block = blocks_[row[k] - 1];
    for (size_t i = 0; i < block.words.size(); ++i) {
      for (uint64_t w = block.words[i]; w != 0; w &= w - 1) {
        out.push_back(static_cast<scenes::ObjectId>(k * kBlockBits + i * 64 + std::countr_zero(w)));
      }
    }
  }
  return out;
}

size_t GlobalPvs::Size(CellId cell) const {
  size_t n = 0;
  const uint32_t* row = index_.data() + size_t{cell} * blocks_per_cell_;
  for (size_t k = 0; k < blocks_per_cell_; ++k) {
    if (row[k] == 0) continue;
    for (uint64_t w : blocks_[row[k] - 1].words) n += std::popcount(w);
  }
  return n;
}

uint64_t GlobalPvs::TotalEntries() const {
  // Every indexed block belongs to exactly one cell slot; unindexed ones (after a shrink)
  // were cleared first.
  uint64_t n = 0;
  for (const Block& block : blocks_) {
    for (uint64_t w : block.words) n += std::popcount(w);
  }
  return n;
}

void GlobalPvs::Assign(CellId cell, std::span<const scenes::ObjectId> objects) {
  uint32_t* row = index_.data() + size_t{cell} * blocks_per_cell_;
  for (size_t k = 0; k < blocks_per_cell_; ++k) {
    if (row[k] != 0) blocks_[row[k] - 1] = Block{};
  }
  for (scenes::ObjectId o : objects) Insert(cell, o);
}

bool operator==(const GlobalPvs& a, const GlobalPvs& b) {
  if (a.cells_ != b.cells_ || a.objects_ != b.objects_) return false;
  static constexpr GlobalPvs::Block kEmpty{};
  for (size_t s = 0; s < a.index_.size(); ++s) {
    const GlobalPvs::Block& x = a.index_[s] != 0 ? a.blocks_[a.index_[s] - 1] : kEmpty;
    const GlobalPvs::Block& y = b.index_[s] != 0 ? b.blocks_[b.index_[s] - 1] : kEmpty;
    if (x != y) return false;
  }
  return true;
}

}  // namespace vistream::visibility
