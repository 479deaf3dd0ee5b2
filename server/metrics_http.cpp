// Compiled with cpp-httplib's pkg-config flags (server/CMakeLists.txt): Debian's libcpp-httplib
// is built with its OpenSSL, zlib and Brotli support on, which changes the layout of the types
// it shares with us, so this file must see the same definitions.
#include "server/metrics_http.h"

#include <httplib.h>
#include <netdb.h>
#include <sys/socket.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace vistream::server {
namespace {

// Threads serving connections: a scraper and a few health probes at once.
constexpr size_t kThreads = 4;

struct ListenAddress {
  std::string host;   // as getaddrinfo takes it (an IPv6 address without brackets)
  std::string shown;  // as written (with brackets)
  int port = 0;
};

// HOST:PORT, or [IPV6]:PORT, with a port from 0 to 65535.
absl::StatusOr<ListenAddress> ParseListen(const std::string& listen) {
  const absl::Status malformed = absl::InvalidArgumentError(absl::StrCat(
      "metrics listen address '", listen,
      "': expected HOST:PORT with a port from 0 to 65535 (0: any free port), e.g. 127.0.0.1:9464"));
  ListenAddress a;
  std::string port;
  if (listen.starts_with('[')) {
    const size_t close = listen.find(']');
    if (close == std::string::npos || close + 1 >= listen.size() || listen[close + 1] != ':')
      return malformed;
    a.host = listen.substr(1, close - 1);
    a.shown = listen.substr(0, close + 1);
    port = listen.substr(close + 2);
  } else {
    const size_t colon = listen.rfind(':');
    if (colon == std::string::npos) return malformed;
    a.host = listen.substr(0, colon);
    a.shown = a.host;
    port = listen.substr(colon + 1);
    if (a.host.find(':') != std::string::npos) return malformed;  // IPv6 needs brackets
  }
  if (a.host.empty() || port.empty() || port.size() > 5) return malformed;
  for (char c : port) {
    if (c < '0' || c > '9') return malformed;
    a.port = a.port * 10 + (c - '0');
  }
  if (a.port > 65535) return malformed;
  return a;
}

// Why binding `a` failed, given bind's errno.
std::string BindFailure(const ListenAddress& a, int error) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* result = nullptr;
  if (const int gai = getaddrinfo(a.host.c_str(), nullptr, &hints, &result); gai != 0) {
    return absl::StrCat(a.shown, " is not a host name or address (", gai_strerror(gai), ")");
  }
  freeaddrinfo(result);
  switch (error) {
    case EADDRINUSE:
      return absl::StrCat("the port ", a.port, " is in use");
    case EADDRNOTAVAIL:
      return absl::StrCat(a.shown, " is not an address of this machine");
    case EACCES:
      return absl::StrCat("permission denied (a port below 1024 needs privileges)");
    case 0:
      return "the socket could not be bound";
    default:
      return std::strerror(error);
  }
}

}  // namespace

absl::StatusOr<std::unique_ptr<MetricsHttpServer>> MetricsHttpServer::Start(
    const std::string& listen, MetricsRegistry* registry, std::function<bool()> healthy) {
  absl::StatusOr<ListenAddress> a = ParseListen(listen);
  if (!a.ok()) return a.status();

  std::unique_ptr<MetricsHttpServer> s(new MetricsHttpServer());
  s->server_ = std::make_unique<httplib::Server>();
  httplib::Server& http = *s->server_;
  http.new_task_queue = [] { return new httplib::ThreadPool(kThreads); };
  // SO_REUSEADDR only: httplib's default adds SO_REUSEPORT, which would let a second server
  // share a port already in use instead of failing.
  http.set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  // An idle kept-alive connection holds Stop() this long (Prometheus scrapes far less often).
  http.set_keep_alive_timeout(1);

  http.Get("/metrics", [registry](const httplib::Request&, httplib::Response& res) {
    res.set_content(registry->Render(), "text/plain; version=0.0.4; charset=utf-8");
  });
  http.Get("/healthz",
           [healthy = std::move(healthy)](const httplib::Request&, httplib::Response& res) {
             const bool serving = !healthy || healthy();
             res.status = serving ? 200 : 503;
             res.set_content(serving ? "serving\n" : "draining\n", "text/plain; charset=utf-8");
           });
  // httplib calls this for every status >= 400, our 503 too: only fill in the 404s.
  http.set_error_handler(
      httplib::Server::HandlerWithResponse([](const httplib::Request&, httplib::Response& res) {
        if (res.status != 404) return httplib::Server::HandlerResponse::Unhandled;
        res.set_content("not found: this server answers /metrics and /healthz\n",
                        "text/plain; charset=utf-8");
        return httplib::Server::HandlerResponse::Handled;
      }));

  errno = 0;
  const int port = a->port == 0 ? http.bind_to_any_port(a->host)
                                : (http.bind_to_port(a->host, a->port) ? a->port : -1);
  if (port <= 0) {
    const int error = errno;
    return absl::UnavailableError(
        absl::StrCat("cannot listen for metrics on ", listen, ": ", BindFailure(*a, error)));
  }
  s->port_ = port;
  s->address_ = absl::StrCat(a->shown, ":", port);

  // httplib's stop() does nothing until listen_after_bind() is running, so wait for that.
  auto returned = std::make_shared<std::atomic<bool>>(false);
  s->thread_ = std::thread([&http, returned] {
    http.listen_after_bind();
    returned->store(true);
  });
  while (!http.is_running() && !returned->load())
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (!http.is_running()) {
    s->thread_.join();
    return absl::UnavailableError(absl::StrCat("cannot listen for metrics on ", s->address_,
                                               ": the server stopped as it started"));
  }
  return s;
}

MetricsHttpServer::~MetricsHttpServer() { Stop(); }

void MetricsHttpServer::Stop() {
  std::lock_guard<std::mutex> lock(stop_mu_);
  if (server_ != nullptr) server_->stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace vistream::server
