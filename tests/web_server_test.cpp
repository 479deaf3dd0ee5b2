// The web edge (server/web_server.h): the page's files over HTTP, WebSocket sessions served like
// gRPC ones (the same Session, admission, tokens, drain), WSS with a certificate openssl makes,
// and WebSocket input that is no session's ending that connection only. Real sockets on
// 127.0.0.1, free ports; a Beast client.

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <optional>
#include <set>
#include <string>

#include <absl/strings/str_cat.h>
#include <boost/asio.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>
#include <gtest/gtest.h>

#include "client/client_model.h"
#include "proto/walkthrough.pb.h"
#include "server/security.h"
#include "server/web_server.h"
#include "tests/server_test_util.h"
#include "tests/temp_dir.h"
#include "tests/tls_test_util.h"

namespace vistream::server {
namespace {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace net = boost::asio;
namespace ssl = net::ssl;
using tcp = net::ip::tcp;
namespace v1 = vistream::v1;
using test::Centre;
using test::City1;

constexpr char kToken[] = "web-tenant-0123456789abcdef";

// A folder with the page's stand-in: index.html and one script.
const std::string& PageRoot() {
  static const std::string root = [] {
    const std::string dir = vistream::testing::ProcessTempDir() + "/web-root";
    std::filesystem::create_directories(dir + "/assets");
    std::ofstream(dir + "/index.html") << "<!doctype html><title>vistream</title>";
    std::ofstream(dir + "/assets/app.js") << "console.log('vistream');";
    std::ofstream(dir + "/.hidden") << "secret";
    return dir;
  }();
  return root;
}

struct Served {
  std::unique_ptr<WalkthroughServer> grpc;
  std::unique_ptr<WebServer> web;
};

Served Serve(ServerOptions options = {}, WebOptions web = {}) {
  Served s;
  static EventLog debug_log(stderr, false);
  options.listen = "127.0.0.1:0";
  s.grpc = std::move(*WalkthroughServer::Start(&City1(), options, std::getenv("WEB_DEBUG") ? &debug_log : nullptr));
  web.listen = "127.0.0.1:0";
  web.root = PageRoot();
  absl::StatusOr<std::unique_ptr<WebServer>> started = WebServer::Start(&s.grpc->service(), web, nullptr);
  EXPECT_TRUE(started.ok()) << started.status();
  if (started.ok()) s.web = std::move(*started);
  return s;
}

// One HTTP request and its response (status, body, Content-Type), or the status 0.
struct Reply {
  unsigned status = 0;
  std::string body, type, length;
};
Reply Fetch(int port, http::verb verb, const std::string& target) {
  net::io_context ioc;
  beast::tcp_stream stream(ioc);
  Reply r;
  beast::error_code ec;
  stream.expires_after(std::chrono::seconds(30));
  stream.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)), ec);
  if (ec) return r;
  http::request<http::empty_body> req(verb, target, 11);
  req.set(http::field::host, "127.0.0.1");
  http::write(stream, req, ec);
  if (ec) return r;
  beast::flat_buffer buffer;
  http::response_parser<http::string_body> parser;
  if (verb == http::verb::head) parser.skip(true);
  http::read(stream, buffer, parser, ec);
  if (ec) return r;
  r.status = parser.get().result_int();
  r.body = parser.get().body();
  r.type = std::string(parser.get()[http::field::content_type]);
  r.length = std::string(parser.get()[http::field::content_length]);
  return r;
}

// A WebSocket client of /session with a deadline on every wait (plain, or TLS trusting `ca`).
class WsClient {
 public:
  explicit WsClient(int port, const std::string& ca = "", int receive_buffer = 0) {
    if (!ca.empty()) {
      tls_ctx_.emplace(ssl::context::tls_client);
      tls_ctx_->load_verify_file(ca);
      tls_ctx_->set_verify_mode(ssl::verify_peer);
      tls_.emplace(ioc_, *tls_ctx_);
    } else {
      plain_.emplace(ioc_);
    }
    With([&](auto& ws) {
      auto& socket = beast::get_lowest_layer(ws).socket();
      beast::error_code ec;
      socket.open(tcp::v4(), ec);
      if (receive_buffer > 0) socket.set_option(net::socket_base::receive_buffer_size(receive_buffer), ec);
      socket.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)), ec);
      if (ec) return;
      if constexpr (!std::is_same_v<std::decay_t<decltype(ws)>, websocket::stream<beast::tcp_stream>>) {
        ws.next_layer().handshake(ssl::stream_base::client, ec);
        if (ec) return;
      }
      ws.handshake("127.0.0.1", "/session", ec);
      if (ec) return;
      ws.binary(true);
      ws.read_message_max(size_t{64} << 20);
      connected_ = true;
    });
  }

  bool connected() const { return connected_; }

  bool Send(const v1::ClientMessage& m) { return SendBytes(m.SerializeAsString(), true); }
  bool SendBytes(const std::string& bytes, bool binary) {
    bool ok = false;
    With([&](auto& ws) {
      beast::error_code ec;
      ws.binary(binary);
      ws.write(net::buffer(bytes), ec);
      ws.binary(true);
      ok = !ec;
    });
    return ok;
  }

  // The next message, or none once the connection is closed (close_code() says how) or after
  // `timeout_s` without one.
  std::optional<v1::ServerMessage> Read(double timeout_s = test::kWait) {
    std::optional<v1::ServerMessage> out;
    With([&](auto& ws) {
      bool done = false;
      beast::error_code error;
      buffer_.consume(buffer_.size());
      ws.async_read(buffer_, [&](beast::error_code ec, size_t) {
        done = true;
        error = ec;
      });
      ioc_.restart();
      ioc_.run_for(std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::duration<double>(timeout_s)));
      if (!done) {
        beast::error_code ignored;
        beast::get_lowest_layer(ws).socket().cancel(ignored);
        ioc_.restart();
        ioc_.run_for(std::chrono::seconds(5));
        timed_out_ = true;
        return;
      }
      if (error) {
        closed_ = true;
        close_code_ = ws.reason().code;
        return;
      }
      v1::ServerMessage m;
      const auto data = buffer_.cdata();
      if (m.ParseFromArray(data.data(), static_cast<int>(data.size()))) out = std::move(m);
    });
    return out;
  }

  // Reads until a message of `body` comes (returned), the connection closes or the time runs out.
  std::optional<v1::ServerMessage> ReadUntil(v1::ServerMessage::BodyCase body, double timeout_s = test::kWait) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (std::chrono::steady_clock::now() < until) {
      std::optional<v1::ServerMessage> m = Read(std::chrono::duration<double>(until - std::chrono::steady_clock::now()).count());
      if (!m.has_value()) return std::nullopt;
      if (m->body_case() == body) return m;
    }
    return std::nullopt;
  }

  // The session's end: its SessionEnd, then the close frame.
  std::optional<v1::SessionEnd> End(double timeout_s = test::kWait) {
    std::optional<v1::ServerMessage> m = ReadUntil(v1::ServerMessage::kEnd, timeout_s);
    if (!m.has_value()) return std::nullopt;
    Read(timeout_s);  // the close frame
    return m->end();
  }

  bool closed() const { return closed_; }
  bool timed_out() const { return timed_out_; }
  uint16_t close_code() const { return close_code_; }

 private:
  template <class F>
  void With(F f) {
    if (plain_.has_value()) {
      f(*plain_);
    } else {
      f(*tls_);
    }
  }

  net::io_context ioc_;
  std::optional<ssl::context> tls_ctx_;
  std::optional<websocket::stream<beast::tcp_stream>> plain_;
  std::optional<websocket::stream<beast::ssl_stream<beast::tcp_stream>>> tls_;
  beast::flat_buffer buffer_;
  bool connected_ = false, closed_ = false, timed_out_ = false;
  uint16_t close_code_ = 0;
};

v1::ClientMessage Hello(const std::string& token = "") {
  client::HelloSettings settings;
  settings.scene = "city1";
  v1::ClientMessage m = client::HelloMessage(settings);
  if (!token.empty()) m.mutable_hello()->set_token(token);
  return m;
}

// Reads until the PVS lists of `cells` cells have come and every object on them: what a
// session sends for a standing client, after which it has nothing more to write.
bool ReadAllOf(WsClient& c, size_t cells) {
  std::set<uint32_t> wanted, held;
  size_t lists = 0;
  while (lists < cells || !std::includes(held.begin(), held.end(), wanted.begin(), wanted.end())) {
    std::optional<v1::ServerMessage> m = c.Read();
    if (!m.has_value()) return false;
    if (m->has_pvs()) {
      ++lists;
      wanted.insert(m->pvs().object_ids().begin(), m->pvs().object_ids().end());
    }
    if (m->has_geometry()) held.insert(m->geometry().object_id());
  }
  return true;
}

// Opens a session at cell (i, j) with unlimited credit; true once its cell's PVS has come.
bool Walk(WsClient& c, int i, int j, const std::string& token = "") {
  if (!c.connected() || !c.Send(Hello(token)) || !c.Send(client::CreditMessage(uint64_t{1} << 40))) return false;
  if (!c.Send(client::PoseMessage(client::MakePose(Centre(i, j), glm::dvec3(0.0), 0.0, 0.0, 0.0)))) return false;
  std::optional<v1::ServerMessage> pvs = c.ReadUntil(v1::ServerMessage::kPvs);
  return pvs.has_value() && pvs->pvs().cell_id() == test::Cell(i, j);
}

TEST(WebServer, ServesThePageItsAssetsAndNothingOutsideTheFolder) {
  Served s = Serve();
  ASSERT_NE(s.web, nullptr);
  EXPECT_STREQ(s.web->scheme(), "http");
  const Reply index = Fetch(s.web->port(), http::verb::get, "/?scene=city1&walk=street%201&speed=30");
  EXPECT_EQ(index.status, 200u);
  EXPECT_EQ(index.body, "<!doctype html><title>vistream</title>");
  EXPECT_EQ(index.type, "text/html; charset=utf-8");
  const Reply script = Fetch(s.web->port(), http::verb::get, "/assets/app.js");
  EXPECT_EQ(script.status, 200u);
  EXPECT_EQ(script.type, "text/javascript; charset=utf-8");
  const Reply head = Fetch(s.web->port(), http::verb::head, "/assets/app.js");
  EXPECT_EQ(head.status, 200u);
  EXPECT_EQ(head.length, std::to_string(script.body.size()));
  for (const char* bad : {"/../index.html", "/assets/../../etc/passwd", "/.hidden", "/missing.js", "/assets",
                          "/a%2F..%2Findex.html", "relative"}) {
    EXPECT_EQ(Fetch(s.web->port(), http::verb::get, bad).status, 404u) << bad;
  }
  EXPECT_EQ(Fetch(s.web->port(), http::verb::post, "/").status, 405u);
  // A root without the page is refused, naming the folder and how the page is built.
  WebOptions o;
  o.listen = "127.0.0.1:0";
  o.root = vistream::testing::ProcessTempDir();
  const absl::Status st = WebServer::Start(&s.grpc->service(), o, nullptr).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find(o.root), std::string::npos) << st;
  EXPECT_NE(st.message().find("vistream.sh"), std::string::npos) << st;
}

TEST(WebServer, AWebSocketSessionIsServedAsAGrpcOneIs) {
  Served s = Serve();
  WsClient c(s.web->port());
  ASSERT_TRUE(c.connected());
  ASSERT_TRUE(c.Send(Hello()));
  std::optional<v1::ServerMessage> info = c.Read();
  ASSERT_TRUE(info.has_value());
  ASSERT_TRUE(info->has_scene_info()) << info->DebugString();
  EXPECT_EQ(info->scene_info().name(), "city1");
  ASSERT_TRUE(c.Send(client::CreditMessage(uint64_t{1} << 40)));
  ASSERT_TRUE(c.Send(client::PoseMessage(client::MakePose(Centre(3, 4), glm::dvec3(0.0), 0.0, 0.0, 0.0))));
  // The cell's PVS as the gRPC sessions get it, then every object on it.
  std::optional<v1::ServerMessage> pvs = c.ReadUntil(v1::ServerMessage::kPvs);
  ASSERT_TRUE(pvs.has_value());
  ASSERT_EQ(pvs->pvs().cell_id(), test::Cell(3, 4));
  const std::vector<uint32_t> expected = test::ExpectedPvs(test::Cell(3, 4));
  EXPECT_EQ(std::vector<uint32_t>(pvs->pvs().object_ids().begin(), pvs->pvs().object_ids().end()), expected);
  std::set<uint32_t> missing(expected.begin(), expected.end());
  while (!missing.empty()) {
    std::optional<v1::ServerMessage> m = c.Read();
    ASSERT_TRUE(m.has_value()) << missing.size() << " objects never came";
    if (m->has_geometry()) missing.erase(m->geometry().object_id());
  }
  // Counted as a websocket session while it lasts.
  const v1::ServerStats stats = s.grpc->service().Stats();
  ASSERT_EQ(stats.sessions_size(), 1);
  EXPECT_EQ(stats.sessions(0).transport(), "websocket");
  EXPECT_EQ(stats.sessions(0).scene(), "city1");
  EXPECT_NE(stats.sessions(0).peer().find("ipv4:127.0.0.1:"), std::string::npos);
}

// Each kind of input that is no session's ends its own connection, with a SessionEnd naming what
// was wrong (or close code 1009 for a frame over the limit); a session beside them goes on and
// a new one is served.
TEST(WebServer, InputThatIsNoSessionEndsThatConnectionOnly) {
  WebOptions web;
  web.max_message_bytes = 64 * 1024;
  web.write_timeout_s = 2.0;
  web.send_buffer_bytes = 64 * 1024;  // so that a client that never reads fills the buffers soon
  web.idle_timeout_s = 120.0;         // the good client below answers pings only as it reads
  Served s = Serve({}, web);
  WsClient good(s.web->port());
  ASSERT_TRUE(Walk(good, 3, 4));
  ASSERT_TRUE(ReadAllOf(good, 8));  // the other 8 of the 9 cells: nothing left to write to it
  const uint64_t good_id = s.grpc->service().Stats().sessions(0).session_id();

  {
    WsClient c(s.web->port());
    ASSERT_TRUE(c.SendBytes(std::string("\xff\xff\xff\xff garbage", 12), true));
    std::optional<v1::SessionEnd> end = c.End();
    ASSERT_TRUE(end.has_value());
    EXPECT_EQ(end->code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
    EXPECT_EQ(end->message(), "message 1 (12 bytes) is not a ClientMessage");
    EXPECT_EQ(c.close_code(), static_cast<uint16_t>(websocket::close_code::policy_error));
  }
  {
    WsClient c(s.web->port());
    ASSERT_TRUE(c.SendBytes("{\"hello\": {}}", false));
    std::optional<v1::SessionEnd> end = c.End();
    ASSERT_TRUE(end.has_value());
    EXPECT_EQ(end->code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
    EXPECT_NE(end->message().find("message 1 is a text frame"), std::string::npos) << end->message();
  }
  {
    WsClient c(s.web->port());
    ASSERT_TRUE(c.Send(client::PoseMessage(client::MakePose(Centre(1, 1), glm::dvec3(0.0), 0.0, 0.0, 0.0))));
    std::optional<v1::SessionEnd> end = c.End();
    ASSERT_TRUE(end.has_value());
    EXPECT_EQ(end->message(), "the first message must be a Hello");
  }
  {
    WsClient c(s.web->port());
    ASSERT_TRUE(c.Send(Hello()));
    c.SendBytes(std::string(100 * 1024, 'x'), true);
    while (c.Read().has_value()) {
    }
    EXPECT_TRUE(c.closed());
    EXPECT_EQ(c.close_code(), static_cast<uint16_t>(websocket::close_code::too_big));
  }
  const auto others = [&] {
    size_t n = 0;
    const v1::ServerStats stats = s.grpc->service().Stats();
    for (const v1::SessionStats& st : stats.sessions()) n += st.session_id() != good_id;
    return n;
  };
  ASSERT_EQ(others(), 0u);
  {
    // A client that never reads: a 4 KiB receive buffer, every cell of the city asked for,
    // nothing read. The server's writes stall, and after the write timeout its session ends.
    WsClient c(s.web->port(), "", 4096);
    ASSERT_TRUE(c.connected());
    ASSERT_TRUE(c.Send(Hello()));
    ASSERT_TRUE(c.Send(client::CreditMessage(uint64_t{1} << 40)));
    const auto start = std::chrono::steady_clock::now();
    bool ended = false;
    for (int k = 0; k < 600 && !ended; ++k) {
      const int i = k % 28, j = (k / 28) % 20;
      c.Send(client::PoseMessage(client::MakePose(Centre(i, j), glm::dvec3(0.0), 0.0, 0.0, 0.1 * k)));
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      ended = k > 0 && others() == 0;
    }
    EXPECT_TRUE(ended) << "the session of a client that never reads did not end";
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 60.0);
  }
  // The good session goes on: a crossing brings the new cell's PVS.
  ASSERT_EQ(s.grpc->service().Stats().sessions_size(), 1);
  ASSERT_TRUE(good.Send(client::PoseMessage(client::MakePose(Centre(4, 4), glm::dvec3(0.0), 0.0, 0.0, 1.0))));
  std::optional<v1::ServerMessage> pvs = good.ReadUntil(v1::ServerMessage::kPvs);
  ASSERT_TRUE(pvs.has_value());
  // And a new session is served.
  WsClient again(s.web->port());
  EXPECT_TRUE(Walk(again, 5, 5));
}

TEST(WebServer, TheTokenTravelsInTheFirstMessageAndIsNeverLogged) {
  const std::string path = vistream::testing::ProcessTempDir() + "/web-tokens";
  std::ofstream(path) << "browser " << kToken << "\n";
  absl::StatusOr<std::shared_ptr<TokenStore>> tokens = TokenStore::Load(path);
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  ServerOptions options;
  options.tokens = *tokens;
  const std::string log_path = vistream::testing::ProcessTempDir() + "/web-log";
  std::FILE* log_file = std::fopen(log_path.c_str(), "w");
  ASSERT_NE(log_file, nullptr);
  EventLog log(log_file, false);
  options.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> grpc = WalkthroughServer::Start(&City1(), options, &log);
  ASSERT_TRUE(grpc.ok()) << grpc.status();
  WebOptions web;
  web.listen = "127.0.0.1:0";
  web.root = PageRoot();
  absl::StatusOr<std::unique_ptr<WebServer>> started = WebServer::Start(&(*grpc)->service(), web, &log);
  ASSERT_TRUE(started.ok()) << started.status();
  const int port = (*started)->port();
  for (const auto& [token, message] : std::vector<std::pair<std::string, std::string>>{
           {"", "missing token: this server needs one in the first message (Hello.token)"},
           {"not-the-token-0123456789", "unknown token"}}) {
    WsClient c(port);
    ASSERT_TRUE(c.Send(Hello(token)));
    std::optional<v1::SessionEnd> end = c.End();
    ASSERT_TRUE(end.has_value());
    EXPECT_EQ(end->code(), static_cast<int>(grpc::StatusCode::UNAUTHENTICATED));
    EXPECT_EQ(end->message(), message);
    EXPECT_EQ(c.close_code(), static_cast<uint16_t>(websocket::close_code::policy_error));
  }
  {
    WsClient c(port);
    ASSERT_TRUE(Walk(c, 2, 2, kToken));
    const v1::ServerStats stats = (*grpc)->service().Stats();
    ASSERT_EQ(stats.sessions_size(), 1);
    EXPECT_EQ(stats.sessions(0).tenant(), "browser");
  }
  started->reset();
  grpc->reset();
  std::fclose(log_file);
  const std::string text = vistream::testing::ReadText(log_path);
  EXPECT_NE(text.find("unauthenticated"), std::string::npos) << text;
  EXPECT_NE(text.find("websocket"), std::string::npos) << text;
  EXPECT_EQ(text.find(kToken), std::string::npos) << "the log holds the token";
}

TEST(WebServer, WssWithACertificateOpensslMade) {
  const vistream::testing::TestCerts& certs = vistream::testing::Certs();
  WebOptions web;
  web.tls_cert = certs.server_crt;
  web.tls_key = certs.server_key;
  Served s = Serve({}, web);
  ASSERT_NE(s.web, nullptr);
  EXPECT_STREQ(s.web->scheme(), "https");
  WsClient c(s.web->port(), certs.ca_crt);
  ASSERT_TRUE(c.connected());
  EXPECT_TRUE(Walk(c, 2, 3));
  // Plaintext to the TLS listener gets no session.
  WsClient plain(s.web->port());
  EXPECT_FALSE(plain.connected());
}

TEST(WebServer, DrainAndTheHelloTimeoutEndWebSocketSessionsWithTheirStatus) {
  ServerOptions options;
  options.hello_timeout_s = 1.0;
  WebOptions web;
  web.hello_timeout_s = 1.0;
  Served s = Serve(options, web);
  {
    WsClient silent(s.web->port());
    ASSERT_TRUE(silent.connected());
    std::optional<v1::SessionEnd> end = silent.End(30.0);
    ASSERT_TRUE(end.has_value());
    EXPECT_EQ(end->code(), static_cast<int>(grpc::StatusCode::DEADLINE_EXCEEDED));
    EXPECT_EQ(end->message(), "no Hello within 1 s");
  }
  WsClient c(s.web->port());
  ASSERT_TRUE(Walk(c, 3, 3));
  const auto start = std::chrono::steady_clock::now();
  s.grpc->Shutdown(5.0);
  // The drain waits for the session's last message to go out, not for the client's answer.
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 4.0);
  std::optional<v1::SessionEnd> end = c.End(30.0);
  ASSERT_TRUE(end.has_value());
  EXPECT_EQ(end->code(), static_cast<int>(grpc::StatusCode::UNAVAILABLE));
  EXPECT_EQ(end->message(), "the server is shutting down");
  EXPECT_EQ(c.close_code(), static_cast<uint16_t>(websocket::close_code::going_away));
  // A new one is refused with the same status.
  WsClient late(s.web->port());
  ASSERT_TRUE(late.Send(Hello()));
  std::optional<v1::SessionEnd> refused = late.End(30.0);
  ASSERT_TRUE(refused.has_value());
  EXPECT_EQ(refused->code(), static_cast<int>(grpc::StatusCode::UNAVAILABLE));
}

}  // namespace
}  // namespace vistream::server
