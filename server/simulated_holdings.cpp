#include "server/simulated_holdings.h"

#include <algorithm>

namespace vistream::server {

bool SimulatedHoldings::Receive(uint32_t id, double t, uint64_t triangles) {
  if (id >= held_.size()) held_.resize(static_cast<size_t>(id) + 1);
  Held& h = held_[id];
  // A later arrival of an object a prefix may have counted moves that prefix's time.
  if (h.held) ResetPrefixes();
  const bool first = !h.ever;
  h = Held{t, triangles, true, true};
  return first;
}

void SimulatedHoldings::Evict(uint32_t id) {
  if (id >= held_.size() || !held_[id].held) return;
  held_[id].held = false;
  ResetPrefixes();
}

void SimulatedHoldings::SetList(visibility::CellId cell, std::span<const uint32_t> objects, double t) {
  List& list = lists_[cell];
  list.objects.assign(objects.begin(), objects.end());
  list.arrival_s = t;
  list.prefix_held = 0;
  list.prefix_arrival_s = 0.0;
}

std::optional<double> SimulatedHoldings::CompleteAt(visibility::CellId cell) {
  auto it = lists_.find(cell);
  if (it == lists_.end()) return std::nullopt;
  List& list = it->second;
  for (; list.prefix_held < list.objects.size(); ++list.prefix_held) {
    const Held* h = Of(list.objects[list.prefix_held]);
    if (h == nullptr) return std::nullopt;
    list.prefix_arrival_s = std::max(list.prefix_arrival_s, h->arrival_s);
    prefixes_dirty_ = true;
  }
  return std::max(list.arrival_s, list.prefix_arrival_s);
}

void SimulatedHoldings::ResetPrefixes() {
  if (!prefixes_dirty_) return;
  for (auto& [cell, list] : lists_) {
    list.prefix_held = 0;
    list.prefix_arrival_s = 0.0;
  }
  prefixes_dirty_ = false;
}

}  // namespace vistream::server
