#include "server/web_server.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>
#include <type_traits>
#include <vector>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <boost/asio.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>

#include "proto/walkthrough.pb.h"
#include "server/security.h"
#include "server/server_config.h"
#include "server/session_reactor.h"

namespace vistream::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace net = boost::asio;
namespace ssl = net::ssl;
using tcp = net::ip::tcp;
namespace fs = std::filesystem;
namespace v1 = vistream::v1;

std::string DefaultWebRoot() {
  if (const char* env = std::getenv("VISTREAM_WEB"); env != nullptr && *env != '\0') return env;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path installed = (exe.parent_path() / ".." / "share" / "vistream" / "web").lexically_normal();
    if (fs::is_regular_file(installed / "index.html", ec)) return installed.string();
  }
  return VISTREAM_BINARY_DIR "/web";
}

absl::Status CheckWebRoot(const std::string& root) {
  std::error_code ec;
  if (fs::is_regular_file(fs::path(root) / "index.html", ec)) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat("web.root '", root,
                   "' holds no index.html: the page is built by ./vistream.sh (npm and esbuild, into build/web) "
                   "or installed with the package (share/vistream/web)"));
}

namespace {

std::chrono::steady_clock::duration Seconds(double s) {
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(s));
}

// "ipv4:HOST:PORT" / "ipv6:[HOST]:PORT", as gRPC names peers (PeerHost reads it).
std::string PeerName(const tcp::endpoint& e) {
  const net::ip::address a = e.address();
  return a.is_v6() ? absl::StrCat("ipv6:[", a.to_string(), "]:", e.port())
                   : absl::StrCat("ipv4:", a.to_string(), ":", e.port());
}

const char* ContentType(const fs::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json" || ext == ".map") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  if (ext == ".wasm") return "application/wasm";
  if (ext == ".proto" || ext == ".txt") return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

// The file under `root` that the path of `target` names ("/" is index.html), or none: only
// segments of letters, digits, '.', '_' and '-' not starting with '.', at most 4 deep, so that
// nothing outside the folder (or hidden in it) is reachable.
std::optional<fs::path> FileFor(const fs::path& root, std::string_view target) {
  std::string_view path = target.substr(0, target.find_first_of("?#"));
  if (path.empty() || path.front() != '/') return std::nullopt;
  if (path == "/") return root / "index.html";
  fs::path out = root;
  int depth = 0;
  size_t at = 1;
  while (at <= path.size()) {
    const size_t slash = std::min(path.find('/', at), path.size());
    const std::string_view seg = path.substr(at, slash - at);
    if (seg.empty() || seg.front() == '.' || ++depth > 4) return std::nullopt;
    for (char c : seg) {
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-')) return std::nullopt;
    }
    out /= std::string(seg);
    at = slash + 1;
  }
  return out;
}

// RFC 6455 close codes for a session's end.
websocket::close_code CloseCodeFor(const grpc::Status& status) {
  if (status.ok()) return websocket::close_code::normal;
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE) return websocket::close_code::going_away;
  return websocket::close_code::policy_error;
}

}  // namespace

// What every connection shares. It outlives them: Stop closes every connection and waits for
// them to go before the io_context (and with it every handler) goes.
struct WebServer::Impl {
  WalkthroughService* service = nullptr;
  WebOptions options;
  EventLog* log = nullptr;
  fs::path root;
  std::optional<ssl::context> tls;
  std::unique_ptr<net::io_context> ioc = std::make_unique<net::io_context>();
  std::optional<tcp::acceptor> acceptor;
  std::vector<std::thread> threads;
  std::atomic<bool> stopped{false};
  std::string address;
  int port = 0;

  // Every live connection's closer (posts a close to its strand), by a number of its own.
  std::mutex mu;
  std::map<uint64_t, std::function<void()>> closers;
  uint64_t next_connection = 1;

  void Accept();
};

namespace {

using Shared = WebServer::Impl*;

// A connection's place in Impl::closers while it lives: `close` (posted to its strand by Stop)
// must close its socket, so that its pending work ends and it goes.
class Registration {
 public:
  Registration(Shared shared, std::function<void()> close) : shared_(shared) {
    std::lock_guard lock(shared_->mu);
    id_ = shared_->next_connection++;
    shared_->closers.emplace(id_, std::move(close));
  }
  ~Registration() {
    std::lock_guard lock(shared_->mu);
    shared_->closers.erase(id_);
  }
  Registration(const Registration&) = delete;
  Registration& operator=(const Registration&) = delete;
  WebServer::Impl* operator->() const { return shared_; }

 private:
  Shared shared_;
  uint64_t id_ = 0;
};

// A closer for a connection of type T held weakly: on its strand, T::CloseNow().
template <class T>
std::function<void()> CloserOf(const std::shared_ptr<T>& connection, net::any_io_executor strand) {
  return [weak = std::weak_ptr<T>(connection), strand] {
    net::post(strand, [weak] {
      if (std::shared_ptr<T> c = weak.lock(); c != nullptr) c->CloseNow();
    });
  };
}

// One WebSocket session (see the header): reads client frames, hands them to the Session, and
// writes what its NextMessage gives, one write in flight. Everything runs on the connection's
// strand; Pump and EndWith (from any thread, through the SessionLink) post to it.
template <class Stream>
class WsConnection : public SessionEndpoint, public std::enable_shared_from_this<WsConnection<Stream>> {
 public:
  WsConnection(Stream&& stream, Shared shared, std::string peer)
      : ws_(std::move(stream)),
        shared_(std::move(shared)),
        peer_(std::move(peer)),
        write_timer_(ws_.get_executor()),
        hello_timer_(ws_.get_executor()) {}

  ~WsConnection() override {
    // Gone without Finish (Stop gave up waiting and dropped the handlers): the session ends as
    // a lost connection.
    Report(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server stopped"));
  }

  void Run(http::request<http::string_body> request) {
    registration_.emplace(shared_, CloserOf(this->shared_from_this(), ws_.get_executor()));
    beast::get_lowest_layer(ws_).expires_never();  // the WebSocket's own timeouts from here on
    const WebOptions& o = shared_->options;
    websocket::stream_base::timeout t;
    t.handshake_timeout = std::chrono::seconds(30);
    t.idle_timeout = Seconds(o.idle_timeout_s);
    t.keep_alive_pings = true;
    ws_.set_option(t);
    ws_.set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, "vistream-server"); }));
    ws_.read_message_max(o.max_message_bytes);
    ws_.binary(true);
    if (o.send_buffer_bytes > 0) {
      beast::error_code ignored;
      beast::get_lowest_layer(ws_).socket().set_option(net::socket_base::send_buffer_size(o.send_buffer_bytes),
                                                         ignored);
    }
    ws_.async_accept(request, beast::bind_front_handler(&WsConnection::OnAccept, this->shared_from_this()));
  }

  void Pump() override {
    if (auto self = this->weak_from_this().lock(); self != nullptr) {
      net::post(ws_.get_executor(), [self] { self->DoPump(); });
    }
  }

  void EndWith(const grpc::Status& status) override {
    if (auto self = this->weak_from_this().lock(); self != nullptr) {
      net::post(ws_.get_executor(), [self, status] { self->RequestEnd(status); });
    }
  }

  // WebServer::Stop: the connection ends now (its session as a lost connection).
  void CloseNow() { Finish(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server stopped")); }

 private:
  void OnAccept(beast::error_code ec) {
    if (ec) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "WebSocket handshake failed: " + ec.message()));
      return;
    }
    if (const double t = shared_->options.hello_timeout_s; t > 0.0) {
      hello_timer_.expires_after(Seconds(t));
      hello_timer_.async_wait([self = this->shared_from_this(), t](beast::error_code wait) {
        if (wait || self->session_ != nullptr || self->end_.has_value() || self->finished_) return;
        const std::string message = absl::StrFormat("no Hello within %g s", t);
        self->shared_->service->Refused(self->peer_, "Session", "no_hello", message);
        self->RequestEnd(grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED, message));
      });
    }
    ReadNext();
  }

  void ReadNext() {
    ws_.async_read(in_, beast::bind_front_handler(&WsConnection::OnRead, this->shared_from_this()));
  }

  void OnRead(beast::error_code ec, size_t bytes) {
    if (ec) {
      if (ec == websocket::error::closed) {
        Finish(end_.value_or(grpc::Status::OK));
      } else if (ec == websocket::error::message_too_big) {
        // Beast has failed the connection with close code 1009 already.
        Finish(grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                            absl::StrCat("message ", reads_ + 1, " is larger than the server takes (",
                                         shared_->options.max_message_bytes, " bytes)")));
      } else {
        Finish(end_.value_or(grpc::Status(grpc::StatusCode::CANCELLED,
                                          "the client's connection was lost (" + ec.message() + ")")));
      }
      return;
    }
    ++reads_;
    if (!end_.has_value()) Handle(bytes);
    in_.consume(in_.size());
    if (!finished_) ReadNext();
  }

  void Handle(size_t bytes) {
    if (!ws_.got_binary()) {
      Bad(absl::StrCat("message ", reads_, " is a text frame: a session takes binary frames, one ClientMessage each"));
      return;
    }
    v1::ClientMessage message;
    const auto data = in_.cdata();
    if (!message.ParseFromArray(data.data(), static_cast<int>(data.size()))) {
      Bad(absl::StrCat("message ", reads_, " (", bytes, " bytes) is not a ClientMessage"));
      return;
    }
    if (session_ == nullptr) {
      Admit(std::move(message));
      return;
    }
    if (const absl::Status st = session_->OnMessage(message, SteadySeconds()); !st.ok()) {
      RequestEnd(ToGrpcStatus(st));
      return;
    }
    DoPump();
  }

  // A frame that is not a session's: before Hello a refusal, after it the session's end.
  void Bad(const std::string& message) {
    if (session_ == nullptr) shared_->service->Refused(peer_, "Session", "invalid", message);
    RequestEnd(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, message));
  }

  // The first message: a Hello, with the token when the server has tokens; then admission.
  void Admit(v1::ClientMessage message) {
    WalkthroughService& service = *shared_->service;
    if (!message.has_hello()) {
      Bad("the first message must be a Hello");
      return;
    }
    std::string tenant;
    if (const std::shared_ptr<TokenStore>& tokens = service.options().tokens; tokens != nullptr) {
      const std::string& token = message.hello().token();
      std::optional<std::string> t = tokens->TenantFor(token);
      if (!t.has_value()) {
        const std::string why = token.empty() ? "missing token: this server needs one in the first message (Hello.token)"
                                              : "unknown token";
        service.Refused(peer_, "Session", "unauthenticated", why);
        RequestEnd(grpc::Status(grpc::StatusCode::UNAUTHENTICATED, why));
        return;
      }
      tenant = *std::move(t);
    }
    message.mutable_hello()->clear_token();  // never kept, never logged
    absl::StatusOr<WalkthroughService::Admitted> admitted = service.Admit(peer_, tenant, "websocket");
    if (!admitted.ok()) {
      RequestEnd(ToGrpcStatus(admitted.status()));
      return;
    }
    hello_timer_.cancel();
    session_ = std::move(admitted->session);
    link_ = std::move(admitted->link);
    link_->Attach(this);
    if (const absl::Status st = session_->OnMessage(message, SteadySeconds()); !st.ok()) {
      RequestEnd(ToGrpcStatus(st));
      return;
    }
    DoPump();
  }

  void RequestEnd(const grpc::Status& status) {
    if (end_.has_value() || finished_) return;
    end_ = status;
    DoPump();
  }

  // Writes the session's next message; at the end its SessionEnd, then the close frame.
  void DoPump() {
    if (finished_ || writing_ || closing_) return;
    if (!end_.has_value() && session_ != nullptr) {
      if (const absl::Status f = session_->failure(); !f.ok()) end_ = ToGrpcStatus(f);
    }
    if (end_.has_value()) {
      if (!end_sent_) {
        end_sent_ = true;
        v1::ServerMessage last;
        last.mutable_end()->set_code(static_cast<int>(end_->error_code()));
        last.mutable_end()->set_message(end_->error_message());
        Write(last.SerializeAsString());
        return;
      }
      closing_ = true;
      // The session is over once its last message went out: report it now, not when the client
      // answers the close frame (a drain need not wait for that).
      Report(*end_);
      websocket::close_reason reason(CloseCodeFor(*end_));
      const std::string& m = end_->error_message();
      reason.reason = m.substr(0, 123);  // a close frame's reason: at most 123 bytes
      ws_.async_close(reason, [self = this->shared_from_this()](beast::error_code) {
        // The client answered with its close frame (or the idle timeout gave up on it).
        self->Finish(*self->end_);
      });
      return;
    }
    if (session_ == nullptr) return;
    std::optional<v1::ServerMessage> next = session_->NextMessage();
    if (!next.has_value()) return;
    Write(next->SerializeAsString());
  }

  void Write(std::string bytes) {
    out_ = std::move(bytes);
    writing_ = true;
    const double t = shared_->options.write_timeout_s;
    write_timer_.expires_after(Seconds(t));
    write_timer_.async_wait([self = this->shared_from_this(), t](beast::error_code ec) {
      if (ec || !self->writing_ || self->finished_) return;
      self->Finish(grpc::Status(grpc::StatusCode::UNAVAILABLE,
                                absl::StrFormat("the client took no message for %g s (it stopped reading)", t)));
    });
    ws_.async_write(net::buffer(out_), [self = this->shared_from_this()](beast::error_code ec, size_t) {
      self->writing_ = false;
      self->write_timer_.cancel();
      if (ec) {
        self->Finish(self->end_.value_or(
            grpc::Status(grpc::StatusCode::UNAVAILABLE, "the client stopped receiving (" + ec.message() + ")")));
        return;
      }
      self->DoPump();
    });
  }

  // Reports the session's end once (WalkthroughService::Remove): no more wakes, no more work.
  void Report(const grpc::Status& status) {
    if (reported_) return;
    reported_ = true;
    if (link_ != nullptr) link_->Detach();
    if (session_ != nullptr) {
      session_->End();
      shared_->service->Remove(session_->id(), status);
    }
  }

  // Ends the connection once, and the session with it.
  void Finish(const grpc::Status& status) {
    if (finished_) return;
    finished_ = true;
    beast::error_code ignored;
    write_timer_.cancel(ignored);
    hello_timer_.cancel(ignored);
    // Pending reads and writes end with operation_aborted; their handlers find finished_.
    beast::get_lowest_layer(ws_).socket().close(ignored);
    Report(status);
  }

  websocket::stream<Stream> ws_;
  const Shared shared_;
  std::optional<Registration> registration_;
  const std::string peer_;
  net::steady_timer write_timer_, hello_timer_;
  beast::flat_buffer in_;
  std::string out_;
  uint64_t reads_ = 0;
  std::shared_ptr<Session> session_;
  std::shared_ptr<SessionLink> link_;
  std::optional<grpc::Status> end_;  // the session is ending with this
  bool writing_ = false, end_sent_ = false, closing_ = false, reported_ = false, finished_ = false;
};

// One HTTP connection: the page's files, or the upgrade to a WebSocket session on /session.
template <class Stream>
class HttpConnection : public std::enable_shared_from_this<HttpConnection<Stream>> {
 public:
  HttpConnection(Stream&& stream, Shared shared, std::string peer)
      : stream_(std::move(stream)), shared_(shared), peer_(std::move(peer)) {}

  void Run() {
    registration_.emplace(shared_, CloserOf(this->shared_from_this(), stream_.get_executor()));
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
      Read();
    } else {
      beast::get_lowest_layer(stream_).expires_after(std::chrono::seconds(30));
      stream_.async_handshake(ssl::stream_base::server, [self = this->shared_from_this()](beast::error_code ec) {
        if (!ec) self->Read();
      });
    }
  }

 private:
  void Read() {
    parser_.emplace();
    parser_->header_limit(16 * 1024);
    parser_->body_limit(64 * 1024);
    beast::get_lowest_layer(stream_).expires_after(std::chrono::seconds(30));
    http::async_read(stream_, in_, *parser_, beast::bind_front_handler(&HttpConnection::OnRead, this->shared_from_this()));
  }

  void OnRead(beast::error_code ec, size_t) {
    if (ec) {
      if (ec == http::error::end_of_stream) Close();
      return;
    }
    http::request<http::string_body> request = parser_->release();
    const std::string_view target(request.target().data(), request.target().size());
    const std::string_view path = target.substr(0, target.find_first_of("?#"));
    if (websocket::is_upgrade(request)) {
      if (path == "/session") {
        std::make_shared<WsConnection<Stream>>(std::move(stream_), shared_, peer_)->Run(std::move(request));
        return;
      }
      Respond(request, http::status::not_found, "text/plain; charset=utf-8", "WebSocket sessions are on /session\n");
      return;
    }
    if (request.method() != http::verb::get && request.method() != http::verb::head) {
      Respond(request, http::status::method_not_allowed, "text/plain; charset=utf-8", "GET or HEAD only\n");
      return;
    }
    const std::optional<fs::path> file = FileFor(shared_->root, target);
    std::error_code fe;
    if (!file.has_value() || !fs::is_regular_file(*file, fe)) {
      Respond(request, http::status::not_found, "text/plain; charset=utf-8",
              absl::StrCat("not found: ", std::string(path), "\n"));
      return;
    }
    std::ifstream in(*file, std::ios::binary);
    std::ostringstream body;
    body << in.rdbuf();
    if (!in) {
      Respond(request, http::status::internal_server_error, "text/plain; charset=utf-8", "cannot read the file\n");
      return;
    }
    Respond(request, http::status::ok, ContentType(*file), body.str());
  }

  void Respond(const http::request<http::string_body>& request, http::status status, const char* type,
               std::string body) {
    auto res = std::make_shared<http::response<http::string_body>>(status, request.version());
    res->set(http::field::server, "vistream-server");
    res->set(http::field::content_type, type);
    res->set("X-Content-Type-Options", "nosniff");
    res->set(http::field::cache_control, "no-cache");
    res->keep_alive(request.keep_alive());
    const size_t length = body.size();
    if (request.method() != http::verb::head) res->body() = std::move(body);
    res->content_length(length);  // HEAD: the length GET would send, no body
    http::async_write(stream_, *res, [self = this->shared_from_this(), res](beast::error_code ec, size_t) {
      if (ec) return;
      if (!res->keep_alive()) {
        self->Close();
        return;
      }
      self->Read();
    });
  }

  void Close() {
    beast::error_code ignored;
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
      stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    } else {
      beast::get_lowest_layer(stream_).expires_after(std::chrono::seconds(5));
      stream_.async_shutdown([self = this->shared_from_this()](beast::error_code) {});
    }
  }

 public:
  // WebServer::Stop.
  void CloseNow() {
    beast::error_code ignored;
    beast::get_lowest_layer(stream_).socket().close(ignored);
  }

 private:
  Stream stream_;
  const Shared shared_;
  std::optional<Registration> registration_;
  const std::string peer_;
  beast::flat_buffer in_;
  std::optional<http::request_parser<http::string_body>> parser_;
};

}  // namespace

void WebServer::Impl::Accept() {
  acceptor->async_accept(net::make_strand(*ioc), [this](beast::error_code ec, tcp::socket socket) {
    if (ec) {
      if (!stopped && ec != net::error::operation_aborted) Accept();
      return;
    }
    beast::error_code pe;
    const tcp::endpoint remote = socket.remote_endpoint(pe);
    size_t open = 0;
    {
      std::lock_guard lock(mu);
      open = closers.size();
    }
    if (pe || open >= options.max_connections) {
      if (!pe && log != nullptr) {
        log->Write(EventLog::Level::kWarn, 0, "refused",
                   {{"call", "web"}, {"peer", PeerName(remote)}, {"reason", "too_many_connections"}});
      }
      socket.close(pe);
    } else if (tls.has_value()) {
      std::make_shared<HttpConnection<beast::ssl_stream<beast::tcp_stream>>>(
          beast::ssl_stream<beast::tcp_stream>(std::move(socket), *tls), this, PeerName(remote))
          ->Run();
    } else {
      std::make_shared<HttpConnection<beast::tcp_stream>>(beast::tcp_stream(std::move(socket)), this, PeerName(remote))
          ->Run();
    }
    if (!stopped) Accept();
  });
}

absl::StatusOr<std::unique_ptr<WebServer>> WebServer::Start(WalkthroughService* service, const WebOptions& options,
                                                            EventLog* log) {
  if (!IsHostPort(options.listen)) {
    return absl::InvalidArgumentError(absl::StrCat("web.listen '", options.listen,
                                                   "': expected HOST:PORT with a port from 0 to 65535, e.g. 127.0.0.1:8080"));
  }
  const size_t colon = options.listen.rfind(':');
  std::string host = options.listen.substr(0, colon);
  const std::string port = options.listen.substr(colon + 1);
  if (host.front() == '[') host = host.substr(1, host.size() - 2);  // [::1]
  if (absl::Status st = CheckWebRoot(options.root); !st.ok()) return st;
  if (options.threads < 1 || !(options.write_timeout_s > 0.0) || !(options.idle_timeout_s > 0.0)) {
    return absl::InvalidArgumentError("web: threads, the write timeout and the idle timeout must be positive");
  }
  auto impl = std::make_unique<Impl>();
  impl->service = service;
  impl->options = options;
  impl->log = log;
  impl->root = fs::path(options.root);
  if (options.tls_cert.empty() != options.tls_key.empty()) {
    return absl::InvalidArgumentError("web: TLS needs both tls.cert and tls.key");
  }
  if (!options.tls_cert.empty()) {
    beast::error_code ec;
    ssl::context ctx(ssl::context::tls_server);
    ctx.set_options(ssl::context::default_workarounds | ssl::context::no_sslv2 | ssl::context::no_sslv3 |
                    ssl::context::no_tlsv1 | ssl::context::no_tlsv1_1);
    ctx.use_certificate_chain_file(options.tls_cert, ec);
    if (ec) return absl::InvalidArgumentError(absl::StrCat("tls.cert '", options.tls_cert, "': ", ec.message()));
    ctx.use_private_key_file(options.tls_key, ssl::context::pem, ec);
    if (ec) return absl::InvalidArgumentError(absl::StrCat("tls.key '", options.tls_key, "': ", ec.message()));
    if (!options.tls_client_ca.empty()) {
      ctx.load_verify_file(options.tls_client_ca, ec);
      if (ec) {
        return absl::InvalidArgumentError(absl::StrCat("tls.client_ca '", options.tls_client_ca, "': ", ec.message()));
      }
      ctx.set_verify_mode(ssl::verify_peer | ssl::verify_fail_if_no_peer_cert);
    }
    impl->tls.emplace(std::move(ctx));
  }
  beast::error_code ec;
  tcp::resolver resolver(*impl->ioc);
  const auto endpoints = resolver.resolve(host, port, tcp::resolver::passive | tcp::resolver::numeric_service, ec);
  if (ec || endpoints.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("web.listen '", options.listen, "': '", host, "' is not an address of this machine (",
                     ec ? ec.message() : "no address", ")"));
  }
  const tcp::endpoint endpoint = endpoints.begin()->endpoint();
  impl->acceptor.emplace(*impl->ioc);
  impl->acceptor->open(endpoint.protocol(), ec);
  if (!ec) impl->acceptor->set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) impl->acceptor->bind(endpoint, ec);
  if (!ec) impl->acceptor->listen(net::socket_base::max_listen_connections, ec);
  if (ec) {
    return absl::UnavailableError(absl::StrCat("cannot listen on ", options.listen, " (web.listen): ", ec.message()));
  }
  impl->port = impl->acceptor->local_endpoint().port();
  impl->address = absl::StrCat(options.listen.substr(0, colon), ":", impl->port);
  impl->Accept();
  for (int i = 0; i < options.threads; ++i) impl->threads.emplace_back([ioc = impl->ioc.get()] { ioc->run(); });
  std::unique_ptr<WebServer> server(new WebServer());
  server->impl_ = std::move(impl);
  return server;
}

WebServer::~WebServer() { Stop(); }

const std::string& WebServer::address() const { return impl_->address; }
int WebServer::port() const { return impl_->port; }
const char* WebServer::scheme() const { return impl_->tls.has_value() ? "https" : "http"; }

void WebServer::Stop() {
  if (impl_ == nullptr || impl_->stopped.exchange(true)) return;
  Impl& impl = *impl_;
  net::post(*impl.ioc, [&impl] {
    beast::error_code ignored;
    impl.acceptor->close(ignored);
  });
  // Every connection closes on its strand; its pending work ends, it goes (an open session ends
  // as a lost connection, its link detached), and so nothing posts to the io_context any more.
  std::vector<std::function<void()>> closers;
  {
    std::lock_guard lock(impl.mu);
    for (const auto& [id, close] : impl.closers) closers.push_back(close);
  }
  for (const std::function<void()>& close : closers) close();
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  for (;;) {
    {
      std::lock_guard lock(impl.mu);
      if (impl.closers.empty()) break;
    }
    if (std::chrono::steady_clock::now() > until) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  impl.ioc->stop();
  for (std::thread& t : impl.threads) t.join();
  impl.threads.clear();
  impl.acceptor.reset();
  impl.ioc.reset();  // drops what is left of the handlers (and the connections they hold)
}

}  // namespace vistream::server
