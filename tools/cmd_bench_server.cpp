// vistream bench server: N simulated clients walk random street-level paths in real time
// through a real vistream-server on loopback, and report what a deployment cares about: cells
// entered before their PVS and geometry arrived (late), crossing latency, PVS computations and
// cache hits, bytes per crossing with and without meshoptimizer, and the server's RSS. With
// --tls on (or both, side by side in one run) the server serves TLS with a certificate made for
// the run by `openssl`, and every walker connects with its CA. With --replicas N --balancer
// haproxy the walkers go through a real HAProxy to N replicas; with --store they share a PVS
// store in Redis, cold, or warmed first by the same walks (--warm). With --lod off,1 (issue 45)
// the same walkers ask for full detail and for levels at tau = 1 px (the server made with
// --levels), side by side in one run.

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "client/channel_security.h"
#include "client/connection.h"
#include "client/session_stream.h"
#include "server/pvs_store.h"
#include "server/server_config.h"
#include "scenes/terrain.h"
#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/replica_set.h"
#include "visibility/viewcell_grid.h"

namespace vistream::tools {

namespace {

namespace v1 = vistream::v1;

struct BenchServerArgs {
  std::string scene = "london";
  size_t sessions = 10;
  double speed_kmh = 6.0;
  double seconds = 120.0;
  double cell_size = 0.0;  // 0: the catalog entry's
  uint32_t res = 128;
  unsigned threads = 0;
  uint64_t seed = 1;
  std::string log;
  bool json = false;
  std::string tls = "off";  // off | on | both
  size_t replicas = 1;
  std::string balancer = "none";  // none | haproxy
  std::string store = "none";     // none | redis (a redis-server of the run's own) | HOST:PORT
  bool warm = false;              // fill the store with the same walks first
  std::string masks = "on";       // on | off: the walkers' Hello.epsilon_masks (issue 34)
  std::string lod = "off";        // off, or tau in pixels, or several: one run each (issue 45)
};

// What the passes of one bench run share: the PVS store's address and key prefix (empty: no
// store), and whether this pass only fills it.
struct RunContext {
  std::string store_address, store_prefix;
  std::string store_password_file;  // $VISTREAM_STORE_PASSWORD in a file of the run's own, for the replicas
  bool warmup = false;
};

// The replicas of one pass: one vistream-server, or N behind HAProxy (tools/replica_set.h).
struct Replicas {
  std::unique_ptr<RunningServer> single;
  std::unique_ptr<Balancer> balanced;
  std::string address;  // where the walkers connect
  std::string dir;      // the balanced run's folder (configuration, logs), removed at the end

  size_t size() const { return balanced != nullptr ? balanced->size() : 1; }
  std::string replica_address(size_t k) const {
    return balanced != nullptr ? balanced->replica_address(k) : single->address();
  }
  pid_t pid(size_t k) {
    RunningServer* s = balanced != nullptr ? balanced->replica(k) : single.get();
    return s != nullptr ? s->pid() : -1;
  }
  // SIGTERM to every replica, then HAProxy: the first non-zero exit code, else 0.
  int Stop() {
    int code = 0;
    if (single != nullptr) code = single->Stop(SIGTERM);
    for (size_t k = 0; balanced != nullptr && k < balanced->size(); ++k) {
      const int c = balanced->StopReplica(k, SIGTERM);
      if (code == 0) code = c;
    }
    balanced.reset();
    std::error_code ignored;
    if (!dir.empty()) std::filesystem::remove_all(dir, ignored);
    return code;
  }
};

// deploy/haproxy.cfg beside this executable: in the build tree (build/bin/../../deploy) or
// installed (bin/../share/doc/vistream); empty if neither holds it.
std::string HaproxyTemplate() {
  const std::filesystem::path bin = std::filesystem::read_symlink("/proc/self/exe").parent_path();
  for (const std::filesystem::path& p : {bin / "../../deploy/haproxy.cfg", bin / "../share/doc/vistream/haproxy.cfg"}) {
    std::error_code ec;
    if (std::filesystem::is_regular_file(p, ec)) return std::filesystem::weakly_canonical(p).string();
  }
  return "";
}

// A CA and a server certificate for 127.0.0.1 made with `openssl` in `dir`: the files' paths.
struct RunCertificates {
  std::string ca, cert, key;
};

absl::StatusOr<RunCertificates> MakeCertificates(const std::string& dir) {
  std::filesystem::create_directories(dir);
  const std::string script = absl::StrFormat(
      "set -e; cd '%s'; "
      "openssl req -x509 -newkey rsa:2048 -nodes -keyout ca.key -out ca.crt -days 2 -subj /CN=vistream-bench-ca; "
      "openssl req -newkey rsa:2048 -nodes -keyout server.key -out server.csr -subj /CN=127.0.0.1; "
      "printf 'subjectAltName=IP:127.0.0.1,DNS:localhost\n' > san.ext; "
      "openssl x509 -req -in server.csr -CA ca.crt -CAkey ca.key -CAcreateserial -out server.crt -days 2 "
      "-extfile san.ext",
      dir);
  const std::string command = "bash -c \"" + script + "\" >/dev/null 2>&1";
  if (std::system(command.c_str()) != 0) {
    return absl::UnavailableError("--tls: making a certificate with openssl failed (is `openssl` installed?)");
  }
  return RunCertificates{dir + "/ca.crt", dir + "/server.crt", dir + "/server.key"};
}

double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double k = p * static_cast<double>(v.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(k)), hi = std::min(v.size() - 1, lo + 1);
  return v[lo] + (k - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

// Where a pedestrian may be: the ground outside every building's box, on a raster.
class Streets {
 public:
  Streets(const scenes::Scene& scene, const scenes::Aabb& area, double step) : area_(area), step_(step) {
    nx_ = static_cast<int>(std::ceil((area.max.x - area.min.x) / step));
    ny_ = static_cast<int>(std::ceil((area.max.y - area.min.y) / step));
    blocked_.assign(static_cast<size_t>(nx_) * ny_, false);
    for (const scenes::Object& o : scene.objects) {
      const int i0 = std::max(0, static_cast<int>((o.bounds.min.x - area.min.x) / step));
      const int i1 = std::min(nx_ - 1, static_cast<int>((o.bounds.max.x - area.min.x) / step));
      const int j0 = std::max(0, static_cast<int>((o.bounds.min.y - area.min.y) / step));
      const int j1 = std::min(ny_ - 1, static_cast<int>((o.bounds.max.y - area.min.y) / step));
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) blocked_[static_cast<size_t>(j) * nx_ + i] = true;
      }
    }
  }
  bool Free(const glm::dvec2& p) const {
    const int i = static_cast<int>(std::floor((p.x - area_.min.x) / step_));
    const int j = static_cast<int>(std::floor((p.y - area_.min.y) / step_));
    // Keep a cell's width from the edge of the area.
    if (i < 1 || j < 1 || i >= nx_ - 1 || j >= ny_ - 1) return false;
    return !blocked_[static_cast<size_t>(j) * nx_ + i];
  }
  glm::dvec2 RandomFree(std::mt19937_64& rng) const {
    std::uniform_real_distribution<double> ux(area_.min.x, area_.max.x), uy(area_.min.y, area_.max.y);
    for (int k = 0; k < 100000; ++k) {
      const glm::dvec2 p(ux(rng), uy(rng));
      if (Free(p)) return p;
    }
    return {0.5 * (area_.min.x + area_.max.x), 0.5 * (area_.min.y + area_.max.y)};
  }

 private:
  scenes::Aabb area_;
  double step_;
  int nx_ = 0, ny_ = 0;
  std::vector<bool> blocked_;
};

// A walker that keeps to the streets: straight on until a building is ahead, then a new
// heading; now and then a turn at random.
class Walker {
 public:
  Walker(const Streets& streets, uint64_t seed, double speed) : streets_(streets), rng_(seed), speed_(speed) {
    p_ = streets.RandomFree(rng_);
    NewHeading();
  }
  void Step(double dt) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    if (u(rng_) < dt / 30.0) NewHeading();  // a turn every half minute on average
    for (int tries = 0; tries < 16; ++tries) {
      const glm::dvec2 next = p_ + heading_ * speed_ * dt;
      const glm::dvec2 probe = p_ + heading_ * std::max(4.0, speed_ * dt);
      if (streets_.Free(next) && streets_.Free(probe)) {
        p_ = next;
        return;
      }
      NewHeading();
    }
  }
  glm::dvec2 position() const { return p_; }
  glm::dvec2 velocity() const { return heading_ * speed_; }

 private:
  void NewHeading() {
    std::uniform_real_distribution<double> a(0.0, 2.0 * M_PI);
    const double t = a(rng_);
    heading_ = {std::cos(t), std::sin(t)};
  }
  const Streets& streets_;
  std::mt19937_64 rng_;
  double speed_;
  glm::dvec2 p_, heading_{1.0, 0.0};
};

struct SessionResult {
  bool started = false;
  std::string error;
  double startup_s = 0.0;
  uint64_t cells_entered = 0, late_cells = 0, crossings = 0, incomplete_crossings = 0;
  std::vector<double> crossing_ms;
  uint64_t geometry_bytes = 0, raw_geometry_bytes = 0;  // after start-up
  uint64_t masks = 0, mask_bytes = 0;                   // ε-masks received, their triangle bytes
  uint64_t level_objects = 0;                           // geometry received at a level of detail
};

SessionResult RunSession(const std::string& address, const client::ChannelSecurity& security,
                         const std::string& scene_name, const Streets& streets, const visibility::ViewcellGrid& grid,
                         const scenes::TerrainHeight& terrain, uint64_t seed, double speed, double seconds, bool masks,
                         double tau_px, const std::atomic<bool>& cancel) {
  SessionResult out;
  client::SessionStream s(address, security);
  s.set_keep_geometry(false);
  // A 1280 x 720 client, 60 degrees high (the client model's defaults), with levels at tau_px
  // when asked (and then its lists as differences, as the native client takes them).
  client::HelloSettings settings;
  settings.scene = scene_name;
  settings.epsilon_masks = masks;
  settings.screen_error_px = tau_px;
  const v1::Hello hello = client::MakeHello(settings);
  s.Start(hello);
  s.SendCredit(uint64_t{1} << 50);
  Walker walker(streets, seed, speed);
  // 1.2 m above the band's base: on flat ground base_z + 1.2, over terrain that above the ground.
  const double eye = grid.base_z() + 1.2;
  auto pose = [&] {
    const glm::dvec2 p = walker.position(), v = walker.velocity();
    s.SendPose({p.x, p.y, terrain.empty() ? eye : terrain.HeightAt(p) + eye}, {v.x, v.y, 0.0});
  };
  pose();
  visibility::CellId cell = *grid.CellAt(walker.position());
  const double t0 = SteadySeconds();
  // Start-up: the nine cells around the client, in slices so that ^C is heard.
  bool ready = false;
  while (!ready && !cancel.load() && !s.Ended() && SteadySeconds() - t0 < 300.0) {
    ready = s.WaitFor([&](const client::SessionRecord& r) { return r.AllComplete(grid.Neighbourhood(cell)); }, 0.5);
  }
  if (!ready) {
    out.error = s.Ended() ? "the server ended the session" : cancel.load() ? "interrupted" : "start-up took over 300 s";
    return out;
  }
  out.started = true;
  out.startup_s = SteadySeconds() - t0;
  const client::SessionRecord at_start = s.Snapshot();
  // A crossing ends when each newly adjacent cell that was not complete when the client
  // crossed has become complete.
  struct Crossing {
    double t;
    std::vector<visibility::CellId> pending;
  };
  std::vector<Crossing> crossings;
  auto finished = [](const client::SessionRecord& r, const Crossing& c, double* end) {
    *end = c.t;
    for (visibility::CellId p : c.pending) {
      const double done = r.CompletedAfter(p, c.t);
      if (done < 0.0) return false;
      *end = std::max(*end, done);
    }
    return true;
  };
  constexpr double kDt = 1.0 / client::kPoseRateHz;  // a pose a step, at the client model's rate
  const double start = SteadySeconds();
  double next = start;
  while (SteadySeconds() - start < seconds && !cancel.load()) {
    if (s.Ended()) {
      out.error = "the server ended the session while the client walked";
      break;
    }
    next += kDt;
    std::this_thread::sleep_for(std::chrono::duration<double>(std::max(0.0, next - SteadySeconds())));
    walker.Step(kDt);
    const std::optional<visibility::CellId> now_cell = grid.CellAt(walker.position());
    if (now_cell.has_value() && *now_cell != cell) {
      ++out.cells_entered;
      const double t = SteadySeconds();
      const client::SessionRecord r = s.Snapshot();
      if (!r.CellComplete(*now_cell)) ++out.late_cells;
      Crossing c{t, {}};
      // Newly adjacent cells; after a jump past a neighbour (tiny cells, high speed), those of
      // the new neighbourhood that were not in the old one.
      std::vector<visibility::CellId> fresh = grid.NewlyAdjacent(cell, *now_cell);
      if (fresh.empty()) {
        const std::vector<visibility::CellId> before = grid.Neighbourhood(cell);
        for (visibility::CellId n : grid.Neighbourhood(*now_cell)) {
          if (std::find(before.begin(), before.end(), n) == before.end()) fresh.push_back(n);
        }
      }
      for (visibility::CellId n : fresh) {
        if (!r.CellComplete(n)) c.pending.push_back(n);
      }
      crossings.push_back(c);
      cell = *now_cell;
    }
    pose();
  }
  // The last crossing's cells are still wanted: give them time. Earlier ones the walker may
  // have left before they completed (abandoned: counted apart).
  if (!crossings.empty() && out.error.empty() && !cancel.load()) {
    double unused;
    s.WaitFor([&](const client::SessionRecord& r) { return finished(r, crossings.back(), &unused); }, 60.0);
  }
  const client::SessionRecord end = s.Snapshot();
  for (const Crossing& c : crossings) {
    ++out.crossings;
    double done = 0.0;
    if (!finished(end, c, &done)) {
      ++out.incomplete_crossings;
      continue;
    }
    out.crossing_ms.push_back(1000.0 * (done - c.t));
  }
  out.geometry_bytes = end.geometry_bytes - at_start.geometry_bytes;
  out.raw_geometry_bytes = end.raw_geometry_bytes - at_start.raw_geometry_bytes;
  out.masks = end.masks.size();
  out.mask_bytes = end.mask_bytes;
  out.level_objects = end.level_objects;
  if (!end.bad_data.empty() && out.error.empty()) out.error = "a PVS list that does not decode: " + end.bad_data;
  const grpc::Status st = s.Finish();
  if (!st.ok() && out.error.empty()) out.error = st.error_message();
  return out;
}

// CPU seconds (user + system) the process has used; 0 when /proc says nothing.
double CpuSeconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(in, line)) return 0.0;
  // Fields after the command's closing parenthesis: state is field 3, utime 14, stime 15.
  const size_t close = line.rfind(')');
  if (close == std::string::npos) return 0.0;
  std::istringstream rest(line.substr(close + 2));
  std::string field;
  double utime = 0.0, stime = 0.0;
  for (int k = 3; k <= 15 && rest >> field; ++k) {
    if (k == 14) utime = std::strtod(field.c_str(), nullptr);
    if (k == 15) stime = std::strtod(field.c_str(), nullptr);
  }
  return (utime + stime) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

uint64_t RssKiB(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string key;
  while (in >> key) {
    if (key == "VmRSS:") {
      uint64_t kib = 0;
      in >> kib;
      return kib;
    }
    in.ignore(1 << 20, '\n');
  }
  return 0;
}

// One run: a server (TLS when `tls`), the walkers, their figures as JSON in `*j`. 0 or the
// tool's exit code.
int RunOnce(const BenchServerArgs& a, bool tls, double tau_px, const RunContext& run, nlohmann::json* result) {
  // The server: the vistream-server beside this executable, on a free loopback port.
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe");
  const std::string server_bin = (self.parent_path() / "vistream-server").string();
  if (!std::filesystem::exists(server_bin)) return Fail(absl::NotFoundError("no vistream-server beside " + self.string()));
  const std::string log = a.log.empty() ? "/dev/null" : a.log;
  // Cells of the catalog entry's size unless --cell-size says otherwise, on both sides.
  const scenes::ViewcellSpec grid_spec = scenes::ViewcellSpecFor(a.scene, a.cell_size);
  client::ChannelSecurity security;
  std::vector<std::string> tls_args;
  const std::string dir =
      (std::filesystem::temp_directory_path() / ("vistream-bench-tls-" + std::to_string(getpid()))).string();
  struct RemoveDir {  // the run's certificates go with it
    std::string dir;
    ~RemoveDir() {
      std::error_code ignored;
      std::filesystem::remove_all(dir, ignored);
    }
  } remove_dir{tls ? dir : ""};
  if (tls) {
    absl::StatusOr<RunCertificates> certs = MakeCertificates(dir);
    if (!certs.ok()) return Fail(certs.status());
    absl::StatusOr<client::ChannelSecurity> loaded = client::LoadChannelSecurity(certs->ca, "", "", "");
    if (!loaded.ok()) return Fail(loaded.status());
    security = *loaded;
    tls_args = {"--tls-cert", certs->cert, "--tls-key", certs->key};
  }
  std::vector<std::string> args = {"--scene", a.scene,
                                   "--cell-size", absl::StrFormat("%.17g", grid_spec.size_m),
                                   "--res", std::to_string(a.res),
                                   "--threads", std::to_string(a.threads),
                                   "--max-sessions", std::to_string(a.sessions + 8),
                                   "--drain", "0"};
  args.insert(args.end(), tls_args.begin(), tls_args.end());
  if (tau_px > 0.0) args.push_back("--levels");
  if (!run.store_address.empty()) args.insert(args.end(), {"--store", run.store_address, "--store-prefix", run.store_prefix});
  if (!run.store_password_file.empty()) args.insert(args.end(), {"--store-password-file", run.store_password_file});
  Replicas replicas;
  std::string start_error;
  if (a.balancer == "haproxy") {
    BalancerOptions o;
    o.replicas = a.replicas;
    o.replica_args = args;
    o.server_bin = server_bin;
    o.config_template = HaproxyTemplate();
    if (o.config_template.empty()) {
      return Fail(absl::NotFoundError("deploy/haproxy.cfg is neither in the build tree nor installed beside " +
                                      self.string()));
    }
    replicas.dir = (std::filesystem::temp_directory_path() / ("vistream-bench-replicas-" + std::to_string(getpid())))
                       .string();
    o.dir = replicas.dir;
    replicas.balanced = Balancer::Start(o, &start_error);
    if (replicas.balanced != nullptr) replicas.address = replicas.balanced->address();
  } else {
    args.insert(args.end(), {"--listen", "127.0.0.1:0"});
    replicas.single = RunningServer::Start(server_bin, args, &start_error, log);
    if (replicas.single != nullptr) replicas.address = replicas.single->address();
  }
  if (replicas.address.empty()) {
    replicas.Stop();
    return Fail(absl::UnavailableError(absl::StrFormat("vistream-server did not start: %s%s", start_error,
                                                       a.log.empty() ? " (run with --log FILE to see why)" : "")));
  }
  auto stop_server = [&] {
    if (!a.log.empty() && replicas.balanced != nullptr) {
      // The replicas' logs beside --log: FILE.replica1, FILE.replica2, ...
      for (size_t k = 0; k < replicas.size(); ++k) {
        std::error_code ignored;
        std::filesystem::copy_file(replicas.dir + "/" + replicas.balanced->name(k) + ".log",
                                   a.log + "." + replicas.balanced->name(k),
                                   std::filesystem::copy_options::overwrite_existing, ignored);
      }
    }
    return replicas.Stop();
  };

  // Meanwhile the same scene here, for the walkers' streets and the grid.
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.scene);
  if (!scene.ok()) {
    stop_server();
    return Fail(scene.status());
  }
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(*scene, grid_spec);
  if (!grid.ok()) {
    stop_server();
    return Fail(grid.status());
  }
  const std::string address = replicas.address;
  if (!a.json && !run.warmup) {
    std::fprintf(stderr, "%s\n", replicas.balanced != nullptr
                                     ? absl::StrFormat("%zu replicas behind HAProxy on %s", replicas.size(), address).c_str()
                                     : replicas.single->ready_line().c_str());
  }

  const Streets streets(*scene, grid->Bounds(), 3.0);
  const scenes::TerrainHeight terrain(*scene);
  std::atomic<bool> sampling{true};
  std::atomic<uint64_t> max_rss{0};
  std::thread rss([&] {
    while (sampling) {
      for (size_t k = 0; k < replicas.size(); ++k) max_rss = std::max<uint64_t>(max_rss, RssKiB(replicas.pid(k)));
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
    }
  });
  std::vector<SessionResult> results(a.sessions);
  double cpu_start = 0.0;
  for (size_t k = 0; k < replicas.size(); ++k) cpu_start += CpuSeconds(replicas.pid(k));
  const double walk_start = SteadySeconds();
  {
    // Progress in seconds of the walk (start-up first, whose length depends on the server).
    const uint64_t total = static_cast<uint64_t>(std::ceil(a.seconds));
    scenes::Progress progress(ToolRun(),
                              absl::StrFormat("%s%zu sessions at %g km/h%s%s", run.warmup ? "warming the store: " : "",
                                              a.sessions, a.speed_kmh, tls ? " (TLS)" : "",
                                              a.replicas > 1 ? absl::StrFormat(", %zu replicas", a.replicas) : ""),
                              total);
    std::atomic<size_t> finished{0};
    std::vector<std::jthread> threads;
    for (size_t k = 0; k < a.sessions; ++k) {
      threads.emplace_back([&, k] {
        results[k] = RunSession(address, security, scene->name, streets, *grid, terrain, a.seed * 1000003 + k,
                                a.speed_kmh / 3.6, a.seconds, a.masks == "on", tau_px, CancelFlag());
        ++finished;
      });
    }
    const double t0 = SteadySeconds();
    uint64_t shown = 0;
    while (finished.load() < a.sessions) {
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
      progress.SetDetail(absl::StrFormat("%zu of %zu sessions done", finished.load(), a.sessions));
      const uint64_t now = std::min<uint64_t>(total, static_cast<uint64_t>(SteadySeconds() - t0));
      if (now > shown) {
        progress.Advance(now - shown);
        shown = now;
      }
    }
    threads.clear();
    progress.Finish();
  }
  const double walk_s = SteadySeconds() - walk_start;
  double server_cpu_s = -cpu_start;
  for (size_t k = 0; k < replicas.size(); ++k) server_cpu_s += CpuSeconds(replicas.pid(k));
  // Every replica's own figures (asked directly, not through the balancer), and their sum.
  v1::ServerStats stats;
  grpc::Status stats_status;
  std::vector<v1::ServerStats> per_replica(replicas.size());
  for (size_t k = 0; k < replicas.size(); ++k) {
    v1::Walkthrough::Stub stub(client::MakeChannel(replicas.replica_address(k), security));
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    const grpc::Status st = stub.GetStats(&ctx, v1::StatsRequest(), &per_replica[k]);
    if (!st.ok() && stats_status.ok()) stats_status = st;
    const v1::ServerStats& r = per_replica[k];
    stats.set_pvs_computed(stats.pvs_computed() + r.pvs_computed());
    stats.set_pvs_cache_hits(stats.pvs_cache_hits() + r.pvs_cache_hits());
    stats.set_pvs_store_hits(stats.pvs_store_hits() + r.pvs_store_hits());
    stats.set_bytes_sent(stats.bytes_sent() + r.bytes_sent());
    stats.set_sessions_total(stats.sessions_total() + r.sessions_total());
    stats.set_epsilon_masks_computed(stats.epsilon_masks_computed() + r.epsilon_masks_computed());
    stats.set_epsilon_mask_compute_s(stats.epsilon_mask_compute_s() + r.epsilon_mask_compute_s());
    if (r.has_store()) {
      stats.mutable_store()->set_outages(stats.store().outages() + r.store().outages());
      stats.mutable_store()->set_unavailable(stats.store().unavailable() + r.store().unavailable());
    }
  }
  sampling = false;
  rss.join();
  const int server_exit = stop_server();
  if (CancelFlag().load()) return Fail(absl::CancelledError("bench server stopped"));

  uint64_t late = 0, entered = 0, crossings = 0, incomplete = 0, started = 0, without_late = 0, bytes = 0, raw = 0;
  uint64_t masks = 0, mask_bytes = 0, level_objects = 0;
  std::vector<double> crossing_ms, startup_s;
  std::string first_error;
  for (const SessionResult& r : results) {
    if (!r.error.empty() && first_error.empty()) first_error = r.error;
    if (!r.started) continue;
    ++started;
    startup_s.push_back(r.startup_s);
    late += r.late_cells;
    entered += r.cells_entered;
    crossings += r.crossings;
    incomplete += r.incomplete_crossings;
    if (r.late_cells == 0 && r.error.empty()) ++without_late;
    crossing_ms.insert(crossing_ms.end(), r.crossing_ms.begin(), r.crossing_ms.end());
    bytes += r.geometry_bytes;
    raw += r.raw_geometry_bytes;
    masks += r.masks;
    mask_bytes += r.mask_bytes;
    level_objects += r.level_objects;
  }
  const double hits = static_cast<double>(stats.pvs_cache_hits());
  const double computed = static_cast<double>(stats.pvs_computed());
  nlohmann::json& j = *result;
  j["scene"] = scene->name;
  j["tls"] = tls;
  j["lod_tau_px"] = tau_px > 0.0 ? nlohmann::json(tau_px) : nlohmann::json();
  j["level_objects_received"] = level_objects;
  j["sessions"] = a.sessions;
  j["sessions_started"] = started;
  j["sessions_without_late_cells"] = without_late;
  j["speed_kmh"] = a.speed_kmh;
  j["seconds"] = a.seconds;
  j["cell_size"] = grid->cell_size();
  j["res"] = a.res;
  j["cells_entered"] = entered;
  j["late_cells"] = late;
  j["crossings"] = crossings;
  j["incomplete_crossings"] = incomplete;
  j["crossing_p50_ms"] = Percentile(crossing_ms, 0.5);
  j["crossing_p99_ms"] = Percentile(crossing_ms, 0.99);
  j["startup_p50_s"] = Percentile(startup_s, 0.5);
  j["pvs_computations"] = stats.pvs_computed();
  j["cache_hits"] = stats.pvs_cache_hits();
  j["replicas"] = per_replica.size();
  j["balancer"] = a.balancer;
  j["store"] = a.store;
  j["store_warm"] = a.warm;
  j["store_hits"] = stats.pvs_store_hits();
  j["store_outages"] = stats.store().outages();
  {
    const double store_hits = static_cast<double>(stats.pvs_store_hits());
    j["store_hit_rate"] = store_hits + computed > 0 ? store_hits / (store_hits + computed) : 0.0;
    nlohmann::json per = nlohmann::json::array(), computations = nlohmann::json::array();
    for (const v1::ServerStats& r : per_replica) {
      computations.push_back(r.pvs_computed());
      per.push_back({{"sessions_total", r.sessions_total()},
                     {"pvs_computations", r.pvs_computed()},
                     {"store_hits", r.pvs_store_hits()},
                     {"cache_hits", r.pvs_cache_hits()},
                     {"bytes_sent", r.bytes_sent()}});
    }
    j["pvs_computations_per_replica"] = computations;
    j["per_replica"] = per;
  }
  j["cache_hit_rate"] = hits + computed > 0 ? hits / (hits + computed) : 0.0;
  j["bytes_per_crossing"] = crossings > 0 ? static_cast<double>(bytes) / static_cast<double>(crossings) : 0.0;
  j["bytes_per_crossing_raw"] = crossings > 0 ? static_cast<double>(raw) / static_cast<double>(crossings) : 0.0;
  j["encoded_fraction"] = raw > 0 ? static_cast<double>(bytes) / static_cast<double>(raw) : 0.0;
  j["rss_mb"] = static_cast<double>(max_rss.load()) / 1024.0;
  j["bytes_sent"] = stats.bytes_sent();
  j["walk_s"] = walk_s;
  j["bytes_per_s"] = walk_s > 0.0 ? static_cast<double>(stats.bytes_sent()) / walk_s : 0.0;
  j["server_exit_code"] = server_exit;
  // ε-masks (issue 34): what the walkers received, and the server's CPU for them: seconds, and
  // their share of the server's CPU and of every core over the walk (start-up included).
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  j["masks"] = a.masks;
  j["masks_received"] = masks;
  j["mask_bytes"] = mask_bytes;
  j["masks_computed"] = stats.epsilon_masks_computed();
  j["mask_cpu_s"] = stats.epsilon_mask_compute_s();
  j["server_cpu_s"] = server_cpu_s;
  j["mask_cpu_share_of_server"] = server_cpu_s > 0.0 ? stats.epsilon_mask_compute_s() / server_cpu_s : 0.0;
  j["mask_cpu_share_of_cores"] = walk_s > 0.0 ? stats.epsilon_mask_compute_s() / (walk_s * cores) : 0.0;
  j["server_cpu_share_of_cores"] = walk_s > 0.0 ? server_cpu_s / (walk_s * cores) : 0.0;
  j["cores"] = cores;
  if (!first_error.empty()) j["first_error"] = first_error;
  if (!a.json && !run.warmup) {
    std::printf("%s, %zu sessions at %g km/h for %g s, %g m viewcells at %u^2%s%s\n", scene->name.c_str(), a.sessions,
                a.speed_kmh, a.seconds, grid->cell_size(), a.res, tls ? ", TLS" : "",
                (tau_px > 0.0 ? absl::StrFormat(", levels at tau %g px (%llu objects at a level)", tau_px,
                                                static_cast<unsigned long long>(level_objects))
                              : std::string(", full detail"))
                    .c_str());
    std::printf("  sessions started %llu, without a late cell %llu; cells entered %llu, late %llu\n",
                static_cast<unsigned long long>(started), static_cast<unsigned long long>(without_late),
                static_cast<unsigned long long>(entered), static_cast<unsigned long long>(late));
    std::printf("  crossings %llu (%llu left before complete); latency p50 %.0f ms, p99 %.0f ms; start-up p50 %.1f s\n",
                static_cast<unsigned long long>(crossings), static_cast<unsigned long long>(incomplete),
                Percentile(crossing_ms, 0.5), Percentile(crossing_ms, 0.99), Percentile(startup_s, 0.5));
    std::printf("  PVS computations %llu, cache hits %llu (%.1f%%)\n", static_cast<unsigned long long>(computed),
                static_cast<unsigned long long>(hits), 100.0 * j["cache_hit_rate"].get<double>());
    if (a.replicas > 1 || a.store != "none") {
      std::string per;
      for (size_t k = 0; k < per_replica.size(); ++k) {
        per += absl::StrFormat("%s%llu", k == 0 ? "" : ", ", static_cast<unsigned long long>(per_replica[k].pvs_computed()));
      }
      std::printf("  %zu replica%s (PVS computations %s); store %s%s: %llu hits (%.1f%% of PVSs not in a local cache)\n",
                  per_replica.size(), per_replica.size() == 1 ? "" : "s", per.c_str(), a.store.c_str(),
                  a.warm ? " (warmed)" : "", static_cast<unsigned long long>(stats.pvs_store_hits()),
                  100.0 * j["store_hit_rate"].get<double>());
    }
    std::printf("  bytes per crossing %.0f encoded, %.0f raw (%.3f); server RSS %.0f MiB\n",
                j["bytes_per_crossing"].get<double>(), j["bytes_per_crossing_raw"].get<double>(),
                j["encoded_fraction"].get<double>(), j["rss_mb"].get<double>());
    std::printf("  %.0f bytes/s sent (%llu bytes in %.1f s)\n", j["bytes_per_s"].get<double>(),
                static_cast<unsigned long long>(stats.bytes_sent()), walk_s);
    std::printf("  ε-masks %s: %llu received (%llu bytes), %llu computed in %.1f CPU s: %.1f%% of the server's %.1f "
                "CPU s, %.1f%% of %u cores (the server used %.1f%%)\n",
                a.masks.c_str(), static_cast<unsigned long long>(masks), static_cast<unsigned long long>(mask_bytes),
                static_cast<unsigned long long>(stats.epsilon_masks_computed()), stats.epsilon_mask_compute_s(),
                100.0 * j["mask_cpu_share_of_server"].get<double>(), server_cpu_s,
                100.0 * j["mask_cpu_share_of_cores"].get<double>(), cores,
                100.0 * j["server_cpu_share_of_cores"].get<double>());
    if (!first_error.empty()) std::printf("  first session error: %s\n", first_error.c_str());
  }
  // A run whose server or sessions failed measured something else: say so and fail.
  if (server_exit != 0) return Fail(absl::InternalError(absl::StrFormat("vistream-server exited %d", server_exit)));
  if (!stats_status.ok()) {
    return Fail(absl::UnavailableError("the server's statistics are missing: " + stats_status.error_message()));
  }
  if (!first_error.empty()) return Fail(absl::UnavailableError("a session failed: " + first_error));
  if (stats.store().outages() > 0) {
    return Fail(absl::UnavailableError(absl::StrFormat(
        "the PVS store at %s went down %llu times during the run (replicas' logs: --log FILE): these figures are "
        "not those of a shared store",
        run.store_address, static_cast<unsigned long long>(stats.store().outages()))));
  }
  return 0;
}

int BenchServer(const BenchServerArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  if (a.replicas > 1 && a.balancer != "haproxy") {
    return BadOption("bench server", "--replicas", "several replicas need a balancer in front: add --balancer haproxy");
  }
  if (a.store != "none" && a.store != "redis" && !server::IsStoreAddress(a.store)) {
    return BadOption("bench server", "--store", "'" + a.store + "' is not none, redis or HOST:PORT of a Redis");
  }
  if (a.warm && a.store == "none") return BadOption("bench server", "--warm", "warms the PVS store: give --store");
  if (a.warm && a.tls == "both") return BadOption("bench server", "--warm", "one run at a time: not with --tls both");
  // Levels of detail: each of --lod is a run, side by side (off, or tau in pixels).
  std::vector<double> taus;
  if (std::string why; !cli::ParseScreenErrors(a.lod, /*refuse_repeats=*/true, &taus, &why)) {
    return BadOption("bench server", "--lod", why);
  }
  if (taus.size() > 1 && (a.tls == "both" || a.warm)) {
    return BadOption("bench server", "--lod", "several runs: not with --tls both or --warm");
  }
  InstallCancelHandler();
  // The store: a redis-server of the run's own (empty at the start: a cold store), or the one
  // given, under a key prefix of this run's own (cold there too).
  RunContext run;
  std::unique_ptr<RedisServer> redis;
  if (a.store == "redis") {
    std::string error;
    redis = RedisServer::Start(&error);
    if (redis == nullptr) return Fail(absl::UnavailableError("--store redis: " + error));
    run.store_address = redis->address();
  } else if (a.store != "none") {
    run.store_address = a.store;
  }
  struct RemoveFile {  // the password file goes with the run
    std::string path;
    ~RemoveFile() {
      if (!path.empty()) std::remove(path.c_str());
    }
  } password_file;
  if (!run.store_address.empty()) {
    run.store_prefix = absl::StrFormat("vistream-bench-%d-%d", getpid(), time(nullptr));
    // The store answers (and takes the password, if one is given) before anything is measured:
    // replicas that cannot reach it would measure a run without it.
    server::PvsStoreOptions so;
    so.address = run.store_address;
    so.connect_timeout_s = 5.0;
    so.read_timeout_s = 5.0;
    if (const char* password = std::getenv("VISTREAM_STORE_PASSWORD"); password != nullptr && *password != 0) {
      so.password = password;
      password_file.path = (std::filesystem::temp_directory_path() /
                            ("vistream-bench-store-" + std::to_string(getpid()) + ".password"))
                               .string();
      const int fd = ::open(password_file.path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      if (fd < 0 || ::write(fd, so.password.data(), so.password.size()) != static_cast<ssize_t>(so.password.size())) {
        if (fd >= 0) ::close(fd);
        return Fail(absl::InternalError("cannot write " + password_file.path));
      }
      ::close(fd);
      run.store_password_file = password_file.path;
    }
    absl::StatusOr<std::unique_ptr<server::PvsStore>> probe = server::PvsStore::Create(so);
    if (!probe.ok()) return BadOption("bench server", "--store", std::string(probe.status().message()));
    if (absl::Status st = (*probe)->Connect(); !st.ok()) return Fail(st);
  }
  if (a.warm) {
    // The same walkers (same seed) once before, on replicas of their own: every cell the
    // measured pass needs is then in the store, and none in the measured replicas' caches.
    RunContext warmup = run;
    warmup.warmup = true;
    nlohmann::json ignored;
    if (const int rc = RunOnce(a, a.tls == "on", taus.front(), warmup, &ignored); rc != 0) return rc;
  }
  if (taus.size() > 1) {
    // Side by side in one run: the same walkers (same seed) at each screen error.
    nlohmann::json j;
    j["runs"] = nlohmann::json::array();
    for (double tau : taus) {
      nlohmann::json r;
      if (const int rc = RunOnce(a, a.tls == "on", tau, run, &r); rc != 0) return rc;
      j["runs"].push_back(r);
    }
    // Each run with levels against the first run at full detail, if there is one.
    auto full = std::find(taus.begin(), taus.end(), 0.0);
    if (full != taus.end()) {
      const nlohmann::json& f = j["runs"][static_cast<size_t>(full - taus.begin())];
      auto ratio = [&](const nlohmann::json& x, const char* key) {
        const double d = f[key].get<double>();
        return d > 0.0 ? x[key].get<double>() / d : 0.0;
      };
      j["levels_over_full"] = nlohmann::json::array();
      for (size_t k = 0; k < taus.size(); ++k) {
        if (taus[k] == 0.0) continue;
        const nlohmann::json& x = j["runs"][k];
        j["levels_over_full"].push_back({{"lod_tau_px", taus[k]},
                                         {"bytes_per_crossing", ratio(x, "bytes_per_crossing")},
                                         {"bytes_per_s", ratio(x, "bytes_per_s")},
                                         {"crossing_p50_ms", ratio(x, "crossing_p50_ms")},
                                         {"crossing_p99_ms", ratio(x, "crossing_p99_ms")},
                                         {"rss_mb", ratio(x, "rss_mb")},
                                         {"late_cells", x["late_cells"]},
                                         {"late_cells_full", f["late_cells"]}});
        if (!a.json) {
          std::printf("levels at tau %g px over full detail: bytes per crossing %.3f, bytes/s %.3f, crossing p50 %.3f, "
                      "p99 %.3f, server RSS %.3f; late cells %llu against %llu\n",
                      taus[k], ratio(x, "bytes_per_crossing"), ratio(x, "bytes_per_s"), ratio(x, "crossing_p50_ms"),
                      ratio(x, "crossing_p99_ms"), ratio(x, "rss_mb"), x["late_cells"].get<unsigned long long>(),
                      f["late_cells"].get<unsigned long long>());
        }
      }
    }
    if (a.json) std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  if (a.tls != "both") {
    nlohmann::json j;
    if (const int rc = RunOnce(a, a.tls == "on", taus.front(), run, &j); rc != 0) return rc;
    if (a.json) std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  // Side by side in one run: plaintext, then TLS, the same walkers (same seed).
  nlohmann::json plain, tls;
  if (const int rc = RunOnce(a, false, taus.front(), run, &plain); rc != 0) return rc;
  if (const int rc = RunOnce(a, true, taus.front(), run, &tls); rc != 0) return rc;
  auto ratio = [](const nlohmann::json& x, const nlohmann::json& y, const char* key) {
    const double d = y[key].get<double>();
    return d > 0.0 ? x[key].get<double>() / d : 0.0;
  };
  nlohmann::json j;
  j["runs"] = {plain, tls};
  j["tls_over_plain"] = {{"bytes_per_s", ratio(tls, plain, "bytes_per_s")},
                         {"crossing_p50_ms", ratio(tls, plain, "crossing_p50_ms")},
                         {"crossing_p99_ms", ratio(tls, plain, "crossing_p99_ms")},
                         {"rss_mb", ratio(tls, plain, "rss_mb")}};
  if (a.json) {
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf("TLS over plaintext: bytes/s %.3f, crossing p50 %.3f, p99 %.3f, server RSS %.3f\n",
                j["tls_over_plain"]["bytes_per_s"].get<double>(), j["tls_over_plain"]["crossing_p50_ms"].get<double>(),
                j["tls_over_plain"]["crossing_p99_ms"].get<double>(), j["tls_over_plain"]["rss_mb"].get<double>());
  }
  return 0;
}

}  // namespace

void AddBenchServerCommand(CLI::App* bench, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<BenchServerArgs>(
      bench, "server", "simulated clients walking a city through a real vistream-server",
      BenchServer, done);
  c->add_option("--scene", args->scene, "catalog name, .json or glTF")->capture_default_str();
  c->add_option("--sessions", args->sessions, "simulated clients at once")->check(WholeRange(1, 1000))
      ->capture_default_str();
  c->add_option("--speed", args->speed_kmh, "walking speed, km/h")->check(FiniteRange(0.1, 500.0))
      ->capture_default_str();
  c->add_option("--seconds", args->seconds, "how long each client walks, after its start-up")
      ->check(FiniteRange(1.0, 86400.0))->capture_default_str();
  c->add_option("--cell-size", args->cell_size, "viewcell edge, metres (default: the catalog entry's)")
      ->check(FiniteRange(1.0, 10000.0));  // the walkers need room in a cell
  c->add_option("--res", args->res, "finest dual-ray-space raster")->check(PowerOfTwo(1, 256))->capture_default_str();
  c->add_option("--threads", args->threads, "server PVS workers (0: one per core)")->check(WholeRange(0, 1024))
      ->capture_default_str();
  c->add_option("--seed", args->seed, "walkers' seed")->check(WholeRange(0, kMaxSeed))->capture_default_str();
  c->add_option("--log", args->log, "write the server's log here")->check(OutputPath());
  c->add_flag("--json", args->json, "print one JSON object");
  c->add_option("--lod", args->lod,
                 "levels of detail the walkers ask for: off, or a screen error in pixels, or several (off,1): one run "
                 "each, side by side (the server made with --levels)")
      ->capture_default_str();
  c->add_option("--masks", args->masks, "on | off: whether the walkers ask for ε-masks (Hello.epsilon_masks)")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  c->add_option("--tls", args->tls,
                "off | on | both: serve TLS (a certificate made for the run with openssl); both: plaintext and TLS "
                "side by side, with their ratios")
      ->check(CLI::IsMember({"off", "on", "both"}))
      ->capture_default_str();
  c->add_option("--replicas", args->replicas, "vistream-server replicas (more than one: behind --balancer haproxy)")
      ->check(WholeRange(1, 64))
      ->capture_default_str();
  c->add_option("--balancer", args->balancer,
                "none | haproxy: the replicas behind a real HAProxy running deploy/haproxy.cfg (ports, stats socket "
                "and check timers adapted), the walkers connecting through it")
      ->check(CLI::IsMember({"none", "haproxy"}))
      ->capture_default_str();
  c->add_option("--store", args->store,
                "none | redis | HOST:PORT: the replicas share a PVS store, in a redis-server of the run's own (empty "
                "at the start) or in the Redis given (password from $VISTREAM_STORE_PASSWORD; under a key prefix "
                "vistream-bench-PID-TIME of the run's own, which stays there: delete it with redis-cli --scan "
                "--pattern 'vistream-bench-*' | xargs redis-cli del)")
      ->capture_default_str();
  c->add_flag("--warm", args->warm,
              "fill the store first with the same walks on replicas of their own; then measure on "
              "fresh replicas");
}

}  // namespace vistream::tools
