#include "client/cell_completion.h"

#include <algorithm>

namespace vistream::client {

CellCompletion::Standing CellCompletion::StandingOf(const CellList& list, uint32_t o, uint32_t needed,
                                                    const Object& state) const {
  Standing own = !state.held ? Standing::kMissing : state.level > needed ? Standing::kCoarse : Standing::kComplete;
  if (own == Standing::kComplete || list.cover.empty()) return own;
  const auto c = list.cover.find(o);
  if (c == list.cover.end()) return own;
  const auto chosen = std::lower_bound(list.clusters.begin(), list.clusters.end(), std::pair{c->second, uint32_t{0}});
  const uint32_t level = clusters_.at(c->second).level;
  return level <= chosen->second ? Standing::kComplete : Standing::kCoarse;
}

void CellCompletion::Recount(uint32_t cell, double t_s) {
  CellList& list = lists_.at(cell);
  const bool was_complete = list.missing == 0;
  list.cover.clear();
  for (const auto& [c, level] : list.clusters) {
    const auto held = clusters_.find(c);
    if (held == clusters_.end()) continue;
    list.latest_s = std::max(list.latest_s, t_s);
    const std::vector<uint32_t>& members = held->second.objects;
    for (uint32_t o : list.objects) {
      if (std::binary_search(members.begin(), members.end(), o)) list.cover.emplace(o, c);
    }
  }
  list.missing = list.coarse = 0;
  for (size_t k = 0; k < list.objects.size(); ++k) {
    const auto e = entries_.find(list.objects[k]);
    const Standing st = StandingOf(list, list.objects[k], list.levels[k], e->second.state);
    list.missing += st == Standing::kMissing ? 1 : 0;
    list.coarse += st == Standing::kCoarse ? 1 : 0;
  }
  if (!was_complete && list.missing == 0 && on_complete) on_complete(cell, t_s);
}

void CellCompletion::SetList(uint32_t cell, std::span<const uint32_t> objects, double t_s,
                             std::span<const uint32_t> levels, std::span<const uint32_t> cluster_ids,
                             std::span<const uint32_t> cluster_levels) {
  DropList(cell);
  CellList& list = lists_[cell];
  list.objects.assign(objects.begin(), objects.end());
  list.levels.assign(list.objects.size(), 0);
  list.latest_s = t_s;
  for (size_t k = 0; k < cluster_ids.size() && k < cluster_levels.size(); ++k) {
    list.clusters.emplace_back(cluster_ids[k], cluster_levels[k]);
    cluster_cells_[cluster_ids[k]].push_back(cell);
  }
  std::sort(list.clusters.begin(), list.clusters.end());
  for (size_t k = 0; k < list.objects.size(); ++k) {
    const uint32_t o = list.objects[k];
    const uint32_t needed = k < levels.size() ? levels[k] : 0;
    list.levels[k] = needed;
    ObjectEntry& e = entries_[o];
    e.cells.emplace_back(cell, needed);
    if (e.state.held) list.latest_s = std::max(list.latest_s, e.state.arrival_s);
  }
  list.missing = 1;  // so that Recount reports a list complete as it arrives
  Recount(cell, t_s);
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
  for (const auto& [c, level] : it->second.clusters) {
    std::vector<uint32_t>& cells = cluster_cells_[c];
    if (auto at = std::find(cells.begin(), cells.end(), cell); at != cells.end()) cells.erase(at);
    if (cells.empty()) cluster_cells_.erase(c);
  }
  lists_.erase(it);
}

bool CellCompletion::Arrive(uint32_t id, double t_s, uint32_t level) {
  ObjectEntry& e = entries_[id];
  const bool first = !e.state.ever;
  const bool was_held = e.state.held;
  const Object before = e.state;
  if (was_held && level != before.level) {
    // Another level of an object held: what was drawn stays drawable; only the level changes.
    e.state.level = level;
  } else {
    e.state.arrival_s = t_s;
    e.state.held = e.state.ever = true;
    e.state.level = level;
  }
  for (const auto& [cell, needed] : e.cells) {
    CellList& list = lists_[cell];
    const Standing from = StandingOf(list, id, needed, before);
    const Standing to = StandingOf(list, id, needed, e.state);
    if (!(was_held && level != before.level)) list.latest_s = std::max(list.latest_s, t_s);
    list.coarse = list.coarse - (from == Standing::kCoarse ? 1 : 0) + (to == Standing::kCoarse ? 1 : 0);
    if (from == Standing::kMissing && to != Standing::kMissing && --list.missing == 0 && on_complete) {
      on_complete(cell, t_s);
    }
  }
  return first;
}

void CellCompletion::Drop(uint32_t id) {
  auto it = entries_.find(id);
  if (it == entries_.end() || !it->second.state.held) return;
  const Object before = it->second.state;
  it->second.state.held = false;
  for (const auto& [cell, needed] : it->second.cells) {
    CellList& list = lists_[cell];
    const Standing from = StandingOf(list, id, needed, before);
    const Standing to = StandingOf(list, id, needed, it->second.state);
    list.coarse = list.coarse - (from == Standing::kCoarse ? 1 : 0) + (to == Standing::kCoarse ? 1 : 0);
    list.missing = list.missing - (from == Standing::kMissing ? 1 : 0) + (to == Standing::kMissing ? 1 : 0);
  }
}

void CellCompletion::ArriveCluster(uint32_t id, double t_s, uint32_t level, std::span<const uint32_t> objects) {
  Cluster& c = clusters_[id];
  c.level = level;
  c.arrival_s = t_s;
  c.objects.assign(objects.begin(), objects.end());
  if (auto cells = cluster_cells_.find(id); cells != cluster_cells_.end()) {
    for (uint32_t cell : cells->second) Recount(cell, t_s);
  }
}

void CellCompletion::DropCluster(uint32_t id) {
  if (clusters_.erase(id) == 0) return;
  if (auto cells = cluster_cells_.find(id); cells != cluster_cells_.end()) {
    for (uint32_t cell : cells->second) {
      CellList& list = lists_.at(cell);
      const double latest = list.latest_s;
      Recount(cell, latest);
    }
  }
}

const CellCompletion::Cluster* CellCompletion::HeldCluster(uint32_t id) const {
  auto it = clusters_.find(id);
  return it == clusters_.end() ? nullptr : &it->second;
}

std::optional<uint32_t> CellCompletion::CoveringCluster(uint32_t cell, uint32_t o) const {
  auto it = lists_.find(cell);
  if (it == lists_.end()) return std::nullopt;
  auto c = it->second.cover.find(o);
  return c == it->second.cover.end() ? std::nullopt : std::optional<uint32_t>(c->second);
}

std::span<const std::pair<uint32_t, uint32_t>> CellCompletion::ListClusters(uint32_t cell) const {
  auto it = lists_.find(cell);
  if (it == lists_.end()) return {};
  return it->second.clusters;
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
