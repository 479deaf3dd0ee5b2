// The server's security end to end, on loopback: TLS and mutual TLS with certificates made by
// `openssl`, bearer tokens (missing, wrong, revoked by a reload, and by SIGHUP to the
// vistream-server process), health open without a token, per-token and per-address session
// limits, and the Hello timeout.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/generic/generic_stub.h>
#include <gtest/gtest.h>

#include "client/connection.h"
#include "client/session_stream.h"
#include "server/security.h"
#include "tests/server_process_util.h"
#include "tests/server_test_util.h"
#include "tests/temp_dir.h"
#include "tests/tls_test_util.h"

namespace vistream::server {
namespace {

namespace v1 = vistream::v1;
using client::ChannelSecurity;
using client::SessionRecord;
using client::SessionStream;
using test::Cell;
using test::Centre;
using test::kWait;
using testing::Certs;
using testing::ReadText;
using testing::WriteText;

constexpr char kAliceToken[] = "alice-0123456789abcdef";
constexpr char kBobToken[] = "bob-0123456789abcdef+/=";

std::string TokensFile(const std::string& name, const std::string& text) {
  const std::string dir = (std::filesystem::path(vistream::testing::ProcessTempDir()) / "security-e2e").string();
  std::filesystem::create_directories(dir);
  EXPECT_TRUE(WriteText(dir + "/" + name, text));
  return dir + "/" + name;
}

// What the client sends: TLS with `ca_file`, a client certificate (`cert_file`, its key
// `key_file`), a bearer token.
ChannelSecurity Security(const std::string& ca_file = "", const std::string& token = "",
                         const std::string& cert_file = "", const std::string& key_file = "") {
  ChannelSecurity s;
  if (!ca_file.empty()) {
    s.tls_ca = ReadText(ca_file);
    s.tls_ca_file = ca_file;
  }
  if (!cert_file.empty()) {
    s.tls_cert = ReadText(cert_file);
    s.tls_key = ReadText(key_file);
    s.tls_cert_file = cert_file;
  }
  s.token = token;
  s.token_file = "the test's token";
  return s;
}

std::unique_ptr<WalkthroughServer> TlsServer(bool mutual, ServerOptions options = {}) {
  TlsSettings tls{Certs().server_crt, Certs().server_key, mutual ? Certs().ca_crt : "", false};
  absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> c = ServerCredentialsFor(tls, "127.0.0.1:0");
  EXPECT_TRUE(c.ok()) << c.status();
  options.credentials = *c;
  return test::StartServer(options);
}

// A session as the tests' clients open one, with `security`; served: its cell (i, j) arrives.
std::unique_ptr<SessionStream> Open(const WalkthroughServer& server, const ChannelSecurity& security) {
  auto s = std::make_unique<SessionStream>(server.address(), security);
  s->Start(SessionStream::HelloFor("city1"));
  s->SendCredit(uint64_t{1} << 40);
  return s;
}

void ExpectWalks(SessionStream& s, int i, int j) {
  ASSERT_TRUE(s.SendPose(Centre(i, j)));
  EXPECT_TRUE(s.WaitFor([&](const SessionRecord& r) { return r.scene_info && r.CellComplete(Cell(i, j)); }, kWait));
  EXPECT_EQ(s.Snapshot().pvs.at(Cell(i, j)), test::ExpectedPvs(Cell(i, j)));
}

grpc::Status Refusal(const WalkthroughServer& server, const ChannelSecurity& security) {
  auto s = Open(server, security);
  return s->AwaitEnd(kWait);
}

// grpc.health.v1.Health/Check{service: "vistream.v1.Walkthrough"} on a plain channel, without
// a token: the status, and the reply's bytes (SERVING is field 1 = 1).
std::pair<grpc::Status, std::string> HealthCheck(const std::string& address) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub generic(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  const std::string service = "vistream.v1.Walkthrough";
  grpc::Slice check(std::string("\x0a") + static_cast<char>(service.size()) + service);
  auto call = generic.PrepareUnaryCall(&ctx, "/grpc.health.v1.Health/Check", grpc::ByteBuffer(&check, 1), &cq);
  call->StartCall();
  grpc::ByteBuffer reply;
  grpc::Status st;
  call->Finish(&reply, &st, reinterpret_cast<void*>(1));
  void* tag;
  bool ok;
  EXPECT_TRUE(cq.Next(&tag, &ok));
  std::string bytes;
  std::vector<grpc::Slice> slices;
  if (st.ok() && reply.Dump(&slices).ok()) {
    for (const grpc::Slice& sl : slices) bytes.append(reinterpret_cast<const char*>(sl.begin()), sl.size());
  }
  return {st, bytes};
}

TEST(SecurityTls, AClientWithTheCaWalksAndClientsWithoutItAreToldWhy) {
  auto server = TlsServer(false);
  auto good = Open(*server, Security(Certs().ca_crt));
  ExpectWalks(*good, 6, 6);

  // Plaintext against TLS: the client says the server expects TLS and what to give.
  absl::StatusOr<v1::ServerStats> plain = client::Probe(server->address(), 5.0, nullptr, Security());
  ASSERT_EQ(plain.status().code(), absl::StatusCode::kUnavailable) << plain.status();
  EXPECT_NE(plain.status().message().find("it expects a TLS handshake and this client speaks plaintext: give "
                                          "--tls-ca FILE"),
            std::string::npos)
      << plain.status();
  // A CA that did not sign the server's certificate.
  absl::StatusOr<v1::ServerStats> other =
      client::Probe(server->address(), 5.0, nullptr, Security(Certs().other_ca_crt));
  ASSERT_EQ(other.status().code(), absl::StatusCode::kUnavailable) << other.status();
  EXPECT_NE(other.status().message().find("TLS handshake failed: the server's certificate is not trusted by --tls-ca " +
                                          Certs().other_ca_crt),
            std::string::npos)
      << other.status();
  // TLS against a plaintext server.
  auto plaintext = test::StartServer();
  absl::StatusOr<v1::ServerStats> tls_to_plain =
      client::Probe(plaintext->address(), 5.0, nullptr, Security(Certs().ca_crt));
  ASSERT_EQ(tls_to_plain.status().code(), absl::StatusCode::kUnavailable) << tls_to_plain.status();
  EXPECT_NE(tls_to_plain.status().message().find("TLS handshake failed: the server does not answer in TLS"),
            std::string::npos)
      << tls_to_plain.status();
  // A plaintext session against the TLS server never starts.
  v1::Walkthrough::Stub stub(grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  auto stream = stub.Session(&ctx);
  v1::ServerMessage m;
  EXPECT_FALSE(stream->Read(&m));
  const grpc::Status st = stream->Finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAVAILABLE) << st.error_message();
  EXPECT_TRUE(good->Finish().ok());
  EXPECT_EQ(server->service().Stats().sessions_total(), 1u);
}

TEST(SecurityTls, MutualTlsRefusesAClientWithoutACertificateAndServesOneWithIt) {
  auto server = TlsServer(true);
  absl::StatusOr<v1::ServerStats> without = client::Probe(server->address(), 5.0, nullptr, Security(Certs().ca_crt));
  ASSERT_EQ(without.status().code(), absl::StatusCode::kUnavailable) << without.status();
  EXPECT_NE(without.status().message().find("TLS handshake failed: the server requires a client certificate (mutual "
                                            "TLS"),
            std::string::npos)
      << without.status();
  EXPECT_NE(without.status().message().find("give --tls-cert and --tls-key"), std::string::npos) << without.status();
  // A certificate that a CA the server does not trust signed.
  absl::StatusOr<v1::ServerStats> stranger = client::Probe(
      server->address(), 5.0, nullptr, Security(Certs().ca_crt, "", Certs().stranger_crt, Certs().stranger_key));
  ASSERT_EQ(stranger.status().code(), absl::StatusCode::kUnavailable) << stranger.status();
  EXPECT_NE(stranger.status().message().find("TLS handshake failed: the server refused the client certificate in " +
                                             Certs().stranger_crt),
            std::string::npos)
      << stranger.status();
  const ChannelSecurity client = Security(Certs().ca_crt, "", Certs().client_crt, Certs().client_key);
  absl::StatusOr<v1::ServerStats> with = client::Probe(server->address(), 30.0, nullptr, client);
  ASSERT_TRUE(with.ok()) << with.status();
  EXPECT_EQ(with->scene(), "city1");
  auto good = Open(*server, client);
  ExpectWalks(*good, 3, 4);
  EXPECT_TRUE(good->Finish().ok());
  EXPECT_EQ(server->service().Stats().sessions_total(), 1u) << "the client without a certificate got a session";
}

TEST(SecurityTokens, MissingOrWrongTokensAreRefusedBeforeAnyWorkAndHealthStaysOpen) {
  ServerOptions o;
  absl::StatusOr<std::shared_ptr<TokenStore>> tokens = TokenStore::Load(
      TokensFile("tokens-1", std::string("alice ") + kAliceToken + "\nbob " + kBobToken + "\n"));
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  o.tokens = *tokens;
  auto server = test::StartServer(o);
  grpc::Status st = Refusal(*server, Security());
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAUTHENTICATED) << st.error_message();
  EXPECT_EQ(st.error_message(), "missing bearer token");
  st = Refusal(*server, Security("", "alice-0123456789abcdeF"));
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAUTHENTICATED) << st.error_message();
  EXPECT_EQ(st.error_message(), "unknown token");
  EXPECT_EQ(server->service().Stats().sessions_total(), 0u) << "a refused client got a session";

  absl::StatusOr<v1::ServerStats> probe = client::Probe(server->address(), 30.0, nullptr, Security());
  ASSERT_EQ(probe.status().code(), absl::StatusCode::kUnauthenticated) << probe.status();
  EXPECT_NE(probe.status().message().find("requires a token (missing bearer token): give --token-file FILE"),
            std::string::npos)
      << probe.status();
  probe = client::Probe(server->address(), 30.0, nullptr, Security("", "alice-0123456789abcdeF"));
  ASSERT_EQ(probe.status().code(), absl::StatusCode::kUnauthenticated) << probe.status();
  EXPECT_NE(probe.status().message().find("refused the token in the test's token (unknown token)"), std::string::npos)
      << probe.status();
  probe = client::Probe(server->address(), 30.0, nullptr, Security("", kBobToken));
  ASSERT_TRUE(probe.ok()) << probe.status();

  const auto [health, reply] = HealthCheck(server->address());
  ASSERT_TRUE(health.ok()) << health.error_message();
  EXPECT_EQ(reply, std::string("\x08\x01", 2));

  auto good = Open(*server, Security("", kAliceToken));
  ExpectWalks(*good, 8, 8);
  EXPECT_TRUE(good->Finish().ok());
}

TEST(SecurityTokens, ARevokedTokenIsRefusedAfterReloadWhileItsOpenSessionGoesOn) {
  const std::string path = TokensFile("tokens-2", std::string("alice ") + kAliceToken + "\nbob " + kBobToken + "\n");
  ServerOptions o;
  absl::StatusOr<std::shared_ptr<TokenStore>> tokens = TokenStore::Load(path);
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  o.tokens = *tokens;
  auto server = test::StartServer(o);
  auto open = Open(*server, Security("", kBobToken));
  ExpectWalks(*open, 5, 5);
  ASSERT_TRUE(WriteText(path, std::string("alice ") + kAliceToken + "\n"));
  ASSERT_TRUE(o.tokens->Reload().ok());
  const grpc::Status st = Refusal(*server, Security("", kBobToken));
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAUTHENTICATED) << st.error_message();
  ExpectWalks(*open, 6, 5);  // bob's open session is served on
  EXPECT_TRUE(open->Finish().ok());
}

// Waits until a new session with `security` is admitted (sessions that ended are counted
// down when the server is done with them, a moment after the client saw the end).
bool AdmittedWithin(const WalkthroughServer& server, const ChannelSecurity& security, double seconds,
                    std::unique_ptr<SessionStream>* admitted) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < until) {
    auto s = Open(server, security);
    if (s->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait)) {
      *admitted = std::move(s);
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

TEST(SecurityLimits, PerTokenAndPerAddressLimitsHoldAndFreeUpWhenSessionsEnd) {
  ServerOptions o;
  absl::StatusOr<std::shared_ptr<TokenStore>> tokens =
      TokenStore::Load(TokensFile("tokens-3", std::string("alice ") + kAliceToken + "\nbob " + kBobToken + "\n"));
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  o.tokens = *tokens;
  o.max_sessions_per_token = 2;
  o.max_sessions_per_address = 3;
  auto server = test::StartServer(o);
  std::vector<std::unique_ptr<SessionStream>> alice;
  for (int k = 0; k < 2; ++k) {
    alice.push_back(Open(*server, Security("", kAliceToken)));
    ASSERT_TRUE(alice.back()->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  }
  grpc::Status st = Refusal(*server, Security("", kAliceToken));
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << st.error_message();
  EXPECT_NE(st.error_message().find("too many sessions for tenant 'alice': at most 2 at once per token"),
            std::string::npos)
      << st.error_message();
  auto bob = Open(*server, Security("", kBobToken));
  ASSERT_TRUE(bob->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  // Three from 127.0.0.1: the address is full, whoever asks.
  st = Refusal(*server, Security("", kBobToken));
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << st.error_message();
  EXPECT_NE(st.error_message().find("too many sessions from 127.0.0.1: at most 3 at once per client address"),
            std::string::npos)
      << st.error_message();
  // One of alice's ends: she may open another (and the address has room again).
  EXPECT_TRUE(alice.front()->Finish().ok());
  std::unique_ptr<SessionStream> again;
  ASSERT_TRUE(AdmittedWithin(*server, Security("", kAliceToken), 30.0, &again));
  ExpectWalks(*again, 2, 2);
  EXPECT_TRUE(again->Finish().ok());
  EXPECT_TRUE(alice.back()->Finish().ok());
  EXPECT_TRUE(bob->Finish().ok());
}

TEST(SecurityLimits, AStreamWithoutHelloEndsDeadlineExceededAfterTheTimeout) {
  ServerOptions o;
  o.hello_timeout_s = 0.5;
  auto server = test::StartServer(o);
  auto channel = grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials());
  v1::Walkthrough::Stub stub(channel);
  ASSERT_TRUE(channel->WaitForConnected(std::chrono::system_clock::now() + std::chrono::seconds(30)));
  grpc::ClientContext silent;
  const auto began = std::chrono::steady_clock::now();
  auto stream = stub.Session(&silent);  // opens the stream, sends nothing
  v1::ServerMessage m;
  EXPECT_FALSE(stream->Read(&m));
  const grpc::Status st = stream->Finish();
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << st.error_message();
  EXPECT_EQ(st.error_message(), "no Hello within 0.5 s");
  EXPECT_GE(waited, 0.45);
  EXPECT_LT(waited, 10.0);
  // The server counts the session out once it is done with it, a moment after the client saw it end.
  for (int k = 0; k < 200 && server->service().active_sessions() > 0; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_EQ(server->service().active_sessions(), 0u);
  // A session that says Hello in time is not ended by the timeout, however long it then stays.
  auto greeted = test::Connect(*server);
  ASSERT_TRUE(greeted->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_FALSE(greeted->Ended());
  ExpectWalks(*greeted, 7, 3);
  EXPECT_TRUE(greeted->Finish().ok());
}

// ---- the vistream-server process ----

using test::RunServer;

TEST(SecurityProcess, BadSecurityOptionsExitTwoBeforeTheSceneLoads) {
  const std::string bad_tokens = TokensFile("bad-tokens", "alice\n");
  const std::pair<std::string, std::string> cases[] = {
      {"--listen 0.0.0.0:0", "vistream-server: error: refusing to serve plaintext on 0.0.0.0:0"},
      {"--tls-cert " + Certs().server_crt, "vistream-server: error: tls.cert is given without tls.key"},
      {"--tls-cert " + Certs().server_crt + " --tls-key " + Certs().client_key,
       "the key does not match the certificate"},
      {"--tokens /nonexistent/tokens", "vistream-server: error: --tokens: /nonexistent/tokens: cannot read"},
      {"--tokens " + bad_tokens, "vistream-server: error: --tokens: " + bad_tokens + ":1: 'alice' has no token"},
      {"--hello-timeout -1", "vistream-server: error: --hello-timeout: '-1' is not a number from 0"},
      {"--max-sessions-per-token 1.5", "vistream-server: error: --max-sessions-per-token: '1.5' is not a whole number"},
      {"--max-sessions-per-address x", "vistream-server: error: --max-sessions-per-address: 'x' is not a whole number"},
  };
  for (const auto& [args, message] : cases) {
    const auto [rc, out] = RunServer("--scene no-such-scene " + args);
    EXPECT_EQ(rc, 2) << args << ": " << out;
    EXPECT_NE(out.find(message), std::string::npos) << args << ": " << out;
    EXPECT_EQ(out.find("no-such-scene"), std::string::npos) << args << ": " << out;
  }
  // Good ones pass: the scene is what fails then (nothing listens on 0.0.0.0 in this test).
  const auto [rc, out] = RunServer("--scene no-such-scene --listen 0.0.0.0:0 --insecure --hello-timeout 0.5 --tokens " +
                                   TokensFile("good-tokens", std::string("alice ") + kAliceToken + "\n"));
  EXPECT_EQ(rc, 1) << out;
  EXPECT_NE(out.find("no-such-scene"), std::string::npos) << out;
}

TEST(SecurityProcess, SighupRevokesATokenWithoutDroppingItsOpenSession) {
  const std::string path =
      TokensFile("tokens-sighup", std::string("alice ") + kAliceToken + "\nbob " + kBobToken + "\n");
  const std::string log = TokensFile("server-sighup.log", "");
  std::string error;
  std::unique_ptr<test::RunningServer> server = test::RunningServer::Start(
      VISTREAM_SERVER_BIN, {"--scene", "city1", "--listen", "127.0.0.1:0", "--threads", "1", "--tokens", path}, &error,
      log);
  ASSERT_NE(server, nullptr) << error << "; log: " << ReadText(log);
  const std::string address = server->address();
  const pid_t pid = server->pid();

  SessionStream open(address, Security("", kAliceToken));
  open.Start(SessionStream::HelloFor("city1"));
  open.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(open.SendPose(Centre(4, 4)));
  ASSERT_TRUE(open.WaitFor([](const SessionRecord& r) { return r.CellComplete(Cell(4, 4)); }, kWait));

  ASSERT_TRUE(WriteText(path, std::string("bob ") + kBobToken + "\n"));
  ASSERT_EQ(kill(pid, SIGHUP), 0);
  // The reload happens on the server's main loop: wait for its log line.
  for (int k = 0; k < 600 && ReadText(log).find("tokens_reloaded") == std::string::npos; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_NE(ReadText(log).find("tokens_reloaded"), std::string::npos) << ReadText(log);
  SessionStream refused(address, Security("", kAliceToken));
  refused.Start(SessionStream::HelloFor("city1"));
  const grpc::Status st = refused.AwaitEnd(kWait);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAUTHENTICATED) << st.error_message();
  ASSERT_TRUE(open.SendPose(Centre(5, 4)));
  EXPECT_TRUE(open.WaitFor([](const SessionRecord& r) { return r.CellComplete(Cell(5, 4)); }, kWait))
      << "alice's open session stopped being served";
  EXPECT_FALSE(open.Ended());
  // A file that does not parse keeps the tokens and says why.
  ASSERT_TRUE(WriteText(path, "bob\n"));
  ASSERT_EQ(kill(pid, SIGHUP), 0);
  for (int k = 0; k < 600 && ReadText(log).find("tokens_reload_failed") == std::string::npos; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const std::string text = ReadText(log);
  EXPECT_NE(text.find("tokens_reload_failed"), std::string::npos) << text;
  EXPECT_NE(text.find(path + ":1: 'bob' has no token"), std::string::npos) << text;
  EXPECT_NE(text.find("tenant=alice"), std::string::npos) << "session_start names the tenant: " << text;
  EXPECT_EQ(text.find(kAliceToken), std::string::npos) << "the log shows a token";
  EXPECT_EQ(text.find(kBobToken), std::string::npos) << "the log shows a token";
  EXPECT_TRUE(open.Finish().ok());
  EXPECT_EQ(server->Stop(SIGTERM), 0);
}

}  // namespace
}  // namespace vistream::server
