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
  if (pvs->from_store) {
    ++stats_.store_hits;
  } else {
    ++stats_.computed;
    stats_.compute_s += seconds;
  }
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

// PvsWorkerPool: the workers, shared round robin by the schedulers.

PvsWorkerPool::PvsWorkerPool(unsigned threads) : threads_(std::max(1u, threads)) {
  for (unsigned w = 0; w < threads_; ++w) workers_.emplace_back([this, w] { WorkerLoop(w); });
}

PvsWorkerPool::~PvsWorkerPool() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  work_.notify_all();
  workers_.clear();  // joins
}

void PvsWorkerPool::Add(PvsScheduler* lane) {
  std::lock_guard lock(mu_);
  lanes_.push_back(lane);
}

void PvsWorkerPool::Remove(PvsScheduler* lane) {
  std::unique_lock lock(mu_);
  std::erase(lanes_, lane);
  next_lane_ = 0;
  idle_.wait(lock, [&] { return lane->running_ == 0; });
}

void PvsWorkerPool::WorkerLoop(unsigned worker) {
  std::unique_lock lock(mu_);
  for (;;) {
    PvsScheduler* lane = nullptr;
    work_.wait(lock, [&] {
      if (stopping_) return true;
      for (size_t k = 0; k < lanes_.size(); ++k) {
        PvsScheduler* l = lanes_[(next_lane_ + k) % lanes_.size()];
        if (l->policy_.HasQueued()) {
          lane = l;
          next_lane_ = (next_lane_ + k + 1) % lanes_.size();
          return true;
        }
      }
      return false;
    });
    if (stopping_) return;
    const CellId cell = *lane->policy_.StartNext();
    ++lane->running_;
    const bool init = lane->init_ && !lane->initialised_[worker];
    lane->initialised_[worker] = 1;
    lock.unlock();
    if (init) lane->init_(worker);
    const auto start = std::chrono::steady_clock::now();
    auto pvs = std::make_shared<CellPvs>(lane->compute_(cell, worker));
    pvs->cell = cell;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    lock.lock();
    std::vector<PvsSource::Done> done = lane->policy_.Finish(pvs, seconds);
    const std::function<void(double)> observe = lane->observe_;
    lock.unlock();
    if (observe && !pvs->from_store) observe(seconds);
    for (PvsSource::Done& d : done) {
      if (d) d(pvs);
    }
    lock.lock();
    --lane->running_;
    idle_.notify_all();
  }
}

// PvsScheduler: the policy on a pool's workers.

PvsScheduler::PvsScheduler(Compute compute, unsigned threads, size_t cache_bytes, std::function<void(unsigned)> init)
    : compute_(std::move(compute)), init_(std::move(init)), own_pool_(std::make_unique<PvsWorkerPool>(threads)),
      pool_(own_pool_.get()), mu_(pool_->mu_), policy_(cache_bytes), initialised_(pool_->threads(), 0) {
  pool_->Add(this);
}

PvsScheduler::PvsScheduler(Compute compute, PvsWorkerPool* pool, size_t cache_bytes,
                           std::function<void(unsigned)> init)
    : compute_(std::move(compute)), init_(std::move(init)), pool_(pool), mu_(pool_->mu_), policy_(cache_bytes),
      initialised_(pool_->threads(), 0) {
  pool_->Add(this);
}

PvsScheduler::~PvsScheduler() {
  pool_->Remove(this);
  own_pool_.reset();  // joins its workers
}

void PvsScheduler::SetComputeObserver(std::function<void(double)> observe) {
  std::lock_guard lock(mu_);
  observe_ = std::move(observe);
}

CellPvsPtr PvsScheduler::Request(uint64_t requester, CellId cell, double deadline, Done done) {
  bool queued = false;
  CellPvsPtr cached;
  {
    std::lock_guard lock(mu_);
    cached = policy_.Request(requester, cell, deadline, std::move(done), &queued);
  }
  // Every worker looks: the one that wakes may find another scheduler's job first.
  if (queued) pool_->work_.notify_all();
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

}  // namespace vistream::server
