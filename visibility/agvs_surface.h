#pragma once
// The global sampler's surface points (AGVS, Bittner et al. 2009, section 4.3: the
// object-direction and two-point distributions start from "a random point on a random
// object"): a uniform object among those with surface area, then a uniform point of its
// surface, drawn as one choice of a triangle from Walker's alias table over every triangle of
// those objects (Vose's construction) and uniform barycentrics in it. Internal to the sampler
// (agvs_internal.h, agvs_sampling.cpp); a header of its own so that tests can check the
// choice against the weights it must follow.
//
// The table is one entry per triangle, over 100 MB for a city: every lookup is a likely cache
// miss. PickMany resolves many choices at once, prefetching every entry before it is read, so
// that the misses overlap instead of being waited for one after another.

#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/geometric.hpp>

#include "scenes/scene.h"
#include "visibility/silhouette.h"

namespace vistream::visibility::agvs_detail {

class SurfaceTable {
 public:
  struct Entry {
    EdgeTriangle tri;  // frame-relative, single precision like the meshes
    float keep;        // the chance to keep this triangle rather than take its alias
    uint32_t alias;    // index into the table
    scenes::ObjectId object;
  };

  SurfaceTable() = default;
  // objects[o]: the triangles of object o, or empty where o is not to be drawn (deleted, or
  // without surface area). Each object whose triangles have a positive area (as their float
  // edges give it) gets the same chance, shared among its triangles by area.
  explicit SurfaceTable(std::span<const std::span<const EdgeTriangle>> objects) {
    std::vector<double> weight;
    size_t sampleable = 0;
    first_.assign(objects.size(), 0);
    for (scenes::ObjectId id = 0; id < objects.size(); ++id) {
      if (objects[id].empty()) continue;
      ++sampleable;
      const size_t first = weight.size();
      first_[id] = static_cast<uint32_t>(first);
      double sum = 0.0;
      for (const EdgeTriangle& t : objects[id]) {
        entries_.push_back({t, 1.0f, static_cast<uint32_t>(entries_.size()), id});
        weight.push_back(glm::length(glm::cross(glm::dvec3(t.e1), glm::dvec3(t.e2))));
        sum += weight.back();
      }
      if (!(sum > 0.0)) {  // area too small for the float edges to show
        entries_.resize(first);
        weight.resize(first);
        --sampleable;
        continue;
      }
      for (size_t i = first; i < weight.size(); ++i) weight[i] /= sum;
    }
    // Scaled so that the mean weight is 1: each object's triangles sum to n / objects.
    const double scale = static_cast<double>(entries_.size()) / static_cast<double>(std::max<size_t>(sampleable, 1));
    std::vector<uint32_t> small, large;
    for (uint32_t i = 0; i < entries_.size(); ++i) {
      weight[i] *= scale;
      (weight[i] < 1.0 ? small : large).push_back(i);
    }
    while (!small.empty() && !large.empty()) {
      const uint32_t s = small.back(), l = large.back();
      small.pop_back();
      entries_[s].keep = static_cast<float>(weight[s]);
      entries_[s].alias = l;
      weight[l] -= 1.0 - weight[s];
      if (weight[l] < 1.0) {
        large.pop_back();
        small.push_back(l);
      }
    }
    // What is left holds weight 1 up to rounding: always kept.
    for (uint32_t i : small) entries_[i].keep = 1.0f;
    for (uint32_t i : large) entries_[i].keep = 1.0f;
  }

  bool empty() const { return entries_.empty(); }
  size_t size() const { return entries_.size(); }
  const Entry& operator[](uint32_t i) const { return entries_[i]; }
  // Which of its object's triangles entry i is (the index into the triangles given for it).
  uint32_t TriangleOf(uint32_t i) const { return i - first_[entries_[i].object]; }

  // The entry that `x`, uniform in [0, size()), picks: its integer part the column, its
  // fraction whether to keep the column or take its alias. Precondition: !empty().
  uint32_t Pick(double x) const {
    const uint32_t column = Column(x);
    const Entry& e = entries_[column];
    return x - static_cast<double>(column) >= e.keep ? e.alias : column;
  }

  // picks[i] = Pick(xs[i]) for every i, with each entry read prefetched first. Precondition:
  // !empty(), picks.size() == xs.size().
  void PickMany(std::span<const double> xs, std::span<uint32_t> picks) const {
    for (size_t i = 0; i < xs.size(); ++i) {
      picks[i] = Column(xs[i]);
      Prefetch(picks[i]);
    }
    for (size_t i = 0; i < xs.size(); ++i) {
      const Entry& e = entries_[picks[i]];
      if (xs[i] - static_cast<double>(picks[i]) >= e.keep) {
        picks[i] = e.alias;
        Prefetch(picks[i]);
      }
    }
  }

  // Asks for entry i's cache lines (an entry may straddle two).
  void Prefetch(uint32_t i) const {
    const char* p = reinterpret_cast<const char*>(&entries_[i]);
    __builtin_prefetch(p);
    __builtin_prefetch(p + sizeof(Entry) - 1);
  }

 private:
  uint32_t Column(double x) const {
    return static_cast<uint32_t>(std::min(static_cast<size_t>(x), entries_.size() - 1));
  }

  std::vector<Entry> entries_;
  std::vector<uint32_t> first_;  // per object, its first triangle's entry
};

}  // namespace vistream::visibility::agvs_detail
