#include "server/pvs_scheduler.h"

#include <chrono>

namespace vistream::server {

PvsScheduler::PvsScheduler(Compute compute, unsigned threads, size_t cache_bytes, std::function<void(unsigned)> init)
    : compute_(std::move(compute)), init_(std::move(init)), cache_budget_(cache_bytes) {
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
  if (auto it = cache_.find(cell); it != cache_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second);
    ++stats_.cache_hits;
    return *it->second;
  }
  auto [it, fresh] = jobs_.try_emplace(cell);
  Job& job = it->second;
  if (!fresh && job.waiters.find(requester) == job.waiters.end()) ++stats_.cache_hits;  // joins a job
  job.waiters[requester] = Waiter{deadline, std::move(done)};
  Requeue(cell, &job);
  return nullptr;
}

void PvsScheduler::Cancel(uint64_t requester, CellId cell) {
  std::lock_guard lock(mu_);
  auto it = jobs_.find(cell);
  if (it == jobs_.end() || it->second.waiters.erase(requester) == 0) return;
  Requeue(cell, &it->second);
  if (it->second.waiters.empty() && !it->second.running) {
    jobs_.erase(it);
    ++stats_.dropped;
  }
}

void PvsScheduler::CancelAll(uint64_t requester) {
  std::lock_guard lock(mu_);
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

CellPvsPtr PvsScheduler::Cached(CellId cell) {
  std::lock_guard lock(mu_);
  auto it = cache_.find(cell);
  if (it == cache_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second);
  return *it->second;
}

SchedulerStats PvsScheduler::stats() const {
  std::lock_guard lock(mu_);
  SchedulerStats s = stats_;
  s.queued = queue_.size();
  return s;
}

void PvsScheduler::Requeue(CellId cell, Job* job) {
  if (!job->running) queue_.erase({job->key, cell});
  if (job->waiters.empty()) return;
  double key = job->waiters.begin()->second.deadline;
  for (const auto& [id, w] : job->waiters) key = std::min(key, w.deadline);
  job->key = key;
  if (!job->running) {
    queue_.insert({key, cell});
    work_.notify_one();
  }
}

void PvsScheduler::Insert(const CellPvsPtr& pvs) {
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

void PvsScheduler::WorkerLoop(unsigned worker) {
  if (init_) init_(worker);
  std::unique_lock lock(mu_);
  for (;;) {
    work_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
    if (stopping_) return;
    const CellId cell = queue_.begin()->second;
    queue_.erase(queue_.begin());
    jobs_[cell].running = true;
    lock.unlock();
    const auto start = std::chrono::steady_clock::now();
    auto pvs = std::make_shared<CellPvs>(compute_(cell, worker));
    pvs->cell = cell;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    lock.lock();
    ++stats_.computed;
    stats_.compute_s += seconds;
    Insert(pvs);
    std::map<uint64_t, Waiter> waiters = std::move(jobs_[cell].waiters);
    jobs_.erase(cell);
    lock.unlock();
    for (auto& [id, w] : waiters) {
      if (w.done) w.done(pvs);
    }
    lock.lock();
  }
}

}  // namespace vistream::server
