#pragma once
// The vistream-server process once its settings are decided (DESIGN.md "Deployment"): reads the
// TLS and token files, connects the shared PVS store, loads the scenes onto one worker pool,
// starts the service with its metrics and health endpoint, prints one line on stdout when it is
// ready, and serves until SIGTERM or SIGINT; then it drains: /healthz says 503 at once, the
// sessions are served on for up to drain_s seconds (a load balancer takes the replica out
// meanwhile), then they end with UNAVAILABLE (their clients resume elsewhere) and it returns
// within grace_s. A second signal stops the process at once (exit 1); SIGHUP re-reads the token
// file. Logs one line per event on stderr or to the log file (server/event_log.h).

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include "server/server_config.h"

namespace vistream::server {

struct ServerProcessOptions {
  // The configuration file's settings with the command line's over them, checked
  // (CheckServerConfig).
  ServerConfig config;
  // Whether a command-line option ("--tokens") was given: errors in what an option gave name
  // the option, errors in what the file gave name its key and line. Empty: none was given.
  std::function<bool(const char* option)> given;
  // Link emulation (vistream-server --emulate-link, --link, --time-scale, --link-seed): the
  // first scene's declared link (server/link_model.h), or `link_option` (a checked --link
  // BPS,LATENCY_MS) over it, time-scaled by `time_scale` (> 0).
  bool emulate_link = false;
  std::optional<std::string> link_option;
  double time_scale = 1.0;
  uint64_t link_seed = 1;
};

// Runs the server as above. Returns the process's exit code: 0 after a drain (or a stop while
// the scenes loaded), 2 for a bad setting found before any scene loads (a TLS, token or
// password file, a catalog name, the store refusing this server), 1 for a run-time error (a
// scene that does not load, an address that cannot be bound). Errors are printed on stderr as
// "vistream-server: error: ...", naming the option or the file's key and line.
int RunServerProcess(const ServerProcessOptions& options);

}  // namespace vistream::server
