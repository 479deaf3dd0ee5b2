#pragma once
// Real processes on loopback for the tests and `vistream bench server`: a vistream-server
// executable (its ready line, its address, a stop that never leaves it running), a redis-server
// without persistence (the shared PVS store's), and N replicas behind a real HAProxy running the
// repository's deploy/haproxy.cfg with only what a run on one machine must change: its ports
// (every process on a free one), a stats socket and log in the run's folder, no user switch or
// daemon, and health checks ten times faster. Each is stopped, whatever its user did, by its
// destructor. Header-only: the tests and the tool include it.

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace vistream::tools {

// A TCP port on 127.0.0.1 that was free a moment ago (bound to port 0, then closed).
inline int FreeLoopbackPort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return 0;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(a);
  int port = 0;
  if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
    port = ntohs(a.sin_port);
  }
  close(fd);
  return port;
}

// Sends `request` to 127.0.0.1:PORT and returns what comes back: everything until the server
// closes, or with `first_read_only` what its first read gives (a server that keeps the
// connection, e.g. after a WebSocket handshake). Empty when nothing answers within `timeout_s`.
inline std::string LoopbackExchange(int port, const std::string& request, bool first_read_only = false,
                                    int timeout_s = 5) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return "";
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval timeout{timeout_s, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
  std::string reply;
  if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
      write(fd, request.data(), request.size()) == static_cast<ssize_t>(request.size())) {
    char buf[4096];
    for (ssize_t n; (n = read(fd, buf, sizeof(buf))) > 0;) {
      reply.append(buf, static_cast<size_t>(n));
      if (first_read_only) break;
    }
  }
  close(fd);
  return reply;
}

// GET http://127.0.0.1:PORT/PATH over HTTP/1.0 (the server closes after its answer): the status
// (0 when nothing answers within 5 s) and the body.
inline std::pair<int, std::string> HttpGet(int port, const std::string& path) {
  const std::string reply = LoopbackExchange(port, "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n");
  // "HTTP/1.1 200 OK\r\n...\r\n\r\nBODY"
  const size_t space = reply.find(' ');
  if (!reply.starts_with("HTTP/") || space == std::string::npos) return {0, ""};
  const size_t body = reply.find("\r\n\r\n");
  return {std::atoi(reply.c_str() + space + 1), body == std::string::npos ? "" : reply.substr(body + 4)};
}

class RunningServer {
 public:
  // Starts `binary` with `args` (stdout read for the ready line, stderr to `log_path` if given,
  // else inherited). Returns null, with what it printed in `*error`, when it exits or prints
  // something else first.
  static std::unique_ptr<RunningServer> Start(const std::string& binary, const std::vector<std::string>& args,
                                              std::string* error, const std::string& log_path = "") {
    int out[2];
    if (pipe(out) != 0) return nullptr;
    const pid_t pid = fork();
    if (pid < 0) return nullptr;
    if (pid == 0) {
      dup2(out[1], STDOUT_FILENO);
      close(out[0]);
      if (!log_path.empty()) {  // open(), not fopen(): async-signal-safe in the forked child
        if (const int log = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644); log >= 0) {
          dup2(log, STDERR_FILENO);
        }
      }
      std::vector<char*> argv{const_cast<char*>(binary.c_str())};
      for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(binary.c_str(), argv.data());
      _exit(127);
    }
    close(out[1]);
    std::unique_ptr<RunningServer> s(new RunningServer());
    s->pid_ = pid;
    s->out_ = fdopen(out[0], "r");
    char line[4096] = {};
    if (std::fgets(line, sizeof(line), s->out_) == nullptr) {
      if (error != nullptr) *error = "the server exited (status " + std::to_string(s->Stop(SIGKILL)) + ")";
      return nullptr;
    }
    s->ready_ = line;
    const size_t at = s->ready_.find("ready on ");
    if (at == std::string::npos) {
      if (error != nullptr) *error = s->ready_;
      return nullptr;
    }
    const size_t colon = s->ready_.find(':', at + 9);
    s->address_ = s->ready_.substr(at + 9, s->ready_.find(':', colon + 1) - at - 9);
    return s;
  }

  ~RunningServer() {
    if (pid_ > 0) Stop(SIGKILL);
  }

  const std::string& address() const { return address_; }
  const std::string& ready_line() const { return ready_; }
  pid_t pid() const { return pid_; }
  // The port of address().
  int port() const { return std::stoi(address_.substr(address_.rfind(':') + 1)); }

  // Sends `sig` (0: none, only waits) and waits: the exit code, 128 + the signal if killed, -1
  // if already stopped.
  int Stop(int sig = SIGTERM) {
    if (pid_ <= 0) return -1;
    if (sig != 0) kill(pid_, sig);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    if (out_ != nullptr) std::fclose(out_);
    out_ = nullptr;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

 private:
  RunningServer() = default;
  pid_t pid_ = -1;
  std::FILE* out_ = nullptr;
  std::string ready_, address_;
};

// A redis-server (Debian's) on a free loopback port, without persistence.
class RedisServer {
 public:
  // Starts redis-server on 127.0.0.1 at a free port and waits until it answers PING (or asks
  // for a password). `more`: further redis-server options (a TLS port, requirepass). Null, with
  // why in `*error`, when redis-server is missing or does not come up.
  static std::unique_ptr<RedisServer> Start(std::string* error, std::vector<std::string> more = {}) {
    std::unique_ptr<RedisServer> r(new RedisServer());
    r->more_ = std::move(more);
    r->port_ = FreeLoopbackPort();
    if (!r->Launch(error)) return nullptr;
    return r;
  }
  ~RedisServer() { Stop(); }

  int port() const { return port_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  pid_t pid() const { return pid_; }

  // Stops it (SIGKILL: an outage, not a shutdown) and reaps it.
  void Stop() {
    if (pid_ <= 0) return;
    kill(pid_, SIGCONT);
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }
  // Starts it again on the same port (empty: no persistence).
  bool Restart(std::string* error) {
    Stop();
    return Launch(error);
  }
  // Freezes and thaws it (SIGSTOP, SIGCONT): a store that accepts connections but answers
  // nothing, as an overloaded one.
  void Pause() { kill(pid_, SIGSTOP); }
  void Resume() { kill(pid_, SIGCONT); }

  // redis-cli's output for `args` (a shell line's words) against this server.
  std::string Cli(const std::string& args) const {
    std::string out;
    const std::string cmd = "redis-cli -h 127.0.0.1 -p " + std::to_string(port_) + " " + args + " 2>&1";
    std::FILE* p = popen(cmd.c_str(), "r");
    if (p == nullptr) return out;
    char buf[4096];
    for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
    pclose(p);
    while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
    return out;
  }

 private:
  RedisServer() = default;

  bool Launch(std::string* error) {
    const std::string port = std::to_string(port_);
    const pid_t pid = fork();
    if (pid < 0) {
      *error = "fork failed";
      return false;
    }
    if (pid == 0) {
      const int devnull = ::open("/dev/null", O_WRONLY);
      if (devnull >= 0) {
        dup2(devnull, STDOUT_FILENO);
        dup2(devnull, STDERR_FILENO);
      }
      std::vector<std::string> args = {"redis-server", "--port", port, "--bind", "127.0.0.1", "--save", "",
                                        "--appendonly", "no", "--daemonize", "no", "--protected-mode", "yes"};
      args.insert(args.end(), more_.begin(), more_.end());
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execvp("redis-server", argv.data());
      _exit(127);
    }
    pid_ = pid;
    for (int k = 0; k < 200; ++k) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        *error = WIFEXITED(status) && WEXITSTATUS(status) == 127
                     ? "redis-server is not installed (Debian redis-server; ./vistream.sh installs it)"
                     : "redis-server exited at start on port " + port;
        return false;
      }
      const std::string ping = Cli("PING");
      if (ping == "PONG" || ping.starts_with("NOAUTH")) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    *error = "redis-server did not answer PING on port " + port + " within 10 s";
    Stop();
    return false;
  }

  int port_ = 0;
  pid_t pid_ = -1;
  std::vector<std::string> more_;
};

// The metrics port of a vistream-server ready line ("...; metrics on http://HOST:PORT/metrics").
inline int MetricsPortOf(const std::string& ready_line) {
  const size_t at = ready_line.find("metrics on http://");
  if (at == std::string::npos) return 0;
  const size_t colon = ready_line.find(':', at + 18);
  return colon == std::string::npos ? 0 : std::atoi(ready_line.c_str() + colon + 1);
}

struct BalancerOptions {
  size_t replicas = 2;
  // Each replica's options besides --listen and --metrics-listen (which the helper sets), e.g.
  // {"--scene", "default", "--threads", "1", "--drain", "3"}.
  std::vector<std::string> replica_args;
  std::string server_bin;       // the vistream-server executable
  std::string config_template;  // the HAProxy configuration to adapt: deploy/haproxy.cfg
  std::string haproxy = "/usr/sbin/haproxy";
  std::string dir;              // a folder for the configuration, the socket and the logs
  // Each replica also serves the browser client (--web-listen on a free port; the page must be
  // built), behind HAProxy's web frontend; off: that frontend has no server.
  bool web = false;
};

// The web port of a vistream-server ready line ("...; web page on http://HOST:PORT/"); 0 if none.
inline int WebPortOf(const std::string& ready_line) {
  const size_t at = ready_line.find("web page on ");
  if (at == std::string::npos) return 0;
  const size_t colon = ready_line.find(':', ready_line.find("//", at) + 2);
  return colon == std::string::npos ? 0 : std::atoi(ready_line.c_str() + colon + 1);
}

class Balancer {
 public:
  // Starts the replicas (each on free loopback ports), then HAProxy on a free port in front of
  // them, and waits until HAProxy reports every replica UP (its /healthz checked) and serves.
  // Returns null, saying why in `*error` (with HAProxy's output), otherwise.
  static std::unique_ptr<Balancer> Start(const BalancerOptions& options, std::string* error) {
    std::unique_ptr<Balancer> b(new Balancer());
    b->options_ = options;
    if (access(options.haproxy.c_str(), X_OK) != 0) {
      *error = "HAProxy is missing: " + options.haproxy +
               " is not an executable (Debian package haproxy; ./vistream.sh installs it)";
      return nullptr;
    }
    std::filesystem::create_directories(options.dir);
    b->replicas_.resize(options.replicas);
    for (size_t k = 0; k < options.replicas; ++k) {
      b->replicas_[k].name = "replica" + std::to_string(k + 1);
      if (!b->StartReplica(k, error)) return nullptr;
    }
    b->port_ = FreeLoopbackPort();
    b->address_ = "127.0.0.1:" + std::to_string(b->port_);
    b->web_address_ = "127.0.0.1:" + std::to_string(FreeLoopbackPort());
    b->socket_ = options.dir + "/haproxy.sock";
    b->log_ = options.dir + "/haproxy.log";
    std::string config;
    if (!b->Configure(&config, error)) return nullptr;
    const std::string config_path = options.dir + "/haproxy.cfg";
    std::ofstream(config_path) << config;
    // Checked as an operator would (haproxy -c) before it runs.
    const auto [rc, out] = Run(options.haproxy + " -c -f " + config_path);
    if (rc != 0) {
      *error = "haproxy -c -f " + config_path + " failed:\n" + out;
      return nullptr;
    }
    b->haproxy_pid_ = fork();
    if (b->haproxy_pid_ < 0) {
      *error = "fork failed";
      return nullptr;
    }
    if (b->haproxy_pid_ == 0) {
      if (const int log = open(b->log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644); log >= 0) {
        dup2(log, STDOUT_FILENO);
        dup2(log, STDERR_FILENO);
      }
      // -db: in the foreground, not a daemon; stopped with SIGTERM.
      execl(options.haproxy.c_str(), options.haproxy.c_str(), "-db", "-f", config_path.c_str(), nullptr);
      _exit(127);
    }
    // Every replica UP (two good checks of its /healthz), or HAProxy gone, or 30 s.
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    for (size_t k = 0; k < options.replicas;) {
      if (b->State(k) == "UP") {
        ++k;
        continue;
      }
      if (!b->HaproxyRuns()) {
        *error = "HAProxy exited:\n" + b->HaproxyLog();
        return nullptr;
      }
      if (std::chrono::steady_clock::now() > until) {
        *error = b->replicas_[k].name + " is not UP in HAProxy after 30 s (" + b->State(k) + ")\n" + b->StatsCsv() +
                 "\nHAProxy's log:\n" + b->HaproxyLog();
        return nullptr;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return b;
  }

  ~Balancer() {
    if (haproxy_pid_ > 0) {
      kill(haproxy_pid_, SIGTERM);
      int status = 0;
      for (int k = 0; k < 500 && waitpid(haproxy_pid_, &status, WNOHANG) == 0; ++k) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
      if (waitpid(haproxy_pid_, &status, WNOHANG) == 0) {
        kill(haproxy_pid_, SIGKILL);
        waitpid(haproxy_pid_, &status, 0);
      }
    }
    for (Replica& r : replicas_) r.server.reset();  // SIGKILL to what is left
  }

  // HAProxy's frontend, for clients.
  const std::string& address() const { return address_; }
  // HAProxy's web frontend (the browser client's page and WebSocket sessions).
  const std::string& web_address() const { return web_address_; }
  size_t size() const { return replicas_.size(); }
  // Replica k as HAProxy names it (replica1, replica2, ...).
  const std::string& name(size_t k) const { return replicas_[k].name; }
  // Its gRPC address and metrics port; both stay across a restart.
  const std::string& replica_address(size_t k) const { return replicas_[k].address; }
  int metrics_port(size_t k) const { return replicas_[k].metrics_port; }
  // Its process; null while stopped.
  RunningServer* replica(size_t k) { return replicas_[k].server.get(); }
  std::string replica_log(size_t k) const { return ReadAll(replicas_[k].log); }

  // Sends `sig` to replica k (0: none) and waits for it to exit: RunningServer::Stop's code.
  int StopReplica(size_t k, int sig) {
    if (replicas_[k].server == nullptr) return -1;
    const int code = replicas_[k].server->Stop(sig);
    replicas_[k].server.reset();
    return code;
  }
  // Starts replica k (again) on its ports. False, with what it printed in `*error`, if it
  // does not start.
  bool StartReplica(size_t k, std::string* error) {
    Replica& r = replicas_[k];
    std::vector<std::string> args = options_.replica_args;
    const bool again = r.metrics_port != 0;
    args.insert(args.end(), {"--listen", again ? r.address : "127.0.0.1:0", "--metrics-listen",
                             "127.0.0.1:" + std::to_string(r.metrics_port)});
    if (options_.web) args.insert(args.end(), {"--web-listen", "127.0.0.1:" + std::to_string(r.web_port)});
    r.log = options_.dir + "/" + r.name + (again ? "-" + std::to_string(++r.restarts) : "") + ".log";
    std::string why;
    r.server = RunningServer::Start(options_.server_bin, args, &why, r.log);
    if (r.server == nullptr) {
      *error = r.name + " did not start: " + why + "\n" + ReadAll(r.log);
      return false;
    }
    r.address = r.server->address();
    r.metrics_port = MetricsPortOf(r.server->ready_line());
    if (r.metrics_port == 0) {
      *error = r.name + ": no metrics port in its ready line: " + r.server->ready_line();
      return false;
    }
    if (options_.web && (r.web_port = WebPortOf(r.server->ready_line())) == 0) {
      *error = r.name + ": no web port in its ready line: " + r.server->ready_line();
      return false;
    }
    return true;
  }

  // HAProxy's `show stat` (CSV, its header first); empty when the socket does not answer.
  std::string StatsCsv() const { return AskHaproxy("show stat\n"); }
  // A column of replica k's row in `show stat` ("status": UP, DOWN, "UP 1/2" going down,
  // "DOWN 1/2" coming up, MAINT, NOLB; "scur": streams now; "stot": streams in all,
  // "check_status": L7OK, L7STS, L4CON, ...); empty when HAProxy does not answer.
  std::string Stat(size_t k, const std::string& column) const {
    std::istringstream csv(StatsCsv());
    std::string line;
    std::vector<std::string> header;
    while (std::getline(csv, line)) {
      std::vector<std::string> fields;
      std::stringstream ss(line);
      for (std::string f; std::getline(ss, f, ',');) fields.push_back(f);
      if (line.starts_with("# ")) {
        fields.front() = fields.front().substr(2);
        header = fields;
        continue;
      }
      if (fields.size() < 2 || fields[0] != "replicas" || fields[1] != replicas_[k].name) continue;
      for (size_t c = 0; c < header.size() && c < fields.size(); ++c) {
        if (header[c] == column) return fields[c];
      }
    }
    return "";
  }
  std::string State(size_t k) const { return Stat(k, "status"); }
  // Waits up to `timeout_s` for State(k) to be `state` (exactly: "UP" is not "UP 1/2").
  bool WaitForState(size_t k, const std::string& state, double timeout_s) const {
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (State(k) != state) {
      if (std::chrono::steady_clock::now() > until) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return true;
  }
  std::string HaproxyLog() const { return ReadAll(log_); }
  // Whether HAProxy still runs (reaps it if it exited).
  bool HaproxyRuns() {
    if (haproxy_pid_ <= 0) return false;
    int status = 0;
    if (waitpid(haproxy_pid_, &status, WNOHANG) != haproxy_pid_) return true;
    haproxy_pid_ = -1;
    return false;
  }

 private:
  struct Replica {
    std::string name, address, log;
    int metrics_port = 0;
    int web_port = 0;  // with BalancerOptions::web
    int restarts = 0;
    std::unique_ptr<RunningServer> server;
  };
  Balancer() = default;

  static std::string ReadAll(const std::string& path) {
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  static std::pair<int, std::string> Run(const std::string& command) {
    std::string out;
    std::FILE* p = popen((command + " 2>&1").c_str(), "r");
    if (p == nullptr) return {-1, out};
    char buf[1024];
    for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
    const int status = pclose(p);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
  }

  // deploy/haproxy.cfg, adapted. Each change must find what it changes: a configuration whose
  // shape moved on fails here, naming the line, rather than testing something else.
  bool Configure(std::string* config, std::string* error) const {
    std::ifstream in(options_.config_template);
    if (!in) {
      *error = "cannot read " + options_.config_template;
      return false;
    }
    const auto fail = [&](const std::string& what) {
      *error = options_.config_template + ": " + what + " (tools/replica_set.h adapts it: teach it the new shape)";
      return false;
    };
    // Health checks ten times faster than deployed (inter 2s fastinter 500ms downinter 2s):
    // DOWN within about 0.3 s of the first 503.
    const std::vector<std::pair<std::string, std::string>> timers = {
        {" inter 2s", " inter 200ms"}, {" fastinter 500ms", " fastinter 100ms"}, {" downinter 2s", " downinter 200ms"}};
    bool bind = false, socket = false, log = false, timed = false, servers = false, maxconn = false;
    bool web_bind = false, web_servers = false;
    std::string section;  // "frontend NAME" / "backend NAME" the line is in
    std::ostringstream out;
    for (std::string line; std::getline(in, line);) {
      const std::string t = line.substr(std::min(line.size(), line.find_first_not_of(' ')));
      if (line.starts_with("frontend ") || line.starts_with("backend ") || line.starts_with("defaults") ||
          line.starts_with("global")) {
        section = line;
      }
      if (t.starts_with("log /dev/log")) {
        out << "    log stderr format raw local0 info\n";
        log = true;
      } else if (t.starts_with("stats socket ")) {
        out << "    stats socket " << socket_ << " mode 600 level admin\n";
        socket = true;
      } else if (t.starts_with("maxconn ") && !maxconn) {
        out << "    maxconn 1000\n";  // within any test machine's file limit
        maxconn = true;
      } else if (t == "user haproxy" || t == "group haproxy" || t == "daemon") {
        continue;  // the test's own user, in the foreground
      } else if (t == "bind :8080") {
        out << "    bind " << web_address_ << "\n";  // the browser client's frontend
        web_bind = true;
      } else if (t.starts_with("server ") && section == "backend web_replicas") {
        if (web_servers) continue;
        web_servers = true;
        // server NAME ADDRESS check port METRICS_PORT: each replica's web listener, checked on
        // its metrics port; none without BalancerOptions::web.
        for (const Replica& r : replicas_) {
          if (r.web_port == 0) continue;
          out << "    server " << r.name << " 127.0.0.1:" << r.web_port << " check port " << r.metrics_port << "\n";
        }
      } else if (t.starts_with("bind :50051 ")) {
        out << "    bind " << address_ << t.substr(std::string("bind :50051").size()) << "\n";
        bind = true;
      } else if (t.starts_with("default-server ")) {
        for (const auto& [from, to] : timers) {
          const size_t at = line.find(from + " ");
          if (at == std::string::npos) return fail("no '" + from.substr(1) + "' on the default-server line");
          line.replace(at, from.size(), to);
        }
        out << line << "\n";
        timed = true;
      } else if (t.starts_with("server ")) {
        if (servers) continue;  // the first server line is the pattern of every replica's
        servers = true;
        // server NAME ADDRESS OPTIONS... port METRICS_PORT [OPTIONS...]
        std::istringstream words(t);
        std::string word, name, address, options;
        words >> word >> name >> address;
        bool port = false;
        for (std::string w; words >> w;) {
          if (w == "port") {
            words >> w;
            port = true;
            options += " port %METRICS%";
            continue;
          }
          options += " " + w;
        }
        if (!port) return fail("the first server line has no 'port' (the replica's metrics port)");
        for (const Replica& r : replicas_) {
          std::string o = options;
          o.replace(o.find("%METRICS%"), 9, std::to_string(r.metrics_port));
          out << "    server " << r.name << " " << r.address << o << "\n";
        }
      } else {
        out << line << "\n";
      }
    }
    if (!maxconn) return fail("no global 'maxconn' line");
    if (!log) return fail("no 'log /dev/log' line");
    if (!socket) return fail("no 'stats socket' line");
    if (!bind) return fail("no 'bind :50051' line");
    if (!web_bind) return fail("no 'bind :8080' line (the browser client's frontend)");
    if (!web_servers) return fail("no 'server' line in 'backend web_replicas'");
    if (!timed) return fail("no 'default-server' line");
    if (!servers) return fail("no 'server' line");
    *config = out.str();
    return true;
  }

  // One command on HAProxy's stats socket; its whole answer.
  std::string AskHaproxy(const std::string& command) const {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    if (fd < 0) return "";
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::snprintf(a.sun_path, sizeof(a.sun_path), "%s", socket_.c_str());
    timeval timeout{5, 0};
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
    std::string answer;
    if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
        write(fd, command.data(), command.size()) == static_cast<ssize_t>(command.size())) {
      char buf[4096];
      for (ssize_t n; (n = read(fd, buf, sizeof(buf))) > 0;) answer.append(buf, static_cast<size_t>(n));
    }
    close(fd);
    return answer;
  }

  BalancerOptions options_;
  std::vector<Replica> replicas_;
  int port_ = 0;
  std::string address_, web_address_, socket_, log_;
  pid_t haproxy_pid_ = -1;
};

}  // namespace vistream::tools
