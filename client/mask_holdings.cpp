#include "client/mask_holdings.h"

#include <algorithm>
#include <bit>
#include <iterator>
#include <utility>

#include <absl/strings/str_cat.h>

#include "proto/vec3.h"

namespace vistream::client {

namespace v1 = vistream::v1;

const std::vector<uint8_t>* EpsilonMaskSet::Bits(uint32_t object) const {
  auto it = std::lower_bound(objects.begin(), objects.end(), object,
                             [](const visibility::MaskObject& m, uint32_t id) { return m.object < id; });
  return it != objects.end() && it->object == object ? &it->bits : nullptr;
}

absl::StatusOr<std::string> MaskRunBytes(const v1::EpsilonMask& m, uint32_t object_count, uint64_t triangle_count) {
  if (!m.deflated()) return m.triangles();
  absl::StatusOr<std::string> runs = visibility::InflateMaskBytes(
      m.triangles(), static_cast<size_t>(visibility::MaxMaskRunBytes(object_count, triangle_count)));
  if (!runs.ok()) return absl::InvalidArgumentError(absl::StrCat("ε-mask ", m.mask_id(), ": ", runs.status().message()));
  return runs;
}

absl::Status MaskHoldings::Add(const v1::EpsilonMask& m, uint32_t object_count, uint64_t triangle_count) {
  absl::StatusOr<std::string> runs = MaskRunBytes(m, object_count, triangle_count);
  if (!runs.ok()) return runs.status();
  absl::StatusOr<visibility::DecodedMask> decoded =
      bases_.Decode(m.cell_id(), m.mask_id(), m.base_mask_id(), *runs, object_count, triangle_count);
  if (!decoded.ok()) return decoded.status();
  EpsilonMaskSet set;
  set.mask_id = m.mask_id();
  set.key = next_key_++;
  set.cell = m.cell_id();
  set.box_min = ToVec(m.neighbourhood_min());
  set.box_max = ToVec(m.neighbourhood_max());
  set.triangles = decoded->triangles;
  set.objects = std::move(decoded->objects);
  set.object_ids.reserve(set.objects.size());
  set.object_triangles.reserve(set.objects.size());
  for (const visibility::MaskObject& o : set.objects) {
    set.object_ids.push_back(o.object);
    uint64_t n = 0;
    for (uint8_t byte : o.bits) n += static_cast<uint64_t>(std::popcount(byte));
    set.object_triangles.push_back(n);
  }
  if (auto it = masks_.find(set.mask_id); it != masks_.end()) Drop(it);
  masks_.emplace(set.mask_id, std::move(set));
  return absl::OkStatus();
}

void MaskHoldings::Drop(std::map<uint32_t, EpsilonMaskSet>::iterator it) {
  dropped_.push_back(it->second.key);
  masks_.erase(it);
}

void MaskHoldings::KeepNear(std::optional<uint32_t> cell, const visibility::ViewcellGrid& grid) {
  if (cell.has_value()) {
    for (auto it = masks_.begin(); it != masks_.end();) {
      auto next = std::next(it);
      if (it->second.cell >= grid.CellCount() || !grid.Near(it->second.cell, *cell)) Drop(it);
      it = next;
    }
  }
  while (masks_.size() > kMaxMasks) {
    auto oldest = std::min_element(masks_.begin(), masks_.end(),
                                   [](const auto& a, const auto& b) { return a.second.key < b.second.key; });
    Drop(oldest);
  }
}

MaskChoice MaskHoldings::Choose(const glm::dvec3& eye, const std::function<bool(uint32_t)>& ready) const {
  return Choose(eye, [&](uint32_t o, uint32_t) { return ready(o); });
}

MaskChoice MaskHoldings::Choose(const glm::dvec3& eye,
                                const std::function<bool(uint32_t object, uint32_t cell)>& ready) const {
  MaskChoice choice;
  for (const auto& entry : masks_) {
    const EpsilonMaskSet& m = entry.second;
    if (!m.Contains(eye)) continue;
    choice.in_box = true;
    if (choice.mask != nullptr && choice.mask->triangles <= m.triangles) continue;
    if (std::all_of(m.object_ids.begin(), m.object_ids.end(), [&](uint32_t o) { return ready(o, m.cell); })) {
      choice.mask = &m;
    }
  }
  return choice;
}

std::vector<uint64_t> MaskHoldings::TakeDropped() { return std::exchange(dropped_, {}); }

}  // namespace vistream::client
