#include "server/mask_planner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <glm/geometric.hpp>

#include "server/wire.h"

namespace vistream::server {

namespace {

namespace v1 = vistream::v1;

double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

BuiltMask BuildMask(const visibility::EpsilonSuperset& eps, const scenes::Aabb& box, const CellPvs& pvs) {
  const double start = SteadySeconds();
  const visibility::EpsilonResult r = eps.Compute(box, visibility::EpsilonOptions{}, pvs.objects);
  BuiltMask out;
  out.compute_ms = (SteadySeconds() - start) * 1000.0;
  v1::EpsilonMask* mask = out.message.mutable_epsilon_mask();
  mask->set_cell_id(pvs.cell);
  SetVec(box.min, mask->mutable_neighbourhood_min());
  SetVec(box.max, mask->mutable_neighbourhood_max());
  mask->set_object_count(static_cast<uint32_t>(r.objects.size()));
  mask->set_triangle_count(r.triangles.size());
  // The sets per object (the triangles are sorted by dense id: object by object).
  out.sets = visibility::MaskObjectsFromTriangles(
      r.triangles, [&eps](uint32_t t) { return eps.ObjectOfTriangle(t); },
      [&eps](uint32_t o) { return eps.TriangleId(o, 0); });
  return out;
}

void MaskPlanner::Advance(const glm::dvec3& position, const glm::dvec3& velocity, double now,
                          const visibility::ViewcellGrid& grid, const std::function<bool(CellId)>& wanted,
                          v1::SessionStats* stats) {
  if (!on_) return;
  const double v = std::hypot(velocity.x, velocity.y);
  if (v >= chain_.options().standing_speed_mps) {
    // The turn rate: the heading's change since the last moving pose, smoothed.
    const double heading = std::atan2(velocity.y, velocity.x);
    const double dt = now - heading_s_;
    if (heading_s_ >= 0.0 && dt > 1e-3 && dt < 1.0) {
      const double d = std::remainder(heading - heading_, 2.0 * M_PI);
      turn_rate_ = 0.5 * turn_rate_ + 0.5 * d / dt;
    } else {
      turn_rate_ = 0.0;
    }
    heading_ = heading;
    heading_s_ = now;
  } else {
    turn_rate_ = 0.0;
    heading_s_ = -1.0;
  }
  // Poses come at up to a few dozen a second: the chain moves every quarter metre or second.
  if (chain_s_ >= 0.0 && glm::length(position - chain_eye_) < 0.25 && now - chain_s_ < 0.25) return;
  chain_eye_ = position;
  chain_s_ = now;
  const NeighbourhoodChain::Update u = chain_.Advance(position, velocity, turn_rate_, grid, wanted);
  for (uint64_t id : u.removed) Drop(id, stats);
  for (const Neighbourhood& n : u.added) {
    PlannedMask& p = planned_[n.id];
    p.n = n;
    p.deadline = now + (v >= chain_.options().standing_speed_mps ? n.along_m / v : 0.0);
  }
}

void MaskPlanner::Drop(uint64_t id, v1::SessionStats* stats) {
  // A posted computation finds its entry gone and stops (or its delivery does).
  if (planned_.erase(id) > 0) {
    stats->set_epsilon_masks_dropped(stats->epsilon_masks_dropped() + 1);
    return;
  }
  auto it = std::find_if(ready_.begin(), ready_.end(), [&](const ReadyMask& m) { return m.id == id; });
  if (it != ready_.end()) {
    ready_.erase(it);
    stats->set_epsilon_masks_dropped(stats->epsilon_masks_dropped() + 1);
  }
}

std::vector<MaskPlanner::Job> MaskPlanner::TakeJobs(const std::set<CellId>& emitted,
                                                    const std::map<CellId, CellPvsPtr>& received) {
  std::vector<Job> jobs;
  if (!on_) return jobs;
  for (auto& [id, p] : planned_) {
    // A mask narrows its cell's PVS, whose list the client must have first.
    if (p.posted || emitted.count(p.n.cell) == 0) continue;
    auto it = received.find(p.n.cell);
    if (it == received.end()) continue;
    p.posted = true;
    jobs.push_back(Job{id, p.n.box, it->second, p.deadline});
  }
  return jobs;
}

bool MaskPlanner::AddComputed(uint64_t key, BuiltMask mask) {
  auto plan = planned_.find(key);
  if (plan == planned_.end()) return false;  // dropped while it was computed
  ReadyMask ready{key, plan->second.n.cell, plan->second.deadline, std::move(mask)};
  planned_.erase(plan);
  auto at = std::upper_bound(ready_.begin(), ready_.end(), ready.deadline,
                             [](double d, const ReadyMask& other) { return d < other.deadline; });
  ready_.insert(at, std::move(ready));
  return true;
}

void MaskPlanner::Rewant(const std::vector<CellId>& wanted) {
  auto unwanted = [&](CellId c) { return std::find(wanted.begin(), wanted.end(), c) == wanted.end(); };
  std::erase_if(last_sent_, [&](const auto& entry) { return unwanted(entry.first); });
  if (unwanted(objects_cell_)) {
    objects_.clear();
  } else {
    objects_rank_ = static_cast<size_t>(std::find(wanted.begin(), wanted.end(), objects_cell_) - wanted.begin());
  }
}

std::optional<v1::ServerMessage> MaskPlanner::NextObject(const std::unordered_set<uint32_t>& held,
                                                         const SendObject& send) {
  while (!objects_.empty()) {
    const uint32_t o = objects_.front();
    if (held.count(o) > 0) {
      objects_.pop_front();
      continue;
    }
    bool sent = false;
    std::optional<v1::ServerMessage> m = send(o, objects_rank_, &sent);
    if (sent || !m.has_value()) objects_.pop_front();  // sent, or no room: its cell's turn
    if (m.has_value()) return m;                       // the object, or an Evict before it
  }
  return std::nullopt;
}

std::optional<MaskPlanner::Sent> MaskPlanner::NextMask(const std::vector<CellId>& wanted,
                                                       const std::set<CellId>& emitted,
                                                       const std::unordered_set<uint32_t>& held,
                                                       v1::SessionStats* stats,
                                                       const std::function<uint32_t(CellId, uint32_t)>& whole) {
  while (!ready_.empty()) {
    ReadyMask ready = std::move(ready_.front());
    ready_.erase(ready_.begin());
    auto w = std::find(wanted.begin(), wanted.end(), ready.cell);
    if (w == wanted.end() || emitted.count(ready.cell) == 0) {
      stats->set_epsilon_masks_dropped(stats->epsilon_masks_dropped() + 1);
      continue;  // the client turned away from its cell
    }
    BuiltMask& mask = ready.mask;
    v1::EpsilonMask* e = mask.message.mutable_epsilon_mask();
    e->set_mask_id(next_mask_id_++);
    if (whole) {
      for (visibility::MaskObject& o : mask.sets) {
        const uint32_t n = whole(ready.cell, o.object);
        if (n == 0) continue;
        o.bits.assign((n + 7) / 8, 0xff);
        if (n % 8 != 0) o.bits.back() = static_cast<uint8_t>((1u << (n % 8)) - 1);
      }
    }
    // The sets, or their difference from the last mask of the cell, whichever is shorter.
    std::string bytes = visibility::EncodeMaskRuns(mask.sets);
    if (auto last = last_sent_.find(ready.cell); last != last_sent_.end()) {
      std::string delta = visibility::EncodeMaskDelta(last->second.sets, mask.sets);
      if (delta.size() < bytes.size()) {
        bytes = std::move(delta);
        e->set_base_mask_id(last->second.id);
      }
    }
    if (deflate_) {
      std::string deflated = visibility::DeflateMaskBytes(bytes);
      if (deflated.size() < bytes.size()) {
        bytes = std::move(deflated);
        e->set_deflated(true);
      }
    }
    e->set_triangles(std::move(bytes));
    objects_cell_ = ready.cell;
    objects_rank_ = static_cast<size_t>(w - wanted.begin());
    for (const visibility::MaskObject& o : mask.sets) {
      if (held.count(o.object) == 0) objects_.push_back(o.object);
    }
    last_sent_[ready.cell] = SentMask{e->mask_id(), std::move(mask.sets)};
    stats->set_epsilon_masks(stats->epsilon_masks() + 1);
    stats->set_epsilon_mask_bytes(stats->epsilon_mask_bytes() + e->triangles().size());
    stats->set_bytes_sent(stats->bytes_sent() + mask.message.ByteSizeLong());
    return Sent{std::move(mask.message), ready.cell, mask.compute_ms};
  }
  return std::nullopt;
}

}  // namespace vistream::server
