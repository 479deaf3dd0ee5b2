#include "client/object_store.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <utility>

#include <absl/strings/str_cat.h>

#include "client/cell_completion.h"
#include "proto/scene_info.h"

namespace vistream::client {

namespace v1 = vistream::v1;

std::vector<uint32_t> ObjectStore::Apply(std::vector<Event> events, std::optional<uint32_t> current_cell) {
  for (Event& e : events) {
    if (auto* info = std::get_if<v1::SceneInfo>(&e)) {
      absl::StatusOr<visibility::ViewcellGrid> grid = GridFromSceneInfo(info->grid());
      if (!grid.ok()) {
        if (!failure_.has_value()) {
          failure_ = absl::StrCat("the server sent a malformed scene description: ", grid.status().message());
          bad_data_ = true;
        }
        continue;
      }
      scene_info_ = std::move(*info);
      grid_ = *std::move(grid);
      masks_.NewSession();  // a session starts here; its masks number from 1 again
    } else if (auto* pvs = std::get_if<v1::ViewcellPvs>(&e)) {
      pvs_[pvs->cell_id()].assign(pvs->object_ids().begin(), pvs->object_ids().end());
      if (pvs->object_levels_size() == pvs->object_ids_size() && pvs->object_levels_size() > 0) {
        pvs_levels_[pvs->cell_id()].assign(pvs->object_levels().begin(), pvs->object_levels().end());
      } else {
        pvs_levels_.erase(pvs->cell_id());
      }
      if (pvs->cluster_ids_size() > 0 && pvs->cluster_ids_size() == pvs->cluster_levels_size()) {
        auto& chosen = pvs_clusters_[pvs->cell_id()];
        chosen.clear();
        for (int k = 0; k < pvs->cluster_ids_size(); ++k) {
          chosen.emplace_back(pvs->cluster_ids(k), pvs->cluster_levels(k));
        }
      } else {
        pvs_clusters_.erase(pvs->cell_id());
      }
    } else if (auto* object = std::get_if<ReceivedObject>(&e)) {
      const uint32_t id = object->id;
      if (objects_.count(id) > 0) Remove(id);  // a resent object replaces the old copy
      held_bytes_ += object->raw_bytes;
      objects_[id] = StoredObject{std::move(*object), 0};
      added_.push_back(id);
    } else if (auto* cluster = std::get_if<ReceivedCluster>(&e)) {
      const uint32_t id = cluster->id;
      RemoveCluster(id);  // a level replaces the one held
      StoredCluster stored;
      const scenes::Mesh& mesh = cluster->mesh;
      for (size_t k = 0; k < cluster->objects.size(); ++k) {
        scenes::Aabb box;
        for (size_t t = cluster->first_triangle[k]; t < cluster->first_triangle[k + 1]; ++t) {
          for (int v = 0; v < 3; ++v) box.Extend(glm::dvec3(mesh.positions[mesh.indices[3 * t + v]]));
        }
        if (box.Empty()) box = scenes::Aabb{glm::dvec3(0.0), glm::dvec3(0.0)};
        stored.piece_bounds.emplace_back(box.min, box.max);
      }
      held_bytes_ += cluster->raw_bytes;
      stored.data = std::move(*cluster);
      clusters_[id] = std::move(stored);
      added_clusters_.push_back(id);
    } else if (auto* evict = std::get_if<v1::Evict>(&e)) {
      for (uint32_t id : evict->object_ids()) {
        if (objects_.count(id) == 0) continue;
        Remove(id);
        ++evicted_by_server_;
      }
      for (uint32_t id : evict->cluster_ids()) {
        if (clusters_.count(id) == 0) continue;
        RemoveCluster(id);
        ++evicted_by_server_;
      }
    } else if (auto* m = std::get_if<v1::EpsilonMask>(&e)) {
      AddMask(*m);
    } else if (auto* ended = std::get_if<SessionEnded>(&e)) {
      if (!failure_.has_value()) failure_ = std::string(ended->status.message());
    }
  }
  max_held_bytes_ = std::max(max_held_bytes_, held_bytes_);
  if (current_cell.has_value() && scene_info_.has_value()) {
    // Lists of cells two or more cells beyond the adjacent ones: the server, which follows
    // the client a pose behind, has stopped wanting them and sends them again when it does.
    const visibility::CellCoord c = grid_.Coord(*current_cell);
    std::erase_if(pvs_, [&](const auto& entry) {
      const visibility::CellCoord e = grid_.Coord(entry.first);
      return std::max(std::abs(e.i - c.i), std::abs(e.j - c.j)) >= 3;
    });
    std::erase_if(pvs_levels_, [&](const auto& entry) { return pvs_.count(entry.first) == 0; });
    std::erase_if(pvs_clusters_, [&](const auto& entry) { return pvs_.count(entry.first) == 0; });
  }
  masks_.KeepNear(scene_info_.has_value() ? current_cell : std::nullopt, grid_);
  return EnforceBudget(current_cell);
}

void ObjectStore::AddMask(const v1::EpsilonMask& m) {
  if (failure_.has_value()) return;  // nothing after bad data is trusted
  const std::string what =
      absl::StrCat("the server sent a malformed ε-mask (mask ", m.mask_id(), ", cell ", m.cell_id(), ")");
  if (!scene_info_.has_value()) {
    failure_ = absl::StrCat(what, ": it arrived before the scene's description");
    bad_data_ = true;
    return;
  }
  if (absl::Status st = masks_.Add(m, scene_info_->object_count(), scene_info_->triangle_count()); !st.ok()) {
    failure_ = absl::StrCat(what, ": ", st.message());
    bad_data_ = true;
  }
}

MaskChoice ObjectStore::ChooseMask(const glm::dvec3& eye, const std::function<bool(uint32_t)>& ready,
                                   const std::function<bool(uint32_t)>& cluster_ready) const {
  return masks_.Choose(eye, [&](uint32_t o, uint32_t cell) {
    if (objects_.count(o) > 0 && (!ready || ready(o))) return true;
    const auto piece = CoveringCluster(cell, o);
    return piece.has_value() && (!cluster_ready || cluster_ready(piece->first));
  });
}

std::vector<uint64_t> ObjectStore::TakeDroppedMasks() { return masks_.TakeDropped(); }

std::vector<uint32_t> ObjectStore::EnforceBudget(std::optional<uint32_t> current_cell) {
  std::vector<uint32_t> dropped;
  if (budget_ == 0 || held_bytes_ <= budget_) return dropped;
  // Rank: 0 outside the current and adjacent PVSs, 1 adjacent only; the current cell's PVS
  // is never dropped. Within a rank, least recently drawn first.
  std::set<uint32_t> current, adjacent;
  if (current_cell.has_value()) {
    if (const std::vector<uint32_t>* p = Pvs(*current_cell)) current.insert(p->begin(), p->end());
    for (uint32_t c : grid_.Neighbourhood(*current_cell)) {
      if (const std::vector<uint32_t>* p = Pvs(c)) adjacent.insert(p->begin(), p->end());
    }
  }
  std::vector<std::tuple<int, uint64_t, uint32_t>> order;
  for (const auto& [id, o] : objects_) {
    if (current.count(id) > 0) continue;
    order.emplace_back(adjacent.count(id) > 0 ? 1 : 0, o.last_drawn_frame, id);
  }
  std::sort(order.begin(), order.end());
  for (const auto& [rank, frame, id] : order) {
    if (held_bytes_ <= budget_) break;
    Remove(id);
    ++evicted_by_budget_;
    dropped.push_back(id);
  }
  return dropped;
}

void ObjectStore::Remove(uint32_t id) {
  auto it = objects_.find(id);
  if (it == objects_.end()) return;
  held_bytes_ -= it->second.data.raw_bytes;
  objects_.erase(it);
  removed_.push_back(id);
}

const StoredObject* ObjectStore::Find(uint32_t id) const {
  auto it = objects_.find(id);
  return it == objects_.end() ? nullptr : &it->second;
}

StoredObject* ObjectStore::Find(uint32_t id) {
  auto it = objects_.find(id);
  return it == objects_.end() ? nullptr : &it->second;
}

const std::vector<uint32_t>* ObjectStore::Pvs(uint32_t cell) const {
  auto it = pvs_.find(cell);
  return it == pvs_.end() ? nullptr : &it->second;
}

const std::vector<uint32_t>* ObjectStore::PvsLevels(uint32_t cell) const {
  auto it = pvs_levels_.find(cell);
  return it == pvs_levels_.end() ? nullptr : &it->second;
}

bool ObjectStore::CellComplete(uint32_t cell) const {
  return client::CellComplete(
      Pvs(cell), [&](uint32_t id) { return objects_.count(id) > 0 || CoveringCluster(cell, id).has_value(); });
}

const StoredCluster* ObjectStore::FindCluster(uint32_t id) const {
  auto it = clusters_.find(id);
  return it == clusters_.end() ? nullptr : &it->second;
}

const std::vector<std::pair<uint32_t, uint32_t>>* ObjectStore::PvsClusters(uint32_t cell) const {
  auto it = pvs_clusters_.find(cell);
  return it == pvs_clusters_.end() ? nullptr : &it->second;
}

std::optional<std::pair<uint32_t, size_t>> ObjectStore::CoveringCluster(uint32_t cell, uint32_t o) const {
  const std::vector<std::pair<uint32_t, uint32_t>>* chosen = PvsClusters(cell);
  if (chosen == nullptr) return std::nullopt;
  for (const auto& [c, level] : *chosen) {
    const StoredCluster* held = FindCluster(c);
    if (held == nullptr) continue;
    const std::vector<uint32_t>& members = held->data.objects;
    const auto at = std::lower_bound(members.begin(), members.end(), o);
    if (at != members.end() && *at == o) return std::pair{c, static_cast<size_t>(at - members.begin())};
  }
  return std::nullopt;
}

void ObjectStore::RemoveCluster(uint32_t id) {
  auto it = clusters_.find(id);
  if (it == clusters_.end()) return;
  held_bytes_ -= it->second.data.raw_bytes;
  clusters_.erase(it);
  removed_clusters_.push_back(id);
}

std::vector<uint32_t> ObjectStore::TakeAddedClusters() { return std::exchange(added_clusters_, {}); }

std::vector<uint32_t> ObjectStore::TakeRemovedClusters() { return std::exchange(removed_clusters_, {}); }

std::vector<uint32_t> ObjectStore::TakeAdded() { return std::exchange(added_, {}); }

std::vector<uint32_t> ObjectStore::TakeRemoved() { return std::exchange(removed_, {}); }

}  // namespace vistream::client
