#pragma once
// Where a session's small background jobs (ε-masks) run: TaskQueue, a worker thread, in the
// server; the simulator's own runner on simulated time (server/simulator.h).

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>

namespace vistream::server {

class TaskRunner {
 public:
  // A job in two steps: the work (run off the caller's thread, or at a simulated time, whose
  // length the simulator measures), which returns what delivers its result (run right after
  // it by TaskQueue, or when the simulated work ends). The delivery may be empty.
  using Work = std::function<std::function<void()>()>;
  virtual ~TaskRunner() = default;
  virtual void Post(Work work) = 0;
};

// A worker thread, first in first out. Bounded: when more than `capacity` jobs wait, the
// oldest is dropped (its owner asks again if it still cares).
class TaskQueue : public TaskRunner {
 public:
  explicit TaskQueue(size_t capacity = 64) : capacity_(capacity), thread_([this] { Loop(); }) {}
  ~TaskQueue() {
    {
      std::lock_guard lock(mu_);
      stopping_ = true;
    }
    cv_.notify_all();
  }
  TaskQueue(const TaskQueue&) = delete;
  TaskQueue& operator=(const TaskQueue&) = delete;

  void Post(Work task) override {
    {
      std::lock_guard lock(mu_);
      if (tasks_.size() >= capacity_) tasks_.pop_front();
      tasks_.push_back(std::move(task));
    }
    cv_.notify_one();
  }

 private:
  void Loop() {
    std::unique_lock lock(mu_);
    for (;;) {
      cv_.wait(lock, [&] { return stopping_ || !tasks_.empty(); });
      if (stopping_) return;
      Work task = std::move(tasks_.front());
      tasks_.pop_front();
      lock.unlock();
      if (std::function<void()> deliver = task()) deliver();
      lock.lock();
    }
  }

  size_t capacity_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::deque<Work> tasks_;
  std::jthread thread_;  // last: starts after the members it reads
};

}  // namespace vistream::server
