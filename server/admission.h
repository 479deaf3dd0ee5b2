#pragma once
// Limits a public server puts on sessions apart from their messages: how many one client
// address and one tenant (token) may hold at once, and how long a new stream may take to say
// Hello. The service (server/service.h) asks SessionQuota before it starts a session and tells
// it when the session ends; HelloWatchdog ends streams that stay silent.

#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>

#include <absl/status/status.h>

#include "server/due_timer.h"
#include "server/session.h"

namespace vistream::server {

// The client address of a gRPC peer string: "ipv4:127.0.0.1:5000" -> "127.0.0.1",
// "ipv6:[::1]:5000" (brackets also as %5B, %5D) -> "::1"; anything else as given.
std::string PeerHost(std::string_view peer);

// Sessions at once per client address and per tenant; a limit of 0 is none. Thread-safe.
class SessionQuota {
 public:
  SessionQuota(size_t per_address, size_t per_tenant) : per_address_(per_address), per_tenant_(per_tenant) {}

  // Counts one more session from `host` for `tenant` (empty: no tenant), or, when that would
  // break a limit, counts nothing and returns RESOURCE_EXHAUSTED naming the limit (its
  // configuration key and option) and the address or tenant.
  absl::Status Admit(const std::string& host, const std::string& tenant);
  // A session Admit counted has ended.
  void Release(const std::string& host, const std::string& tenant);

  size_t sessions_from(const std::string& host) const;
  size_t sessions_of(const std::string& tenant) const;

 private:
  const size_t per_address_, per_tenant_;
  mutable std::mutex mu_;
  std::map<std::string, size_t> by_host_, by_tenant_;
};

// One thread that ends sessions which have not said Hello `timeout_s` seconds after they began.
class HelloWatchdog {
 public:
  explicit HelloWatchdog(double timeout_s);
  ~HelloWatchdog();
  HelloWatchdog(const HelloWatchdog&) = delete;
  HelloWatchdog& operator=(const HelloWatchdog&) = delete;

  // Watches a session that begins now: if it still exists and has not been greeted
  // (Session::greeted) after the timeout, `expire` is called, on the watchdog's thread.
  void Watch(std::weak_ptr<Session> session, std::function<void()> expire);
  double timeout_s() const { return timeout_s_; }

 private:
  const double timeout_s_;
  DueTimer timer_;  // last: its thread runs while the member above exists
};

}  // namespace vistream::server
