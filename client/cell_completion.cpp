#include "client/cell_completion.h"

#include <algorithm>

namespace vistream::client {

void CellCompletion::SetList(uint32_t cell, std::span<const uint32_t> objects, double t_s,
                             std::span<const uint32_t> levels) {
  DropList(cell);
  CellList& list = lists_[cell];
  list.objects.assign(objects.begin(), objects.end());
  list.latest_s = t_s;
  for (size_t k = 0; k < list.objects.size(); ++k) {
    const uint32_t o = list.objects[k];
    const uint32_t needed = k < levels.size() ? levels[k] : 0;
    ObjectEntry& e = entries_[o];
    e.cells.emplace_back(cell, needed);
    if (e.state.held) {
      list.latest_s = std::max(list.latest_s, e.state.arrival_s);
      if (e.state.level > needed) ++list.coarse;
    } else {
      ++list.missing;
    }
  }
  if (list.missing == 0 && on_complete) on_complete(cell, t_s);
}

void CellCompletion::DropList(uint32_t cell) {
  auto it = lists_.find(cell);
  if (it == lists_.end()) return;
  for (uint32_t o : it->second.objects) {
    auto& cells = entries_[o].cells;
    if (auto at = std::find_if(cells.begin(), cells.end(), [cell](const auto& c) { return c.first == cell; });
        at != cells.end()) {
      cells.erase(at);
    }
  }
  lists_.erase(it);
}

bool CellCompletion::Arrive(uint32_t id, double t_s, uint32_t level) {
  ObjectEntry& e = entries_[id];
  const bool first = !e.state.ever;
  const bool was_held = e.state.held;
  const uint32_t was_level = e.state.level;
  if (was_held && level != was_level) {
    // Another level of an object held: what was drawn stays drawable; only the level changes.
    e.state.level = level;
    for (const auto& [cell, needed] : e.cells) {
      CellList& list = lists_[cell];
      list.coarse = list.coarse - (was_level > needed ? 1 : 0) + (level > needed ? 1 : 0);
    }
    return first;
  }
  e.state.arrival_s = t_s;
  e.state.held = e.state.ever = true;
  e.state.level = level;
  for (const auto& [cell, needed] : e.cells) {
    CellList& list = lists_[cell];
    list.latest_s = std::max(list.latest_s, t_s);
    if (!was_held && level > needed) ++list.coarse;
    if (!was_held && --list.missing == 0 && on_complete) on_complete(cell, t_s);
  }
  return first;
}

void CellCompletion::Drop(uint32_t id) {
  auto it = entries_.find(id);
  if (it == entries_.end() || !it->second.state.held) return;
  it->second.state.held = false;
  for (const auto& [cell, needed] : it->second.cells) {
    CellList& list = lists_[cell];
    ++list.missing;
    if (it->second.state.level > needed) --list.coarse;
  }
}

const CellCompletion::Object* CellCompletion::Held(uint32_t id) const {
  auto it = entries_.find(id);
  return it != entries_.end() && it->second.state.held ? &it->second.state : nullptr;
}

const std::vector<uint32_t>* CellCompletion::List(uint32_t cell) const {
  auto it = lists_.find(cell);
  return it == lists_.end() ? nullptr : &it->second.objects;
}

bool CellCompletion::Complete(uint32_t cell) const {
  auto it = lists_.find(cell);
  return it != lists_.end() && it->second.missing == 0;
}

size_t CellCompletion::Missing(uint32_t cell) const {
  auto it = lists_.find(cell);
  return it == lists_.end() ? 0 : it->second.missing;
}

size_t CellCompletion::Coarse(uint32_t cell) const {
  auto it = lists_.find(cell);
  return it == lists_.end() ? 0 : it->second.coarse;
}

std::optional<double> CellCompletion::CompleteAt(uint32_t cell) const {
  auto it = lists_.find(cell);
  if (it == lists_.end() || it->second.missing != 0) return std::nullopt;
  return it->second.latest_s;
}

}  // namespace vistream::client
