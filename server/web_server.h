#pragma once
// The web edge of vistream-server (issue 47): an HTTP listener of its own ([web] listen,
// --web-listen; off by default) that serves the browser client's page and its assets from a
// folder, and a WebSocket endpoint, /session, that carries a walkthrough Session: one binary
// frame per vistream.v1.ClientMessage from the browser, one per ServerMessage to it (RFC 6455;
// proto/walkthrough.proto). gRPC-Web cannot carry the bidirectional Session (no client
// streaming), hence the WebSocket.
//
// A WebSocket session is a session like any other: WalkthroughService::Admit admits it under the
// same limits (draining, max sessions, per-address and per-tenant quotas), the same Session
// (server/session.h) serves it, a drain or the Hello watchdog ends it through its SessionLink,
// metrics count it under transport="websocket". What differs:
//   - the token (a browser cannot set an Authorization header on a WebSocket) travels in the
//     first message, Hello.token, and is checked before any work; never in the URL, never logged;
//   - the session's end is sent as a last ServerMessage, SessionEnd (the gRPC status's code and
//     message), then the close frame (RFC 6455 section 7.4: 1000 for OK, 1001 when the server
//     goes away, 1008 for anything else; the reason: the message's first 123 bytes);
//   - the first message must come within the Hello timeout and must be a Hello;
//   - a text frame, a frame that is no ClientMessage, a frame over the size limit (1009), a
//     client that leaves a message untaken for the write timeout, or no answer to the server's
//     pings for the idle timeout ends that connection only.
// With [tls] cert and key the listener speaks only TLS: HTTPS and WSS with the same certificate
// (and, with tls.client_ca, the same demand for a client certificate).
//
// Boost.Beast (HTTP and WebSocket) over Boost.Asio; one strand per connection, `threads` threads.

#include <cstddef>
#include <memory>
#include <string>

#include <absl/status/statusor.h>

#include "server/event_log.h"
#include "server/service.h"

namespace vistream::server {

struct WebOptions {
  std::string listen;          // HOST:PORT; port 0 picks a free one
  std::string root;            // the page's folder: index.html and the files it loads
  std::string tls_cert;        // PEM certificate chain ([tls] cert); with tls_key: HTTPS and WSS
  std::string tls_key;         // PEM private key ([tls] key)
  std::string tls_client_ca;   // PEM CA bundle ([tls] client_ca): clients must present a certificate it signed
  size_t max_message_bytes = size_t{1} << 20;  // a larger client frame ends its connection (close 1009)
  double hello_timeout_s = 30.0;   // no Hello by then: DEADLINE_EXCEEDED; 0: never
  double write_timeout_s = 30.0;   // a message the client leaves untaken this long: UNAVAILABLE
  double idle_timeout_s = 30.0;    // nothing from the client (its pongs included) this long: the connection ends
  size_t max_connections = 1024;   // HTTP and WebSocket connections at once; more are closed on accept
  // SO_SNDBUF of a WebSocket session's socket: what may wait in the kernel for the client; 0:
  // the kernel's own sizing.
  int send_buffer_bytes = 0;
  int threads = 2;
};

// The folder the page is served from when none is configured: $VISTREAM_WEB, else the
// installed share/vistream/web beside bin/, else the build's web/ folder.
std::string DefaultWebRoot();

// Whether `root` holds the page (index.html). Errors: INVALID_ARGUMENT "web.root 'ROOT' holds no
// index.html: ..." saying how the page is built or installed.
absl::Status CheckWebRoot(const std::string& root);

class WebServer {
 public:
  // Binds `options.listen` and serves until Stop. `service` (not owned) admits and serves the
  // sessions and must outlive the server; `log` may be null.
  // Errors: INVALID_ARGUMENT naming what is wrong (listen not HOST:PORT, a root without
  // index.html (naming the folder and how to build the page), TLS files that cannot be used);
  // UNAVAILABLE when the address cannot be bound (naming it).
  static absl::StatusOr<std::unique_ptr<WebServer>> Start(WalkthroughService* service, const WebOptions& options,
                                                          EventLog* log);
  ~WebServer();

  // HOST:PORT as bound (the port picked when 0 was asked).
  const std::string& address() const;
  int port() const;
  // "http" or "https".
  const char* scheme() const;
  // Closes the listener and every connection (an open session ends as its client's connection
  // is lost: its SessionEnd is not sent; drain first, WalkthroughServer::Shutdown, to send it).
  // Idempotent.
  void Stop();

  struct Impl;

 private:
  WebServer() = default;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vistream::server
