#include "visibility/global_pvs.h"

#include <bit>

namespace vistream::visibility {

GlobalPvs::GlobalPvs(size_t cells, size_t objects)
    : cells_(cells), objects_(objects), words_((objects + 63) / 64), bits_(cells * words_, 0) {}

void GlobalPvs::ResizeObjects(size_t objects) {
  const size_t words = (objects + 63) / 64;
  if (words != words_) {
    std::vector<uint64_t> bits(cells_ * words, 0);
    const size_t keep = std::min(words, words_);
    for (size_t c = 0; c < cells_; ++c) {
      std::copy_n(bits_.begin() + c * words_, keep, bits.begin() + c * words);
    }
    bits_.swap(bits);
    words_ = words;
  }
  if (objects < objects_) {
    // Clear the bits of the objects dropped from the range, so equality stays meaningful.
    for (size_t c = 0; c < cells_; ++c) {
      for (size_t o = objects; o < std::min(objects_, words_ * 64); ++o) Erase(static_cast<CellId>(c), static_cast<scenes::ObjectId>(o));
    }
  }
  objects_ = objects;
}

std::vector<scenes::ObjectId> GlobalPvs::Objects(CellId cell) const {
  std::vector<scenes::ObjectId> out;
  const uint64_t* w = bits_.data() + cell * words_;
  for (size_t i = 0; i < words_; ++i) {
    for (uint64_t b = w[i]; b != 0; b &= b - 1) {
      out.push_back(static_cast<scenes::ObjectId>(i * 64 + std::countr_zero(b)));
    }
  }
  return out;
}

size_t GlobalPvs::Size(CellId cell) const {
  size_t n = 0;
  const uint64_t* w = bits_.data() + cell * words_;
  for (size_t i = 0; i < words_; ++i) n += std::popcount(w[i]);
  return n;
}

uint64_t GlobalPvs::TotalEntries() const {
  uint64_t n = 0;
  for (uint64_t w : bits_) n += std::popcount(w);
  return n;
}

void GlobalPvs::Assign(CellId cell, std::span<const scenes::ObjectId> objects) {
  std::fill_n(bits_.begin() + cell * words_, words_, 0);
  for (scenes::ObjectId o : objects) Insert(cell, o);
}

}  // namespace vistream::visibility
