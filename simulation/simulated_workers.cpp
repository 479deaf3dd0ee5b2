#include "simulation/simulated_workers.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace vistream::simulation {

namespace {

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

// EventQueue

void EventQueue::At(double t, std::function<void()> fn) { events_.push(Event{std::max(t, now_), seq_++, std::move(fn)}); }

void EventQueue::RunNext() {
  Event e = events_.top();
  events_.pop();
  now_ = e.t;
  e.fn();
}

// PvsMemo

const PvsMemo::Entry& PvsMemo::Get(const server::ServedScene& scene, CellId cell) {
  auto it = entries_.find(cell);
  if (it != entries_.end()) return it->second;
  const double start = WallSeconds();
  auto pvs = std::make_shared<server::CellPvs>(scene.ComputePvs(cell, 0));
  pvs->cell = cell;
  const double seconds = WallSeconds() - start;
  return entries_.emplace(cell, Entry{std::move(pvs), seconds}).first->second;
}

const PvsMemo::Entry& PvsMemo::GetRadius(const server::ServedScene& scene, CellId cell, double radius_m) {
  auto it = radius_entries_.find({cell, radius_m});
  if (it != radius_entries_.end()) return it->second;
  const double start = WallSeconds();
  auto pvs = std::make_shared<server::CellPvs>();
  pvs->cell = cell;
  const scenes::Aabb box = scene.grid().CellBox(cell);
  for (const scenes::Object& o : scene.scene().objects) {
    if (scenes::BoxDistance(box, o.bounds) <= radius_m) pvs->objects.push_back(o.id);
  }
  const double seconds = WallSeconds() - start;
  return radius_entries_.emplace(std::make_pair(cell, radius_m), Entry{std::move(pvs), seconds}).first->second;
}

// SimulatedScheduler

SimulatedScheduler::SimulatedScheduler(EventQueue* queue, Compute compute, unsigned workers, size_t cache_bytes,
                                       bool cache)
    : queue_(queue), compute_(std::move(compute)), workers_(std::max(1u, workers)), policy_(cache_bytes, cache) {}

CellPvsPtr SimulatedScheduler::Request(uint64_t requester, CellId cell, double deadline, Done done) {
  return policy_.Request(requester, cell, deadline, std::move(done));
}
void SimulatedScheduler::Cancel(uint64_t requester, CellId cell) { policy_.Cancel(requester, cell); }
void SimulatedScheduler::CancelAll(uint64_t requester) { policy_.CancelAll(requester); }
CellPvsPtr SimulatedScheduler::Cached(CellId cell) { return policy_.Cached(cell); }
server::SchedulerStats SimulatedScheduler::stats() const { return policy_.stats(); }

void SimulatedScheduler::Dispatch(const std::function<void(CellId, double)>& on_start) {
  while (busy_ < workers_) {
    const std::optional<CellId> cell = policy_.StartNext();
    if (!cell.has_value()) return;
    double seconds = 0.0;
    CellPvsPtr pvs = compute_(*cell, &seconds);
    ++busy_;
    if (on_start) on_start(*cell, seconds);
    queue_->At(queue_->now() + seconds, [this, pvs, seconds] {
      --busy_;
      for (Done& d : policy_.Finish(pvs, seconds)) {
        if (d) d(pvs);
      }
    });
  }
}

// SimulatedTaskRunner

void SimulatedTaskRunner::Dispatch() {
  while (!busy_ && !waiting_.empty() && (!may_start_ || may_start_())) {
    Work work = std::move(waiting_.begin()->second);
    waiting_.erase(waiting_.begin());
    const double start = WallSeconds();
    std::function<void()> deliver = work();
    if (!deliver) {
      ++dropped_;
      continue;  // stale: no time spent
    }
    const double seconds = fixed_s_.has_value() ? *fixed_s_ : WallSeconds() - start;
    busy_ = true;
    ++ran_;
    busy_s_ += seconds;
    queue_->At(queue_->now() + seconds, [this, deliver = std::move(deliver)] {
      busy_ = false;
      deliver();
    });
  }
}

}  // namespace vistream::simulation
