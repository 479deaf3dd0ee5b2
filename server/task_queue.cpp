#include "server/task_queue.h"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <time.h>

#include <algorithm>

namespace vistream::server {

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

namespace {

// SCHED_IDLE for the calling thread; false if the kernel refused (it then gets nice 19).
bool LowerCallingThread() {
#ifdef SCHED_IDLE
  sched_param p{};
  p.sched_priority = 0;
  if (pthread_setschedparam(pthread_self(), SCHED_IDLE, &p) == 0) return true;
#endif
  setpriority(PRIO_PROCESS, 0, 19);  // per thread on Linux (0: the calling thread)
  return false;
}

}  // namespace

MaskQueue::MaskQueue(unsigned threads, size_t capacity, bool idle_priority)
    : capacity_(std::max<size_t>(1, capacity)), want_idle_(idle_priority) {
  for (unsigned k = 0; k < std::max(1u, threads); ++k) threads_.emplace_back([this] { Loop(); });
}

MaskQueue::~MaskQueue() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  threads_.clear();  // joins
}

void MaskQueue::Post(Work work, double deadline) {
  {
    std::lock_guard lock(mu_);
    tasks_.emplace(std::pair{deadline, seq_++}, std::move(work));
    if (tasks_.size() > capacity_) {
      tasks_.erase(std::prev(tasks_.end()));
      ++stats_.dropped;
    }
  }
  cv_.notify_one();
}

TaskStats MaskQueue::stats() const {
  std::lock_guard lock(mu_);
  TaskStats s = stats_;
  s.queued = tasks_.size();
  return s;
}

bool MaskQueue::idle_priority() const {
  std::lock_guard lock(mu_);
  return want_idle_ && idle_ok_;
}

void MaskQueue::Loop() {
  if (want_idle_ && !LowerCallingThread()) {
    std::lock_guard lock(mu_);
    idle_ok_ = false;
  }
  std::unique_lock lock(mu_);
  for (;;) {
    cv_.wait(lock, [&] { return stopping_ || !tasks_.empty(); });
    if (stopping_) return;
    Work work = std::move(tasks_.begin()->second);
    tasks_.erase(tasks_.begin());
    lock.unlock();
    const double start = ThreadCpuSeconds();
    std::function<void()> deliver = work();
    const double cpu = ThreadCpuSeconds() - start;
    if (deliver) deliver();
    lock.lock();
    if (deliver) {
      ++stats_.computed;
      stats_.cpu_s += cpu;
    } else {
      ++stats_.dropped;
    }
  }
}

}  // namespace vistream::server
