#include "server/admission.h"

#include <absl/strings/str_cat.h>
#include <absl/strings/str_replace.h>

namespace vistream::server {

std::string PeerHost(std::string_view peer) {
  const std::string p = absl::StrReplaceAll(absl::string_view(peer.data(), peer.size()),
                                            {{"%5B", "["}, {"%5D", "]"}, {"%5b", "["}, {"%5d", "]"}});
  std::string_view rest(p);
  if (rest.rfind("ipv4:", 0) == 0) {
    rest.remove_prefix(5);
    return std::string(rest.substr(0, rest.rfind(':')));
  }
  if (rest.rfind("ipv6:", 0) == 0) {
    rest.remove_prefix(5);
    if (!rest.empty() && rest.front() == '[') {
      const size_t close = rest.find(']');
      if (close != std::string_view::npos) return std::string(rest.substr(1, close - 1));
    }
    return std::string(rest.substr(0, rest.rfind(':')));
  }
  return p;
}

absl::Status SessionQuota::Admit(const std::string& host, const std::string& tenant) {
  std::lock_guard lock(mu_);
  if (per_address_ > 0 && by_host_[host] >= per_address_) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "too many sessions from ", host, ": at most ", per_address_,
        " at once per client address (limits.max_sessions_per_address, --max-sessions-per-address)"));
  }
  if (per_tenant_ > 0 && !tenant.empty() && by_tenant_[tenant] >= per_tenant_) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "too many sessions for tenant '", tenant, "': at most ", per_tenant_,
        " at once per token (limits.max_sessions_per_token, --max-sessions-per-token)"));
  }
  ++by_host_[host];
  if (!tenant.empty()) ++by_tenant_[tenant];
  return absl::OkStatus();
}

void SessionQuota::Release(const std::string& host, const std::string& tenant) {
  std::lock_guard lock(mu_);
  if (auto it = by_host_.find(host); it != by_host_.end() && --it->second == 0) by_host_.erase(it);
  if (tenant.empty()) return;
  if (auto it = by_tenant_.find(tenant); it != by_tenant_.end() && --it->second == 0) by_tenant_.erase(it);
}

size_t SessionQuota::sessions_from(const std::string& host) const {
  std::lock_guard lock(mu_);
  auto it = by_host_.find(host);
  return it == by_host_.end() ? 0 : it->second;
}

size_t SessionQuota::sessions_of(const std::string& tenant) const {
  std::lock_guard lock(mu_);
  auto it = by_tenant_.find(tenant);
  return it == by_tenant_.end() ? 0 : it->second;
}

HelloWatchdog::HelloWatchdog(double timeout_s) : timeout_s_(timeout_s) {}

HelloWatchdog::~HelloWatchdog() = default;

void HelloWatchdog::Watch(std::weak_ptr<Session> session, std::function<void()> expire) {
  const double due =
      std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count() + timeout_s_;
  timer_.At(due, [session = std::move(session), expire = std::move(expire)] {
    if (std::shared_ptr<Session> s = session.lock(); s != nullptr && !s->greeted()) expire();
  });
}

}  // namespace vistream::server
