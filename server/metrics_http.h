#pragma once
// The metrics HTTP endpoint (cpp-httplib, on its own threads):
//   GET /metrics  200, text/plain; version=0.0.4, the registry's Render()
//   GET /healthz  200 "serving\n" while healthy() is true, 503 "draining\n" otherwise
//   anything else 404

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "absl/status/statusor.h"
#include "server/metrics.h"

namespace httplib {
class Server;
}

namespace vistream::server {

class MetricsHttpServer {
 public:
  // Listens on `listen`, HOST:PORT (an IPv6 address in brackets, [::1]:9464; port 0: any free
  // one), exactly that address: no wildcard unless HOST is one (0.0.0.0, [::]), and a port
  // another socket listens on is an error, not shared. `registry` (not owned) must outlive the
  // server; `healthy` (null: always healthy) is called on the server's threads, so it must be
  // thread-safe. Returns once the server accepts connections.
  // Errors: INVALID_ARGUMENT for a malformed address (naming it), UNAVAILABLE when it cannot
  // listen there (naming the address and why: in use, not an address of this machine, ...).
  static absl::StatusOr<std::unique_ptr<MetricsHttpServer>> Start(const std::string& listen,
                                                                  MetricsRegistry* registry,
                                                                  std::function<bool()> healthy);
  ~MetricsHttpServer();
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  int port() const { return port_; }                       // the bound port
  const std::string& address() const { return address_; }  // HOST:PORT with the bound port

  // Stops accepting, ends the connections (waiting up to about a second for an idle kept-alive
  // one) and joins the threads. Idempotent and thread-safe; the destructor stops too.
  void Stop();

 private:
  MetricsHttpServer() = default;

  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
  std::mutex stop_mu_;
  int port_ = 0;
  std::string address_;
};

}  // namespace vistream::server
