#include "server/server_process.h"

#include <signal.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <thread>
#include <vector>

#include <grpc/support/log.h>

#include <absl/strings/str_format.h>

#include "cli/stop_signal.h"
#include "scenes/catalog.h"
#include "server/event_log.h"
#include "server/link_model.h"
#include "server/metrics.h"
#include "server/metrics_http.h"
#include "server/pvs_store.h"
#include "server/security.h"
#include "server/served_scene.h"
#include "server/service.h"
#include "server/service_metrics.h"
#include "server/web_server.h"

namespace vistream::server {

namespace {

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

int RunServerProcess(const ServerProcessOptions& run) {
  const ServerConfig& config = run.config;
  const auto given = [&](const char* option) { return run.given != nullptr && run.given(option); };
  const bool emulate_link = run.emulate_link;
  const double time_scale = run.time_scale;
  const uint64_t link_seed = run.link_seed;
  // The page's folder, when the web listener is on.
  const std::string web_root =
      config.web_listen.empty() ? "" : config.web_root.empty() ? DefaultWebRoot() : config.web_root;
  ServerOptions server_options;
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
    const TlsSettings tls{config.tls_cert, config.tls_key, config.tls_client_ca, config.tls_insecure};
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
        ServerCredentialsFor(tls, config.listen);
    if (!credentials.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s%s\n", in_file.c_str(),
                   std::string(credentials.status().message()).c_str());
      return 2;
    }
    server_options.credentials = *std::move(credentials);
    if (!config.web_listen.empty()) {
      // The web listener serves with the same [tls] (HTTPS and WSS), and plaintext on loopback
      // only unless tls.insecure, as the gRPC one.
      if (absl::Status st = ServerCredentialsFor(tls, config.web_listen).status(); !st.ok()) {
        std::fprintf(stderr, "vistream-server: error: %sweb.listen: %s\n", in_file.c_str(),
                     std::string(st.message()).c_str());
        return 2;
      }
      if (absl::Status st = CheckWebRoot(web_root); !st.ok()) {
        std::fprintf(stderr, "vistream-server: error: %s\n", std::string(st.message()).c_str());
        return 2;
      }
    }
    if (!config.tokens.empty()) {
      absl::StatusOr<std::shared_ptr<TokenStore>> tokens =
          TokenStore::Load(config.tokens);
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
    const SceneConfig& sc = config.scenes[k];
    if (sc.line == 0 || !sc.file.empty()) continue;
    if (absl::StatusOr<vistream::scenes::CatalogEntry> e = vistream::scenes::FindCatalogEntry(sc.name, config.catalog);
        !e.ok() && e.status().code() == absl::StatusCode::kNotFound) {
      std::fprintf(stderr, "vistream-server: error: %s:%d: scenes[%zu].name: %s (or give the scene's file)\n",
                   config.path.c_str(), sc.line, k + 1, std::string(e.status().message()).c_str());
      return 2;
    }
  }
  if (config.tls_cert.empty() && !IsLoopbackListen(config.listen)) {
    log.Write(EventLog::Level::kWarn, 0, "insecure",
              {{"listen", config.listen}, {"message", "plaintext on an address that is not loopback (tls.insecure)"}});
  }
  if (server_options.tokens != nullptr && server_options.tokens->size() == 0) {
    log.Write(EventLog::Level::kWarn, 0, "no_tenants",
              {{"tokens", server_options.tokens->path()}, {"message", "the token file lets nobody in"}});
  }

  // The PVS store shared with other replicas: before the pool, so that it outlives the workers
  // that read it.
  std::unique_ptr<PvsStore> store;
  if (!config.store_address.empty()) {
    PvsStoreOptions so;
    so.address = config.store_address;
    so.key_prefix = config.store_key_prefix;
    so.connect_timeout_s = config.store_connect_timeout_ms / 1000.0;
    so.read_timeout_s = config.store_read_timeout_ms / 1000.0;
    so.write_timeout_s = config.store_write_timeout_ms / 1000.0;
    so.username = config.store_username;
    if (!config.store_password_file.empty()) {
      absl::StatusOr<std::string> password = ReadSecretLine(config.store_password_file);
      if (!password.ok()) {
        std::fprintf(stderr, "vistream-server: error: %s: %s\n",
                     given("--store-password-file") ? "--store-password-file" : "store.password_file",
                     std::string(password.status().message()).c_str());
        return 2;
      }
      so.password = *std::move(password);
    }
    absl::StatusOr<std::unique_ptr<PvsStore>> created = PvsStore::Create(
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
  PvsWorkerPool pool(threads);
  std::vector<std::unique_ptr<ServedScene>> served;
  for (const SceneConfig& sc : config.scenes) {
    const ServedSceneOptions o{.scene = sc.source(),
                               .name = sc.name,
                               .catalog_dir = config.catalog,
                               .cell_size = sc.cell_size_m,
                               .res = sc.res,
                               .backend = sc.backend,
                               .pvs_file = sc.pvs_file,
                               .cache_bytes = static_cast<size_t>(sc.cache_mb * (1 << 20)),
                               .pool = &pool,
                               .store = sc.pvs_file.empty() ? store.get() : nullptr,
                               .make_levels = sc.levels};
    log.Write(0, "loading", {{"scene", sc.name}, {"source", o.scene}});
    const auto load_start = std::chrono::steady_clock::now();
    absl::StatusOr<std::unique_ptr<ServedScene>> scene =
        ServedScene::Create(o, {&progress, &g_stop});
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
    const ServedScene& s = **scene;
    log.Write(0, "scene", {{"name", s.name()},
                           {"prepare_s", std::chrono::duration<double>(std::chrono::steady_clock::now() - load_start).count()},
                           {"objects", static_cast<uint64_t>(s.scene().objects.size())},
                           {"triangles", static_cast<uint64_t>(s.scene().TriangleCount())},
                           {"cells", static_cast<uint64_t>(s.grid().CellCount())},
                           {"pvs_source", s.pvs_source()},
                           {"load_s", s.load_seconds()}});
    served.push_back(std::move(*scene));
  }
  std::vector<ServedScene*> scenes;
  std::vector<std::string> names;
  for (const auto& s : served) {
    scenes.push_back(s.get());
    names.push_back(s->name());
  }
  // Metrics: declared for every scene, fed by the schedulers, the sessions and (at each scrape)
  // the service's statistics.
  MetricsRegistry registry;
  ServiceMetrics metrics(&registry, names);
  for (ServedScene* s : scenes) s->scheduler().SetComputeObserver(metrics.PvsComputeObserver(s->name()));
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
    if (run.link_option.has_value()) {
      declared = *ParseLinkOption(*run.link_option, declared);
      source = "--link";
    }
    const LinkParams unscaled = LinkParamsFrom(declared, 1.0);
    server_options.link = LinkParamsFrom(declared, time_scale);
    server_options.link_seed = link_seed;
    link_line = absl::StrFormat("; emulated link %s (%s), time scale %g", unscaled.Describe(), source, time_scale);
    log.Write(0, "link", {{"link", unscaled.Describe()},
                          {"source", source},
                          {"time_scale", time_scale},
                          {"seed", link_seed}});
  }
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> server =
      WalkthroughServer::Start(scenes, server_options, &log);
  if (!server.ok()) {
    std::fprintf(stderr, "vistream-server: error: %s\n", std::string(server.status().message()).c_str());
    return 1;
  }
  metrics.Watch([service = &(*server)->service()] { return service->Stats(); });
  std::unique_ptr<MetricsHttpServer> http;
  if (!config.metrics_listen.empty()) {
    // /healthz answers 503 from the first stop signal on, while the sessions drain.
    absl::StatusOr<std::unique_ptr<MetricsHttpServer>> started =
        MetricsHttpServer::Start(config.metrics_listen, &registry, [] { return !g_stop.load(); });
    if (!started.ok()) {
      std::fprintf(stderr, "vistream-server: error: metrics.listen: %s\n", std::string(started.status().message()).c_str());
      return 1;
    }
    http = std::move(*started);
    log.Write(0, "metrics", {{"address", http->address()}, {"paths", "/metrics /healthz"}});
  }
  std::unique_ptr<WebServer> web;
  if (!config.web_listen.empty()) {
    WebOptions w;
    w.listen = config.web_listen;
    w.root = web_root;
    w.tls_cert = config.tls_cert;
    w.tls_key = config.tls_key;
    w.tls_client_ca = config.tls_client_ca;
    w.hello_timeout_s = config.hello_timeout_s;
    w.max_message_bytes = (*server)->service().max_receive_bytes();  // the gRPC listener's limit
    absl::StatusOr<std::unique_ptr<WebServer>> started = WebServer::Start(&(*server)->service(), w, &log);
    if (!started.ok()) {
      std::fprintf(stderr, "vistream-server: error: web.listen: %s\n", std::string(started.status().message()).c_str());
      return 1;
    }
    web = std::move(*started);
    log.Write(0, "web", {{"address", web->address()}, {"scheme", web->scheme()}, {"root", w.root}});
  }
  // One scene: "scene NAME, ..."; several: "N scenes: NAME (...); NAME (...)".
  std::string what;
  for (const ServedScene* s : scenes) {
    const std::string one = absl::StrFormat(
        "%zu viewcells of %g m (%d x %d), %zu objects, PVSs from %s, %s", s->grid().CellCount(), s->grid().cell_size(),
        s->grid().nx(), s->grid().ny(), s->scene().objects.size(), s->pvs_source(),
        s->levels() != nullptr ? "levels of detail" : "no levels of detail (--levels makes them)");
    if (scenes.size() == 1) {
      what = absl::StrFormat("scene %s, %s", s->name(), one);
    } else {
      what += absl::StrFormat("%s%s (%s)", what.empty() ? absl::StrFormat("%zu scenes: ", scenes.size()) : "; ",
                              s->name(), one);
    }
  }
  std::string metrics_line = http != nullptr ? "; metrics on http://" + http->address() + "/metrics" : "";
  if (web != nullptr) metrics_line += absl::StrFormat("; web page on %s://%s/", web->scheme(), web->address());
  std::string security_line = config.tls_cert.empty() ? "" : config.tls_client_ca.empty() ? "; TLS" : "; mutual TLS";
  if (server_options.tokens != nullptr) {
    security_line += absl::StrFormat("; tokens (%zu tenant%s)", server_options.tokens->size(),
                                     server_options.tokens->size() == 1 ? "" : "s");
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
  (*server)->Shutdown(config.grace_s);  // WebSocket sessions too: each is sent its SessionEnd
  if (web != nullptr) web->Stop();
  if (http != nullptr) http->Stop();  // its collector reads the service
  server->reset();
  served.clear();  // the scenes' schedulers leave the pool before it stops
  log.Write(0, "stopped", {});
  g_log = nullptr;
  if (log_out != stderr) std::fclose(log_out);
  return 0;
}

}  // namespace vistream::server
