#include "server/due_timer.h"

#include <chrono>

namespace vistream::server {

namespace {

double SteadyNow() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

DueTimer::DueTimer() : thread_([this] { Run(); }) {}

DueTimer::~DueTimer() {
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  thread_.join();
}

void DueTimer::At(double at_s, std::function<void()> run) {
  {
    std::lock_guard lock(mu_);
    due_.push(Due{at_s, added_++, std::move(run)});
  }
  cv_.notify_all();
}

void DueTimer::Run() {
  std::unique_lock lock(mu_);
  while (!stop_) {
    if (due_.empty()) {
      cv_.wait(lock);
      continue;
    }
    const double at = due_.top().at_s;
    if (at > SteadyNow()) {
      cv_.wait_until(lock, std::chrono::steady_clock::time_point(std::chrono::duration_cast<
                               std::chrono::steady_clock::duration>(std::chrono::duration<double>(at))));
      continue;
    }
    std::function<void()> run = due_.top().run;
    due_.pop();
    lock.unlock();
    run();
    lock.lock();
  }
}

}  // namespace vistream::server
