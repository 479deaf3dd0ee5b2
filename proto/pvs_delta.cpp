#include "proto/pvs_delta.h"

#include <algorithm>
#include <iterator>

#include <absl/strings/str_cat.h>

namespace vistream::proto {

namespace {

namespace v1 = vistream::v1;

template <typename Field>
void AddGaps(const std::vector<uint32_t>& ids, Field* out) {
  uint32_t last = 0;
  for (size_t k = 0; k < ids.size(); ++k) {
    out->Add(k == 0 ? ids[k] : ids[k] - last);
    last = ids[k];
  }
}

// Ascending ids from gaps; false on a gap of 0 after the first or past 2^32.
template <typename Field>
bool FromGaps(const Field& gaps, std::vector<uint32_t>* ids) {
  uint64_t at = 0;
  for (int k = 0; k < gaps.size(); ++k) {
    if (k > 0 && gaps[k] == 0) return false;
    at = k == 0 ? gaps[k] : at + gaps[k];
    if (at > UINT32_MAX) return false;
    ids->push_back(static_cast<uint32_t>(at));
  }
  return true;
}

uint32_t LevelOf(const PvsList& l, size_t k) { return k < l.levels.size() ? l.levels[k] : 0; }

}  // namespace

void EncodePvsDelta(const PvsList& previous, const PvsList& next, v1::ViewcellPvs* out) {
  out->clear_object_ids();
  out->clear_object_levels();
  out->set_delta(true);
  std::vector<uint32_t> removed, added, level_ids, level_values;
  size_t i = 0, j = 0;
  while (i < previous.objects.size() || j < next.objects.size()) {
    if (j == next.objects.size() || (i < previous.objects.size() && previous.objects[i] < next.objects[j])) {
      removed.push_back(previous.objects[i++]);
    } else if (i == previous.objects.size() || next.objects[j] < previous.objects[i]) {
      if (LevelOf(next, j) != 0) {
        level_ids.push_back(next.objects[j]);
        level_values.push_back(LevelOf(next, j));
      }
      added.push_back(next.objects[j++]);
    } else {
      if (LevelOf(next, j) != LevelOf(previous, i)) {
        level_ids.push_back(next.objects[j]);
        level_values.push_back(LevelOf(next, j));
      }
      ++i;
      ++j;
    }
  }
  AddGaps(removed, out->mutable_removed());
  AddGaps(added, out->mutable_added());
  AddGaps(level_ids, out->mutable_level_ids());
  out->mutable_level_values()->Add(level_values.begin(), level_values.end());
}

absl::StatusOr<PvsList> PvsListDecoder::Decode(const v1::ViewcellPvs& m) {
  const std::string where = absl::StrCat("the PVS list of cell ", m.cell_id());
  PvsList list;
  list.cell = m.cell_id();
  if (!m.delta()) {
    list.objects.assign(m.object_ids().begin(), m.object_ids().end());
    if (m.object_levels_size() != 0 && m.object_levels_size() != m.object_ids_size()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": ", m.object_levels_size(), " levels for ",
                                                     m.object_ids_size(), " objects"));
    }
    list.levels.assign(m.object_levels().begin(), m.object_levels().end());
  } else {
    if (!has_previous_) return absl::InvalidArgumentError(absl::StrCat(where, ": a difference from no list before it"));
    std::vector<uint32_t> removed, added, level_ids;
    if (!FromGaps(m.removed(), &removed) || !FromGaps(m.added(), &added) || !FromGaps(m.level_ids(), &level_ids)) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": ids that do not ascend (a gap of 0, or past 2^32)"));
    }
    if (m.level_values_size() != static_cast<int>(level_ids.size())) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": ", m.level_values_size(), " level values for ",
                                                     level_ids.size(), " ids"));
    }
    const bool levels = !previous_.levels.empty() || !level_ids.empty();
    size_t r = 0, a = 0;
    for (size_t i = 0; i <= previous_.objects.size(); ++i) {
      const bool end = i == previous_.objects.size();
      // Added ids before this previous object go first.
      while (a < added.size() && (end || added[a] < previous_.objects[i])) {
        list.objects.push_back(added[a++]);
        if (levels) list.levels.push_back(0);
      }
      if (end) break;
      if (a < added.size() && added[a] == previous_.objects[i]) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": adds object ", added[a], ", which the list before holds"));
      }
      if (r < removed.size() && removed[r] < previous_.objects[i]) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": removes object ", removed[r], ", which the list before lacks"));
      }
      if (r < removed.size() && removed[r] == previous_.objects[i]) {
        ++r;
        continue;
      }
      list.objects.push_back(previous_.objects[i]);
      if (levels) list.levels.push_back(LevelOf(previous_, i));
    }
    if (r < removed.size()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": removes object ", removed[r], ", which the list before lacks"));
    }
    for (size_t k = 0; k < level_ids.size(); ++k) {
      const auto at = std::lower_bound(list.objects.begin(), list.objects.end(), level_ids[k]);
      if (at == list.objects.end() || *at != level_ids[k]) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": a level for object ", level_ids[k], ", not on the list"));
      }
      list.levels[static_cast<size_t>(at - list.objects.begin())] = m.level_values(static_cast<int>(k));
    }
  }
  if (m.cluster_levels_size() != m.cluster_ids_size()) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", m.cluster_levels_size(), " cluster levels for ",
                                                   m.cluster_ids_size(), " clusters"));
  }
  for (int k = 0; k < m.cluster_ids_size(); ++k) {
    if (k > 0 && m.cluster_ids(k) <= m.cluster_ids(k - 1)) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": cluster ids that do not ascend (", m.cluster_ids(k - 1),
                                                     " then ", m.cluster_ids(k), ")"));
    }
    if (m.cluster_levels(k) == 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": cluster ", m.cluster_ids(k), " at level 0 (a cluster's levels start at 1)"));
    }
  }
  list.cluster_ids.assign(m.cluster_ids().begin(), m.cluster_ids().end());
  list.cluster_levels.assign(m.cluster_levels().begin(), m.cluster_levels().end());
  previous_ = list;
  has_previous_ = true;
  return list;
}

}  // namespace vistream::proto
