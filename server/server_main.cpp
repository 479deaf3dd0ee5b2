// vistream-server: serves the scenes of its configuration (a TOML file, --config, whose keys the
// command-line options override; server/server_config.h) to walkthrough clients over gRPC
// (DESIGN.md, "Server and client", "Deployment"). Prints one line on stdout when it is ready;
// logs one line per event on stderr or to its log file. SIGTERM or SIGINT drains the sessions
// and exits 0: health turns 503 at once, the sessions are served on for up to drain_s seconds
// (a load balancer takes the replica out meanwhile), then they end with UNAVAILABLE (their
// clients resume elsewhere) and the process exits within grace_s. A second signal stops it at
// once (exit 1).

#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <memory>
#include <vector>
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
#include "server/metrics.h"
#include "server/metrics_http.h"
#include "server/pvs_store.h"
#include "server/security.h"
#include "server/served_scene.h"
#include "server/service_metrics.h"
#include "server/server_config.h"
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
  const EventLog::Level level =
      args->severity == GPR_LOG_SEVERITY_ERROR ? EventLog::Level::kError : EventLog::Level::kInfo;
  g_log->Write(level, 0, "grpc", {{"severity", gpr_log_severity_string(args->severity)}, {"message", args->message}});
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
    log->Write(EventLog::Level::kError, 0, "tokens_reload_failed",
               {{"error", std::string(st.message())}, {"tenants", static_cast<uint64_t>(tokens->size())}});
    return;
  }
  log->Write(0, "tokens_reloaded", {{"file", tokens->path()}, {"tenants", static_cast<uint64_t>(tokens->size())}});
}

}  // namespace

int main(int argc, char** argv) {
  // Command-line values: each overrides its configuration key when given (app.count > 0).
  vistream::server::ServerConfig cli;
  vistream::server::SceneConfig cli_scene;
  std::string config_path, scene_option;
  bool json_log = false;
  CLI::App app{"vistream-server: streams the visible part of a city to walkthrough clients over gRPC"};
  app.add_option("--config", config_path,
                 "TOML configuration file (deploy/server.toml documents every key); options given here override its keys");
  app.add_option("--scene", scene_option,
                 "serve this one scene: catalog name, catalog .json or .glb/.gltf file (replaces the configuration's "
                 "[[scenes]])");
  app.add_option("--catalog", cli.catalog, "folder of catalog entries (default: the built-in catalog)");
  app.add_option("--listen", cli.listen, "address to listen on, host:port (port 0: any free one)")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            if (!vistream::server::IsHostPort(text)) {
              return "'" + text + "' is not host:port with a port from 0 to 65535 (e.g. 127.0.0.1:50051)";
            }
            return "";
          },
          "HOST:PORT"));
  app.add_option("--threads", cli.threads, "PVS worker threads, shared by every scene (0: one per core)")
      ->capture_default_str()
      ->check(vistream::cli::WholeRange(0, 1024));
  app.add_option("--cell-size", cli_scene.cell_size_m, "viewcell edge in metres (default: the catalog entry's)")
      ->check(FiniteRange(0.01, 1e6));
  app.add_option("--res", cli_scene.res, "finest dual-ray-space raster (power of two, 1 to 256)")
      ->capture_default_str()
      ->check(vistream::cli::PowerOfTwo(1, 256));
  app.add_option("--backend", cli_scene.backend, "cpu | gl | exact")->check(CLI::IsMember({"cpu", "gl", "exact"}))
      ->capture_default_str();
  app.add_option("--pvs-file", cli_scene.pvs_file,
                 "serve the PVSs of this file (vistream agvs -o, vistream pvs --all -o) instead of computing them "
                 "(one scene only)");
  app.add_option("--max-sessions", cli.max_sessions, "sessions at once; more are refused")
      ->check(vistream::cli::WholeRange(1, 100000))->capture_default_str();
  app.add_option("--cache-mb", cli_scene.cache_mb, "PVS cache budget of each scene in MiB")
      ->check(FiniteRange(1, 1e6))->capture_default_str();
  app.add_option("--max-pose-rate", cli.max_pose_rate_hz, "poses per second a session may send")
      ->check(FiniteRange(0.1, 100000))->capture_default_str();
  app.add_option("--grace", cli.grace_s, "seconds sessions get to end on shutdown")->check(FiniteRange(0, 3600))
      ->capture_default_str();
  app.add_option("--drain", cli.drain_s,
                 "seconds from SIGTERM to the end of the sessions: /healthz says 503 while they are served on, so "
                 "that a load balancer takes this replica out first (0: end them at once)")
      ->check(FiniteRange(0, 3600))
      ->capture_default_str();
  app.add_option("--hello-timeout", cli.hello_timeout_s,
                 "seconds a new stream may take to send its Hello (then DEADLINE_EXCEEDED; 0: no limit)")
      ->check(FiniteRange(0, 86400))->capture_default_str();
  app.add_option("--max-sessions-per-address", cli.max_sessions_per_address,
                 "sessions at once from one client address (0: no limit)")
      ->check(vistream::cli::WholeRange(0, 100000))->capture_default_str();
  app.add_option("--max-sessions-per-token", cli.max_sessions_per_token,
                 "sessions at once per token (0: no limit)")
      ->check(vistream::cli::WholeRange(0, 100000))->capture_default_str();
  app.add_option("--tls-cert", cli.tls_cert, "PEM certificate chain: serve TLS (with --tls-key)");
  app.add_option("--tls-key", cli.tls_key, "PEM private key of --tls-cert");
  app.add_option("--tls-client-ca", cli.tls_client_ca,
                 "PEM CA bundle: clients must present a certificate it signed (mutual TLS)");
  app.add_flag("--insecure", cli.tls_insecure, "allow plaintext on an address that is not loopback");
  app.add_option("--tokens", cli.tokens, "file of 'name token' lines: clients must send one as a bearer token");
  app.add_option("--metrics-listen", cli.metrics_listen, "host:port of the HTTP /metrics and /healthz endpoint")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            if (!text.empty() && !vistream::server::IsHostPort(text)) {
              return "'" + text + "' is not host:port with a port from 0 to 65535 (e.g. 127.0.0.1:9464)";
            }
            return "";
          },
          "HOST:PORT"));
  app.add_option("--store", cli.store_address,
                 "Redis host:port or unix:PATH of the PVS store shared by replicas (README \"Beyond one machine\")")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            if (!vistream::server::IsStoreAddress(text)) {
              return "'" + text + "' is not host:port or unix:/path (e.g. 127.0.0.1:6379)";
            }
            return "";
          },
          "HOST:PORT"));
  app.add_option("--store-prefix", cli.store_key_prefix, "key prefix in the PVS store")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            if (!vistream::server::IsStoreKeyPrefix(text)) {
              return "'" + text + "' is not a non-empty word without spaces";
            }
            return "";
          },
          "WORD"));
  app.add_option("--store-read-timeout-ms", cli.store_read_timeout_ms,
                 "a store read's deadline in ms (then the PVS is computed)")
      ->check(FiniteRange(0.001, 60000))->capture_default_str();
  app.add_option("--store-password-file", cli.store_password_file, "file whose first line is the store's password");
  app.add_flag("--json-log", json_log, "log JSON lines instead of text");
  app.add_option("--log-file", cli.log_file, "append the log to this file instead of stderr");
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
  // The configuration: the file's, then what the command line gives.
  vistream::server::ServerConfig config;
  if (!config_path.empty()) {
    absl::StatusOr<vistream::server::ServerConfig> loaded = vistream::server::LoadServerConfig(config_path);
    if (!loaded.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s\n", std::string(loaded.status().message()).c_str());
      return 2;
    }
    config = std::move(*loaded);
  }
  const auto given = [&](const char* option) { return app.count(option) > 0; };
  if (given("--catalog")) config.catalog = cli.catalog;
  if (given("--listen")) config.listen = cli.listen;
  if (given("--threads")) config.threads = cli.threads;
  if (given("--max-sessions")) config.max_sessions = cli.max_sessions;
  if (given("--max-pose-rate")) config.max_pose_rate_hz = cli.max_pose_rate_hz;
  if (given("--grace")) config.grace_s = cli.grace_s;
  if (given("--drain")) config.drain_s = cli.drain_s;
  if (given("--hello-timeout")) config.hello_timeout_s = cli.hello_timeout_s;
  if (given("--max-sessions-per-address")) config.max_sessions_per_address = cli.max_sessions_per_address;
  if (given("--max-sessions-per-token")) config.max_sessions_per_token = cli.max_sessions_per_token;
  if (given("--tls-cert")) config.tls_cert = cli.tls_cert;
  if (given("--tls-key")) config.tls_key = cli.tls_key;
  if (given("--tls-client-ca")) config.tls_client_ca = cli.tls_client_ca;
  if (given("--insecure")) config.tls_insecure = cli.tls_insecure;
  if (given("--tokens")) config.tokens = cli.tokens;
  if (given("--metrics-listen")) config.metrics_listen = cli.metrics_listen;
  if (config.store_address.empty() && !given("--store")) {
    // Store options without a store would be ignored: say so.
    for (const char* option : {"--store-prefix", "--store-read-timeout-ms", "--store-password-file"}) {
      if (given(option)) {
        std::fprintf(stderr, "vistream-server: error: %s: needs a PVS store: give --store HOST:PORT (or [store] "
                             "address)\nRun 'vistream-server --help' for the options.\n", option);
        return 2;
      }
    }
  }
  if (given("--store")) config.store_address = cli.store_address;
  if (given("--store-prefix")) config.store_key_prefix = cli.store_key_prefix;
  if (given("--store-read-timeout-ms")) config.store_read_timeout_ms = cli.store_read_timeout_ms;
  if (given("--store-password-file")) config.store_password_file = cli.store_password_file;
  if (given("--json-log")) config.log_json = json_log;
  if (given("--log-file")) config.log_file = cli.log_file;
  if (given("--scene")) {
    cli_scene.name = scene_option;
    config.scenes = {cli_scene};
  }
  for (vistream::server::SceneConfig& sc : config.scenes) {
    if (given("--cell-size")) sc.cell_size_m = cli_scene.cell_size_m;
    if (given("--res")) sc.res = cli_scene.res;
    if (given("--backend")) sc.backend = cli_scene.backend;
    if (given("--cache-mb")) sc.cache_mb = cli_scene.cache_mb;
    if (given("--pvs-file")) sc.pvs_file = cli_scene.pvs_file;
  }
  if (absl::Status st = vistream::server::CheckServerConfig(config); !st.ok()) {
    std::fprintf(stderr, "vistream-server: error: %s\nRun 'vistream-server --help' for the options.\n",
                 std::string(st.message()).c_str());
    return 2;
  }
  if (given("--pvs-file") && config.scenes.size() > 1) {
    std::fprintf(stderr, "vistream-server: error: --pvs-file: the configuration serves %zu scenes; give each its "
                         "pvs_file in [[scenes]]\n", config.scenes.size());
    return 2;
  }
  if (emulate_link && config.scenes.size() > 1) {
    std::fprintf(stderr, "vistream-server: error: --emulate-link and --link serve one scene only (the link its "
                         "catalog entry declares); this configuration serves %zu\n", config.scenes.size());
    return 2;
  }
  vistream::server::ServerOptions server_options;
  server_options.listen = config.listen;
  server_options.max_sessions = config.max_sessions;
  server_options.limits.max_pose_rate_hz = config.max_pose_rate_hz;
  server_options.hello_timeout_s = config.hello_timeout_s;
  server_options.max_sessions_per_address = config.max_sessions_per_address;
  server_options.max_sessions_per_token = config.max_sessions_per_token;
  {
    // TLS files and the token file are checked before any scene loads: a bad one exits 2,
    // naming the key (and the configuration file) or the option.
    // Errors name the file and line only for what the file set (options are named by the key,
    // which is the option's name in the file).
    const bool tls_from_cli = given("--tls-cert") || given("--tls-key") || given("--tls-client-ca") || given("--insecure");
    const bool plaintext = config.tls_cert.empty();
    const int line = plaintext ? (given("--listen") || given("--insecure") ? 0 : config.listen_line)
                               : (tls_from_cli ? 0 : config.tls_line);
    const std::string in_file = line > 0 ? absl::StrFormat("%s:%d: ", config.path, line) : "";
    const vistream::server::TlsSettings tls{config.tls_cert, config.tls_key, config.tls_client_ca, config.tls_insecure};
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
        vistream::server::ServerCredentialsFor(tls, config.listen);
    if (!credentials.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s%s\n", in_file.c_str(),
                   std::string(credentials.status().message()).c_str());
      return 2;
    }
    server_options.credentials = *std::move(credentials);
    if (!config.tokens.empty()) {
      absl::StatusOr<std::shared_ptr<vistream::server::TokenStore>> tokens =
          vistream::server::TokenStore::Load(config.tokens);
      if (!tokens.ok()) {
        std::fprintf(stderr, "vistream-server: error: %s%s\n", given("--tokens") ? "--tokens: " : "auth.tokens: ",
                     std::string(tokens.status().message()).c_str());
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

  std::FILE* log_out = stderr;
  if (!config.log_file.empty()) {
    log_out = std::fopen(config.log_file.c_str(), "a");
    if (log_out == nullptr) {
      std::fprintf(stderr, "vistream-server: error: %s: cannot open the log file: %s\n", config.log_file.c_str(),
                   std::strerror(errno));
      return 1;
    }
  }
  EventLog log(log_out, config.log_json);
  g_log = &log;
  gpr_set_log_function(GrpcLog);
  LogProgress progress(&log);
  const char* tls_mode = config.tls_cert.empty() ? "off" : (config.tls_client_ca.empty() ? "on" : "mutual");
  if (server_options.tokens == nullptr) {
    log.Write(0, "security", {{"tls", tls_mode}, {"tokens", "off"}});
  } else {
    log.Write(0, "security", {{"tls", tls_mode},
                              {"tokens", server_options.tokens->path()},
                              {"tenants", static_cast<uint64_t>(server_options.tokens->size())}});
  }
  if (!config.path.empty()) log.Write(0, "config", {{"file", config.path}, {"scenes", config.scenes.size()}});

  // A catalog name the file gives that the catalog does not have is a bad configuration (exit
  // 2), found before any scene loads.
  for (size_t k = 0; k < config.scenes.size(); ++k) {
    const vistream::server::SceneConfig& sc = config.scenes[k];
    if (sc.line == 0 || !sc.file.empty()) continue;
    if (absl::StatusOr<vistream::scenes::CatalogEntry> e = vistream::scenes::FindCatalogEntry(sc.name, config.catalog);
        !e.ok() && e.status().code() == absl::StatusCode::kNotFound) {
      std::fprintf(stderr, "vistream-server: error: %s:%d: scenes[%zu].name: %s (or give the scene's file)\n",
                   config.path.c_str(), sc.line, k + 1, std::string(e.status().message()).c_str());
      return 2;
    }
  }
  if (config.tls_cert.empty() && !vistream::server::IsLoopbackListen(config.listen)) {
    log.Write(EventLog::Level::kWarn, 0, "insecure",
              {{"listen", config.listen}, {"message", "plaintext on an address that is not loopback (tls.insecure)"}});
  }
  if (server_options.tokens != nullptr && server_options.tokens->size() == 0) {
    log.Write(EventLog::Level::kWarn, 0, "no_tenants",
              {{"tokens", server_options.tokens->path()}, {"message", "the token file lets nobody in"}});
  }

  // The PVS store shared with other replicas: before the pool, so that it outlives the workers
  // that read it.
  std::unique_ptr<vistream::server::PvsStore> store;
  if (!config.store_address.empty()) {
    vistream::server::PvsStoreOptions so;
    so.address = config.store_address;
    so.key_prefix = config.store_key_prefix;
    so.connect_timeout_s = config.store_connect_timeout_ms / 1000.0;
    so.read_timeout_s = config.store_read_timeout_ms / 1000.0;
    so.write_timeout_s = config.store_write_timeout_ms / 1000.0;
    so.username = config.store_username;
    if (!config.store_password_file.empty()) {
      absl::StatusOr<std::string> password = vistream::server::ReadSecretLine(config.store_password_file);
      if (!password.ok()) {
        std::fprintf(stderr, "vistream-server: error: %s: %s\n",
                     given("--store-password-file") ? "--store-password-file" : "store.password_file",
                     std::string(password.status().message()).c_str());
        return 2;
      }
      so.password = *std::move(password);
    }
    absl::StatusOr<std::unique_ptr<vistream::server::PvsStore>> created = vistream::server::PvsStore::Create(
        so, [&log](EventLog::Level level, std::string_view event, const std::string& detail) {
          log.Write(level, 0, event, {{"detail", detail}});
        });
    if (!created.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s\n", std::string(created.status().message()).c_str());
      return 2;
    }
    store = std::move(*created);
    // Say now whether it answers; the server starts either way and uses it once it does, but a
    // Redis that refuses this server (password) is a configuration error.
    if (absl::Status st = store->Connect(); absl::IsPermissionDenied(st)) {
      std::fprintf(stderr, "vistream-server: error: %s\n", std::string(st.message()).c_str());
      return 2;
    }
  }
  // One pool of PVS workers for every scene, shared round robin (server/pvs_scheduler.h).
  const unsigned threads = config.threads != 0 ? config.threads : std::max(1u, std::thread::hardware_concurrency());
  vistream::server::PvsWorkerPool pool(threads);
  std::vector<std::unique_ptr<vistream::server::ServedScene>> served;
  for (const vistream::server::SceneConfig& sc : config.scenes) {
    vistream::server::ServedSceneOptions o;
    o.scene = sc.source();
    o.name = sc.name;
    o.catalog_dir = config.catalog;
    o.cell_size = sc.cell_size_m;
    o.res = sc.res;
    o.backend = sc.backend;
    o.pvs_file = sc.pvs_file;
    o.cache_bytes = static_cast<size_t>(sc.cache_mb * (1 << 20));
    o.pool = &pool;
    o.store = sc.pvs_file.empty() ? store.get() : nullptr;
    log.Write(0, "loading", {{"scene", sc.name}, {"source", o.scene}});
    const auto load_start = std::chrono::steady_clock::now();
    absl::StatusOr<std::unique_ptr<vistream::server::ServedScene>> scene =
        vistream::server::ServedScene::Create(o, {&progress, &g_stop});
    if (!scene.ok()) {
      if (g_stop) return 0;
      const std::string where = sc.line > 0 ? absl::StrFormat("%s:%d: scenes '%s': ", config.path, sc.line, sc.name)
                                            : std::string();
      std::fprintf(stderr, "vistream-server: error: %s%s\n", where.c_str(), std::string(scene.status().message()).c_str());
      return 1;
    }
    if (g_stop) {  // stopped while preparing: nothing to drain
      log.Write(0, "stopped", {});
      return 0;
    }
    const vistream::server::ServedScene& s = **scene;
    log.Write(0, "scene", {{"name", s.name()},
                           {"prepare_s", std::chrono::duration<double>(std::chrono::steady_clock::now() - load_start).count()},
                           {"objects", static_cast<uint64_t>(s.scene().objects.size())},
                           {"triangles", static_cast<uint64_t>(s.scene().TriangleCount())},
                           {"cells", static_cast<uint64_t>(s.grid().CellCount())},
                           {"pvs_source", s.pvs_source()},
                           {"load_s", s.load_seconds()}});
    served.push_back(std::move(*scene));
  }
  std::vector<vistream::server::ServedScene*> scenes;
  std::vector<std::string> names;
  for (const auto& s : served) {
    scenes.push_back(s.get());
    names.push_back(s->name());
  }
  // Metrics: declared for every scene, fed by the schedulers, the sessions and (at each scrape)
  // the service's statistics.
  vistream::server::MetricsRegistry registry;
  vistream::server::ServiceMetrics metrics(&registry, names);
  for (vistream::server::ServedScene* s : scenes) s->scheduler().SetComputeObserver(metrics.PvsComputeObserver(s->name()));
  server_options.metrics = &metrics;
  // One scene: its catalog ε box (a session of several scenes takes its scene's at Hello).
  server_options.limits.epsilon_size_m = scenes.front()->viewcell().epsilon_m;
  std::string link_line;
  if (emulate_link) {
    // The link the scene's catalog entry declares (a scene file without an entry: none).
    std::optional<vistream::scenes::LinkSpec> declared;
    std::string source = "the scene declares no link";
    if (absl::StatusOr<vistream::scenes::CatalogEntry> entry =
            vistream::scenes::FindCatalogEntry(config.scenes.front().source(), config.catalog);
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
      vistream::server::WalkthroughServer::Start(scenes, server_options, &log);
  if (!server.ok()) {
    std::fprintf(stderr, "vistream-server: error: %s\n", std::string(server.status().message()).c_str());
    return 1;
  }
  metrics.Watch(&(*server)->service());
  std::unique_ptr<vistream::server::MetricsHttpServer> http;
  if (!config.metrics_listen.empty()) {
    // /healthz answers 503 from the first stop signal on, while the sessions drain.
    absl::StatusOr<std::unique_ptr<vistream::server::MetricsHttpServer>> started =
        vistream::server::MetricsHttpServer::Start(config.metrics_listen, &registry, [] { return !g_stop.load(); });
    if (!started.ok()) {
      std::fprintf(stderr, "vistream-server: error: metrics.listen: %s\n", std::string(started.status().message()).c_str());
      return 1;
    }
    http = std::move(*started);
    log.Write(0, "metrics", {{"address", http->address()}, {"paths", "/metrics /healthz"}});
  }
  // One scene: "scene NAME, ..."; several: "N scenes: NAME (...); NAME (...)".
  std::string what;
  for (const vistream::server::ServedScene* s : scenes) {
    const std::string one = absl::StrFormat("%zu viewcells of %g m (%d x %d), %zu objects, PVSs from %s",
                                            s->grid().CellCount(), s->grid().cell_size(), s->grid().nx(),
                                            s->grid().ny(), s->scene().objects.size(), s->pvs_source());
    if (scenes.size() == 1) {
      what = absl::StrFormat("scene %s, %s", s->name(), one);
    } else {
      what += absl::StrFormat("%s%s (%s)", what.empty() ? absl::StrFormat("%zu scenes: ", scenes.size()) : "; ",
                              s->name(), one);
    }
  }
  const std::string metrics_line = http != nullptr ? "; metrics on http://" + http->address() + "/metrics" : "";
  std::string security_line = config.tls_cert.empty() ? "" : config.tls_client_ca.empty() ? "; TLS" : "; mutual TLS";
  if (server_options.tokens != nullptr) {
    security_line += absl::StrFormat("; tokens (%zu tenants)", server_options.tokens->size());
  }
  std::printf("vistream-server: ready on %s: %s%s%s%s\n", (*server)->address().c_str(), what.c_str(), link_line.c_str(),
              security_line.c_str(), metrics_line.c_str());
  std::fflush(stdout);
  log.Write(0, "ready", {{"address", (*server)->address()}, {"scenes", scenes.size()}});

  while (!g_stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (g_reload.exchange(false)) ReloadTokens(server_options.tokens.get(), &log);
  }
  log.Write(0, "draining", {{"signal", g_signal == SIGTERM ? "SIGTERM" : "SIGINT"},
                            {"sessions", static_cast<uint64_t>((*server)->service().active_sessions())},
                            {"drain_s", config.drain_s}});
  // /healthz has said 503 since the signal (g_stop); sessions go on until a balancer has seen it.
  const double held_s = (*server)->HoldDrain(config.drain_s);
  log.Write(0, "ending_sessions", {{"held_s", held_s},
                                   {"sessions", static_cast<uint64_t>((*server)->service().active_sessions())}});
  (*server)->Shutdown(config.grace_s);
  if (http != nullptr) http->Stop();  // its collector reads the service
  server->reset();
  served.clear();  // the scenes' schedulers leave the pool before it stops
  log.Write(0, "stopped", {});
  g_log = nullptr;
  if (log_out != stderr) std::fclose(log_out);
  return 0;
}
