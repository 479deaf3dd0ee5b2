#pragma once
// A worker thread for small background jobs (ε-masks), first in first out. Bounded: when more
// than `capacity` jobs wait, the oldest is dropped (its owner asks again if it still cares).

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>

namespace vistream::server {

class TaskQueue {
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

  void Post(std::function<void()> task) {
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
      std::function<void()> task = std::move(tasks_.front());
      tasks_.pop_front();
      lock.unlock();
      task();
      lock.lock();
    }
  }

  size_t capacity_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::deque<std::function<void()>> tasks_;
  std::jthread thread_;  // last: starts after the members it reads
};

}  // namespace vistream::server
