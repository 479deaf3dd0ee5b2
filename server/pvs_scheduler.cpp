#include "server/pvs_scheduler.h"

#include <chrono>

namespace vistream::server {

// PvsSchedulePolicy: the policy, shared by the threaded scheduler and the simulated one.

CellPvsPtr PvsSchedulePolicy::Request(uint64_t requester, CellId cell, double deadline, Done done, bool* queued) {
  if (queued != nullptr) *queued = false;
  if (auto it = cache_.find(cell); it != cache_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second);
    ++stats_.cache_hits;
    return *it->second;
  }
  auto [it, fresh] = jobs_.try_emplace(cell);
  Job& job = it->second;
  if (!fresh && job.waiters.find(requester) == job.waiters.end()) ++stats_.cache_hits;  // joins a job
  job.waiters[requester] = Waiter{deadline, std::move(done)};
  const bool q = Requeue(cell, &job);
  if (queued != nullptr) *queued = q;
  return nullptr;
}

void PvsSchedulePolicy::Cancel(uint64_t requester, CellId cell) {
  auto it = jobs_.find(cell);
  if (it == jobs_.end() || it->second.waiters.erase(requester) == 0) return;
  Requeue(cell, &it->second);
  if (it->second.waiters.empty() && !it->second.running) {
    jobs_.erase(it);
    ++stats_.dropped;
  }
}

void PvsSchedulePolicy::CancelAll(uint64_t requester) {
  for (auto it = jobs_.begin(); it != jobs_.end();) {
    if (it->second.waiters.erase(requester) > 0) Requeue(it->first, &it->second);
    if (it->second.waiters.empty() && !it->second.running) {
      it = jobs_.erase(it);
      ++stats_.dropped;
    } else {
      ++it;
    }
  }
}

CellPvsPtr PvsSchedulePolicy::Cached(CellId cell) {
  auto it = cache_.find(cell);
  if (it == cache_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second);
  return *it->second;
}

SchedulerStats PvsSchedulePolicy::stats() const {
  SchedulerStats s = stats_;
  s.queued = queue_.size();
  return s;
}

bool PvsSchedulePolicy::Requeue(CellId cell, Job* job) {
  if (!job->running) queue_.erase({job->key, cell});
  if (job->waiters.empty()) return false;
  double key = job->waiters.begin()->second.deadline;
  for (const auto& [id, w] : job->waiters) key = std::min(key, w.deadline);
  job->key = key;
  if (job->running) return false;
  queue_.insert({key, cell});
  return true;
}

std::optional<CellId> PvsSchedulePolicy::StartNext() {
  if (queue_.empty()) return std::nullopt;
  const CellId cell = queue_.begin()->second;
  queue_.erase(queue_.begin());
  jobs_[cell].running = true;
  return cell;
}

std::vector<PvsSchedulePolicy::Done> PvsSchedulePolicy::Finish(const CellPvsPtr& pvs, double seconds) {
  ++stats_.computed;
  stats_.compute_s += seconds;
  if (use_cache_) Insert(pvs);
  std::vector<Done> done;
  auto it = jobs_.find(pvs->cell);
  if (it == jobs_.end()) return done;
  for (auto& [id, w] : it->second.waiters) done.push_back(std::move(w.done));
  jobs_.erase(it);
  return done;
}

void PvsSchedulePolicy::Insert(const CellPvsPtr& pvs) {
  if (cache_.count(pvs->cell) > 0) return;
  lru_.push_front(pvs);
  cache_[pvs->cell] = lru_.begin();
  stats_.cache_bytes += pvs->Bytes();
  // Keep at least the newest entry, whatever the budget.
  while (stats_.cache_bytes > cache_budget_ && lru_.size() > 1) {
    const CellPvsPtr& old = lru_.back();
    stats_.cache_bytes -= old->Bytes();
    cache_.erase(old->cell);
    lru_.pop_back();
  }
}

// PvsScheduler: the policy on a pool of worker threads.

PvsScheduler::PvsScheduler(Compute compute, unsigned threads, size_t cache_bytes, std::function<void(unsigned)> init)
    : compute_(std::move(compute)), init_(std::move(init)), policy_(cache_bytes) {
  for (unsigned w = 0; w < std::max(1u, threads); ++w) workers_.emplace_back([this, w] { WorkerLoop(w); });
}

PvsScheduler::~PvsScheduler() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  work_.notify_all();
  workers_.clear();  // joins
}

CellPvsPtr PvsScheduler::Request(uint64_t requester, CellId cell, double deadline, Done done) {
  std::lock_guard lock(mu_);
  bool queued = false;
  CellPvsPtr cached = policy_.Request(requester, cell, deadline, std::move(done), &queued);
  if (queued) work_.notify_one();
  return cached;
}

void PvsScheduler::Cancel(uint64_t requester, CellId cell) {
  std::lock_guard lock(mu_);
  policy_.Cancel(requester, cell);
}

void PvsScheduler::CancelAll(uint64_t requester) {
  std::lock_guard lock(mu_);
  policy_.CancelAll(requester);
}

CellPvsPtr PvsScheduler::Cached(CellId cell) {
  std::lock_guard lock(mu_);
  return policy_.Cached(cell);
}

SchedulerStats PvsScheduler::stats() const {
  std::lock_guard lock(mu_);
  return policy_.stats();
}

void PvsScheduler::WorkerLoop(unsigned worker) {
  if (init_) init_(worker);
  std::unique_lock lock(mu_);
  for (;;) {
    work_.wait(lock, [&] { return stopping_ || policy_.HasQueued(); });
    if (stopping_) return;
    const CellId cell = *policy_.StartNext();
    lock.unlock();
    const auto start = std::chrono::steady_clock::now();
    auto pvs = std::make_shared<CellPvs>(compute_(cell, worker));
    pvs->cell = cell;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    lock.lock();
    std::vector<Done> done = policy_.Finish(pvs, seconds);
    lock.unlock();
    for (Done& d : done) {
      if (d) d(pvs);
    }
    lock.lock();
  }
}

}  // namespace vistream::server
