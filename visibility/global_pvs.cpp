#include "visibility/global_pvs.h"

#include <algorithm>

namespace vistream::visibility {

namespace {
size_t BlocksFor(size_t objects) { return (objects + GlobalPvs::kBlockBits - 1) / GlobalPvs::kBlockBits; }
}  // namespace

GlobalPvs::GlobalPvs(size_t cells, size_t objects)
    : cells_(cells),
      objects_(objects),
      blocks_per_cell_(BlocksFor(objects)),
      held_words_((blocks_per_cell_ + 63) / 64),
      held_(cells * held_words_, 0),
      blocks_(cells) {}

bool GlobalPvs::Insert(CellId cell, scenes::ObjectId object) {
  const size_t k = object / kBlockBits;
  int64_t at = Find(cell, k);
  if (at < 0) {
    uint64_t* held = held_.data() + size_t{cell} * held_words_;
    held[k / 64] |= uint64_t{1} << (k % 64);
    at = Find(cell, k);
    blocks_[cell].insert(blocks_[cell].begin() + at, Block{});
  }
  uint64_t& w = blocks_[cell][at].words[object % kBlockBits / 64];
  const uint64_t m = uint64_t{1} << (object % 64);
  const bool added = (w & m) == 0;
  w |= m;
  return added;
}

void GlobalPvs::ResizeObjects(size_t objects) {
  const size_t per_cell = BlocksFor(objects);
  if (objects < objects_) {
    // Clear the bits of the objects dropped from the range, so equality stays meaningful.
    for (size_t c = 0; c < cells_; ++c) {
      for (size_t o = objects; o < std::min(objects_, per_cell * kBlockBits); ++o) {
        Erase(static_cast<CellId>(c), static_cast<scenes::ObjectId>(o));
      }
    }
  }
  if (per_cell != blocks_per_cell_) {
    const size_t words = (per_cell + 63) / 64;
    std::vector<uint64_t> held(cells_ * words, 0);
    for (size_t c = 0; c < cells_; ++c) {
      size_t kept = 0;
      for (size_t k = 0; k < std::min(per_cell, blocks_per_cell_); ++k) {
        if ((held_[c * held_words_ + k / 64] >> (k % 64)) & 1u) {
          held[c * words + k / 64] |= uint64_t{1} << (k % 64);
          ++kept;
        }
      }
      blocks_[c].resize(kept);  // blocks past the new range are the list's last ones
    }
    held_.swap(held);
    held_words_ = words;
    blocks_per_cell_ = per_cell;
  }
  objects_ = objects;
}

std::vector<scenes::ObjectId> GlobalPvs::Objects(CellId cell) const {
  std::vector<scenes::ObjectId> out;
  const uint64_t* held = held_.data() + size_t{cell} * held_words_;
  size_t at = 0;
  for (size_t i = 0; i < held_words_; ++i) {
    for (uint64_t h = held[i]; h != 0; h &= h - 1) {
      const size_t k = i * 64 + static_cast<size_t>(Popcount((h & -h) - 1));
      const Block& block = blocks_[cell][at++];
      for (size_t j = 0; j < block.words.size(); ++j) {
        for (uint64_t w = block.words[j]; w != 0; w &= w - 1) {
          out.push_back(static_cast<scenes::ObjectId>(k * kBlockBits + j * 64 + Popcount((w & -w) - 1)));
        }
      }
    }
  }
  return out;
}

size_t GlobalPvs::Size(CellId cell) const {
  size_t n = 0;
  for (const Block& block : blocks_[cell]) {
    for (uint64_t w : block.words) n += Popcount(w);
  }
  return n;
}

uint64_t GlobalPvs::TotalEntries() const {
  uint64_t n = 0;
  for (CellId c = 0; c < cells_; ++c) n += Size(c);
  return n;
}

void GlobalPvs::Assign(CellId cell, std::span<const scenes::ObjectId> objects) {
  for (Block& block : blocks_[cell]) block = Block{};
  for (scenes::ObjectId o : objects) Insert(cell, o);
}

size_t GlobalPvs::MemoryBytes() const {
  size_t n = held_.capacity() * sizeof(uint64_t) + blocks_.capacity() * sizeof(std::vector<Block>);
  for (const std::vector<Block>& list : blocks_) n += list.capacity() * sizeof(Block);
  return n;
}

bool operator==(const GlobalPvs& a, const GlobalPvs& b) {
  if (a.cells_ != b.cells_ || a.objects_ != b.objects_) return false;
  static constexpr GlobalPvs::Block kEmpty{};
  for (CellId c = 0; c < a.cells_; ++c) {
    for (size_t k = 0; k < a.blocks_per_cell_; ++k) {
      const int64_t i = a.Find(c, k), j = b.Find(c, k);
      const GlobalPvs::Block& x = i >= 0 ? a.blocks_[c][i] : kEmpty;
      const GlobalPvs::Block& y = j >= 0 ? b.blocks_[c][j] : kEmpty;
      if (x != y) return false;
    }
  }
  return true;
}

}  // namespace vistream::visibility
