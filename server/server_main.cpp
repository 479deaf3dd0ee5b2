// vistream-server: serves one scene to walkthrough clients over gRPC (DESIGN.md, "Server and
// client"). Prints one line on stdout when it is ready; logs one line per session event on
// stderr. SIGTERM or SIGINT drains the sessions and exits 0.

#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <thread>

#include <grpc/support/log.h>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>

#include "cli/number_options.h"
#include "cli/stop_signal.h"
#include "cli/unexpected_arguments.h"
#include "scenes/catalog.h"
#include "server/event_log.h"
#include "server/link_model.h"
#include "server/security.h"
#include "server/served_scene.h"
#include "server/service.h"

namespace {

using vistream::server::EventLog;

// Load progress as log lines, one per 10% of a task.
class LogProgress : public vistream::scenes::ProgressSink {
 public:
  explicit LogProgress(EventLog* log) : log_(log) {}
  void Start(std::string_view, uint64_t) override { last_decile_ = -1; }
  void Update(std::string_view label, uint64_t done, uint64_t total, double seconds, std::string_view) override {
    const int decile = static_cast<int>(10 * done / (total == 0 ? 1 : total));
    if (decile == last_decile_ || done == total) return;
    last_decile_ = decile;
    log_->Write(0, "progress", {{"task", label}, {"percent", decile * 10}, {"seconds", seconds}});
  }
  void End(std::string_view label, double seconds, bool completed) override {
    log_->Write(0, completed ? "done" : "stopped", {{"task", label}, {"seconds", seconds}});
  }

 private:
  EventLog* log_;
  int last_decile_ = -1;
};

std::atomic<bool> g_stop{false};
volatile std::sig_atomic_t g_signal = 0;
std::atomic<int64_t> g_first_signal_ns{0};
EventLog* g_log = nullptr;

// gRPC's own log lines go into the server's log.
void GrpcLog(gpr_log_func_args* args) {
  if (g_log == nullptr || args == nullptr || args->message == nullptr) return;
  g_log->Write(0, "grpc", {{"severity", gpr_log_severity_string(args->severity)}, {"message", args->message}});
}

// A finite number in [lo, hi], shared with the vistream tool (CLI11's own checks let NaN through).
using vistream::cli::FiniteRange;

// SIGHUP re-reads the token file (main polls the flag); the sessions open stay open.
std::atomic<bool> g_reload{false};

void ReloadTokens(vistream::server::TokenStore* tokens, EventLog* log) {
  if (tokens == nullptr) {
    log->Write(0, "sighup_ignored", {{"reason", "no --tokens file to reload"}});
    return;
  }
  if (const absl::Status st = tokens->Reload(); !st.ok()) {
    log->Write(0, "tokens_reload_failed",
               {{"error", std::string(st.message())}, {"tenants", static_cast<uint64_t>(tokens->size())}});
    return;
  }
  log->Write(0, "tokens_reloaded", {{"file", tokens->path()}, {"tenants", static_cast<uint64_t>(tokens->size())}});
}

}  // namespace

int main(int argc, char** argv) {
  vistream::server::ServedSceneOptions scene_options;
  vistream::server::ServerOptions server_options;
  bool json_log = false;
  double cache_mb = 256;
  double grace_s = 5;
  CLI::App app{"vistream-server: streams the visible part of a city to walkthrough clients over gRPC"};
  app.add_option("--scene", scene_options.scene, "catalog name, catalog .json or .glb/.gltf file")->required();
  app.add_option("--catalog", scene_options.catalog_dir, "folder of catalog entries (default: the source tree's scenes/)");
  app.add_option("--listen", server_options.listen, "address to listen on, host:port (port 0: any free one)")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            const size_t colon = text.rfind(':');
            int64_t port = -1;
            if (colon == std::string::npos || colon == 0 ||
                !vistream::cli::internal::ParseWhole(text.substr(colon + 1), &port) || port < 0 || port > 65535) {
              return "'" + text + "' is not host:port with a port from 0 to 65535 (e.g. 127.0.0.1:50051)";
            }
            return "";
          },
          "HOST:PORT"));
  app.add_option("--threads", scene_options.threads, "PVS worker threads (0: one per core)")->capture_default_str();
  app.add_option("--cell-size", scene_options.cell_size, "viewcell edge in metres (default: the catalog entry's)")
      ->check(FiniteRange(0.01, 1e6));
  app.add_option("--res", scene_options.res, "finest dual-ray-space raster (power of two, 1 to 256)")
      ->capture_default_str()
      ->check(vistream::cli::PowerOfTwo(1, 256));
  app.add_option("--backend", scene_options.backend, "cpu | gl | exact")->check(CLI::IsMember({"cpu", "gl", "exact"}))
      ->capture_default_str();
  app.add_option("--pvs-file", scene_options.pvs_file,
                 "serve the PVSs of this file (vistream agvs -o, vistream pvs --all -o) instead of computing them");
  app.add_option("--max-sessions", server_options.max_sessions, "sessions at once; more are refused")
      ->check(vistream::cli::WholeRange(1, 100000))->capture_default_str();
  app.add_option("--cache-mb", cache_mb, "PVS cache budget in MiB")->check(FiniteRange(1, 1e6))->capture_default_str();
  app.add_option("--max-pose-rate", server_options.limits.max_pose_rate_hz, "poses per second a session may send")
      ->check(FiniteRange(0.1, 100000))->capture_default_str();
  app.add_option("--grace", grace_s, "seconds sessions get to end on shutdown")->check(FiniteRange(0, 3600))
      ->capture_default_str();
  app.add_flag("--json-log", json_log, "log JSON lines instead of text");
  // Security (server/security.h): configuration keys tls.*, auth.tokens and limits.*.
  vistream::server::TlsSettings tls;
  std::string tokens_file;
  app.add_option("--tls-cert", tls.cert, "PEM certificate chain: serve TLS (with --tls-key)");
  app.add_option("--tls-key", tls.key, "PEM private key of --tls-cert (unencrypted)");
  app.add_option("--tls-client-ca", tls.client_ca,
                 "PEM CA bundle: clients must present a certificate it signed (mutual TLS)");
  app.add_flag("--insecure", tls.insecure, "allow plaintext on an address that is not loopback");
  app.add_option("--tokens", tokens_file,
                 "file of `name token` lines: sessions need one of its tokens (re-read on SIGHUP)");
  app.add_option("--hello-timeout", server_options.hello_timeout_s,
                 "seconds a new stream has to send Hello before it ends DEADLINE_EXCEEDED (0: no limit)")
      ->check(FiniteRange(0, 86400))
      ->capture_default_str();
  app.add_option("--max-sessions-per-address", server_options.max_sessions_per_address,
                 "sessions at once from one client address (0: no limit)")
      ->check(vistream::cli::WholeRange(0, 100000))
      ->capture_default_str();
  app.add_option("--max-sessions-per-token", server_options.max_sessions_per_token,
                 "sessions at once per token (0: no limit)")
      ->check(vistream::cli::WholeRange(0, 100000))
      ->capture_default_str();
  bool emulate_link = false;
  std::string link_option, time_scale_option;
  uint64_t link_seed = 1;
  app.add_flag("--emulate-link", emulate_link,
               "put each session's traffic through the link its scene's catalog entry declares "
               "(simulation.link; none declared: an ideal link)");
  app.add_option("--link", link_option,
                 "BPS,LATENCY_MS: emulate this bandwidth (bits/s, k/M/G) and one-way latency instead of the "
                 "declared ones (keeps the declared jitter and loss); implies --emulate-link");
  app.add_option("--time-scale", time_scale_option,
                 "K > 0: the emulated link runs K times faster (bandwidth x K, times / K), for walks replayed "
                 "K times faster (default 1)");
  app.add_option("--link-seed", link_seed, "seed of the emulated links' jitter and loss draws")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 9007199254740991.0));  // a whole number from 0 to 2^53 - 1
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (dynamic_cast<const CLI::Success*>(&e) != nullptr) return app.exit(e);
    // Bad options exit 2 before the scene loads, in the vistream tool's form; unknown ones
    // first (a misspelt option often hides a required one).
    std::string message = vistream::cli::UnexpectedArguments(app.remaining(), "vistream-server");
    if (message.empty()) message = e.what();
    for (const std::string& r : app.remaining()) {
      if (r == "--port" || r.rfind("--port=", 0) == 0) message += " (the address is --listen HOST:PORT)";
    }
    std::fprintf(stderr, "vistream-server: error: %s\nRun 'vistream-server --help' for the options.\n", message.c_str());
    return 2;
  }
  double time_scale = 1.0;
  if (app.count("--time-scale") > 0) {
    if (!vistream::cli::internal::ParseFinite(time_scale_option, &time_scale) || !(time_scale > 0.0) ||
        time_scale > 1e6) {
      std::fprintf(stderr, "vistream-server: error: --time-scale: '%s' is not a number greater than 0 and at most "
                           "1e6 (e.g. 20: the link runs 20 times faster)\n",
                   time_scale_option.c_str());
      return 2;
    }
  }
  if (app.count("--link") > 0) {
    // Checked now (bad options exit 2 before the scene loads); applied to the declared link below.
    absl::StatusOr<vistream::scenes::LinkSpec> check = vistream::server::ParseLinkOption(link_option, std::nullopt);
    if (!check.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s\n", std::string(check.status().message()).c_str());
      return 2;
    }
    emulate_link = true;
  }
  if (!emulate_link && (app.count("--time-scale") > 0 || app.count("--link-seed") > 0)) {
    std::fprintf(stderr, "vistream-server: error: --time-scale and --link-seed need --emulate-link or --link\n");
    return 2;
  }
  scene_options.cache_bytes = static_cast<size_t>(cache_mb * (1 << 20));
  {
    // TLS files and the token file are checked before the scene loads: a bad one exits 2.
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
        vistream::server::ServerCredentialsFor(tls, server_options.listen);
    if (!credentials.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s\n", std::string(credentials.status().message()).c_str());
      return 2;
    }
    server_options.credentials = *std::move(credentials);
    if (!tokens_file.empty()) {
      absl::StatusOr<std::shared_ptr<vistream::server::TokenStore>> tokens =
          vistream::server::TokenStore::Load(tokens_file);
      if (!tokens.ok()) {
        std::fprintf(stderr, "vistream-server: error: --tokens: %s\n", std::string(tokens.status().message()).c_str());
        return 2;
      }
      server_options.tokens = *std::move(tokens);
    }
  }

  // SIGTERM and SIGINT only raise a flag (whichever thread takes them); main polls it.
  struct sigaction action {};
  action.sa_handler = [](int sig) {
    // A second signal a second or more after the first stops at once (exit 1): a drain that
    // hangs can be cut short, while one signal delivered twice (by a wrapper) does not count.
    switch (vistream::cli::ClassifyStopSignal(&g_stop, &g_first_signal_ns)) {
      case vistream::cli::StopSignal::kFirst: g_signal = sig; return;
      case vistream::cli::StopSignal::kEcho: return;
      case vistream::cli::StopSignal::kSecond: std::_Exit(1);
    }
  };
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  struct sigaction hup {};
  hup.sa_handler = [](int) { g_reload.store(true); };
  sigemptyset(&hup.sa_mask);
  sigaction(SIGHUP, &hup, nullptr);

  EventLog log(stderr, json_log);
  g_log = &log;
  gpr_set_log_function(GrpcLog);
  LogProgress progress(&log);
  const char* tls_mode = tls.cert.empty() ? "off" : (tls.client_ca.empty() ? "on" : "mutual");
  if (server_options.tokens == nullptr) {
    log.Write(0, "security", {{"tls", tls_mode}, {"tokens", "off"}});
  } else {
    log.Write(0, "security", {{"tls", tls_mode},
                              {"tokens", server_options.tokens->path()},
                              {"tenants", static_cast<uint64_t>(server_options.tokens->size())}});
  }
  log.Write(0, "loading", {{"scene", scene_options.scene}});
  const auto load_start = std::chrono::steady_clock::now();
  absl::StatusOr<std::unique_ptr<vistream::server::ServedScene>> scene =
      vistream::server::ServedScene::Create(scene_options, {&progress, &g_stop});
  if (!scene.ok()) {
    if (g_stop) return 0;
    std::fprintf(stderr, "vistream-server: error: %s\n", std::string(scene.status().message()).c_str());
    return 1;
  }
  if (g_stop) {  // stopped while preparing: nothing to drain
    log.Write(0, "stopped", {});
    return 0;
  }
  vistream::server::ServedScene& s = **scene;
  const vistream::scenes::ViewcellSpec& band = s.viewcell();
  server_options.limits.epsilon_size_m = band.epsilon_m;
  log.Write(0, "scene", {{"name", s.scene().name},
                         {"prepare_s", std::chrono::duration<double>(std::chrono::steady_clock::now() - load_start).count()},
                         {"objects", static_cast<uint64_t>(s.scene().objects.size())},
                         {"triangles", static_cast<uint64_t>(s.scene().TriangleCount())},
                         {"cells", static_cast<uint64_t>(s.grid().CellCount())},
                         {"pvs_source", s.pvs_source()},
                         {"load_s", s.load_seconds()}});
  std::string link_line;
  if (emulate_link) {
    // The link the scene's catalog entry declares (a scene file without an entry: none).
    std::optional<vistream::scenes::LinkSpec> declared;
    std::string source = "the scene declares no link";
    if (absl::StatusOr<vistream::scenes::CatalogEntry> entry =
            vistream::scenes::FindCatalogEntry(scene_options.scene, scene_options.catalog_dir);
        entry.ok() && entry->simulation.link.has_value()) {
      declared = entry->simulation.link;
      source = "declared by " + entry->name;
    }
    if (app.count("--link") > 0) {
      declared = *vistream::server::ParseLinkOption(link_option, declared);
      source = "--link";
    }
    const vistream::server::LinkParams unscaled = vistream::server::LinkParamsFrom(declared, 1.0);
    server_options.link = vistream::server::LinkParamsFrom(declared, time_scale);
    server_options.link_seed = link_seed;
    link_line = absl::StrFormat("; emulated link %s (%s), time scale %g", unscaled.Describe(), source, time_scale);
    log.Write(0, "link", {{"link", unscaled.Describe()},
                          {"source", source},
                          {"time_scale", time_scale},
                          {"seed", link_seed}});
  }
  absl::StatusOr<std::unique_ptr<vistream::server::WalkthroughServer>> server =
      vistream::server::WalkthroughServer::Start(&s, server_options, &log);
  if (!server.ok()) {
    std::fprintf(stderr, "vistream-server: error: %s\n", std::string(server.status().message()).c_str());
    return 1;
  }
  std::printf("vistream-server: ready on %s: scene %s, %zu viewcells of %g m (%d x %d), %zu objects, PVSs from %s%s\n",
              (*server)->address().c_str(), s.scene().name.c_str(), s.grid().CellCount(), s.grid().cell_size(),
              s.grid().nx(), s.grid().ny(), s.scene().objects.size(), s.pvs_source().c_str(), link_line.c_str());
  std::fflush(stdout);
  log.Write(0, "ready", {{"address", (*server)->address()}});

  while (!g_stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (g_reload.exchange(false)) ReloadTokens(server_options.tokens.get(), &log);
  }
  log.Write(0, "draining", {{"signal", g_signal == SIGTERM ? "SIGTERM" : "SIGINT"},
                            {"sessions", static_cast<uint64_t>((*server)->service().active_sessions())}});
  (*server)->Shutdown(grace_s);
  log.Write(0, "stopped", {});
  g_log = nullptr;
  return 0;
}
