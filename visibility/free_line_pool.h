#pragma once
// The free lines found so far from one viewcell, indexed by direction. A line that proved one
// kd node visible (the ground track of a free ray on some shaft's ceiling, section 5 of
// Koltun, Chrysanthou, Cohen-Or 2001) often runs through the same gap to another node: traced
// on that node's own ceiling it proves the node visible at the cost of one ray, where the
// node's blockers would cost its whole shaft. Only a speed-up: a line proves nothing until
// traced again.

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

namespace vistream::visibility {

// A line in the scene's xy plane, through `from` (on A's side) and `to` (on B's side): the
// ground track of a ray that a planar test found free.
struct FreeLine {
  glm::dvec2 from{0.0}, to{0.0};
  bool valid = false;
};

class FreeLinePool {
 public:
  void Clear();
  // Keeps `line` (scene-local metres); an invalid line or one with from == to is ignored.
  void Add(const FreeLine& line);
  size_t size() const { return lines_.size(); }

  // The lines whose direction (from -> to) lies in the cone from direction d0 to d1 (scene
  // xy, any lengths; the cone is the one of the two arcs between them that is shorter than a
  // half turn), most recently added first, appended to *out as indices for line(). A few
  // outside the cone may come too (the directions are kept in buckets of 1/kBuckets turn):
  // the caller tests each line anyway.
  void Candidates(const glm::dvec2& d0, const glm::dvec2& d1, std::vector<uint32_t>* out) const;
  const FreeLine& line(uint32_t index) const { return lines_[index]; }

  static constexpr int kBuckets = 1024;

 private:
  std::vector<FreeLine> lines_;
  std::vector<std::vector<uint32_t>> buckets_ = std::vector<std::vector<uint32_t>>(kBuckets);  // ascending
};

}  // namespace vistream::visibility
