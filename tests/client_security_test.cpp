// vistream-client against a server that wants TLS (certificates made by `openssl`), a client
// certificate, or a bearer token: --tls-ca, --tls-cert, --tls-key and --token-file, their bad
// files (exit 2 naming the option and the file), and what the client says when the server
// refuses it (exit 1, "vistream-client: error: ...", pointing at the option to give).
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "server/security.h"
#include "server/served_scene.h"
#include "server/service.h"
#include "tests/temp_dir.h"
#include "tests/tls_test_util.h"

namespace vistream::client {
namespace {

using server::ServedScene;
using server::WalkthroughServer;
using testing::Certs;
using testing::WriteText;

constexpr char kToken[] = "carol-0123456789abcdef";

// The default scene, as the README's run command serves it.
ServedScene& Default() {
  static ServedScene* scene = [] {
    server::ServedSceneOptions o;
    o.scene = "default";
    o.threads = 2;
    absl::StatusOr<std::unique_ptr<ServedScene>> s = ServedScene::Create(o);
    EXPECT_TRUE(s.ok()) << s.status();
    return s->release();
  }();
  return *scene;
}

std::string File(const std::string& name, const std::string& text) {
  const std::string dir = (std::filesystem::path(vistream::testing::ProcessTempDir()) / "client-security").string();
  std::filesystem::create_directories(dir);
  EXPECT_TRUE(WriteText(dir + "/" + name, text));
  return dir + "/" + name;
}

// A server on a free loopback port: TLS (mutual with `client_ca`) and/or tokens.
std::unique_ptr<WalkthroughServer> Start(bool tls, bool mutual, bool tokens) {
  server::ServerOptions o;
  o.listen = "127.0.0.1:0";
  if (tls) {
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> c = server::ServerCredentialsFor(
        {Certs().server_crt, Certs().server_key, mutual ? Certs().ca_crt : "", false}, o.listen);
    EXPECT_TRUE(c.ok()) << c.status();
    o.credentials = *c;
  }
  if (tokens) {
    absl::StatusOr<std::shared_ptr<server::TokenStore>> t =
        server::TokenStore::Load(File("tokens", std::string("carol ") + kToken + "\n"));
    EXPECT_TRUE(t.ok()) << t.status();
    o.tokens = *t;
  }
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> s = WalkthroughServer::Start(&Default(), o, nullptr);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? std::move(*s) : nullptr;
}

struct Ran {
  int rc = -1;
  std::string output;  // stdout and stderr
};

Ran Client(const std::string& args) {
  Ran r;
  std::FILE* p = popen((std::string(VISTREAM_CLIENT_BIN " ") + args + " 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) r.output.append(buf, n);
  const int status = pclose(p);
  r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string Headless(const WalkthroughServer& s) {
  return "--headless --size 160x90 --max-fps 20 --seconds 2 --connect-timeout 20 --server 127.0.0.1:" +
         std::to_string(s.port());
}

TEST(ClientSecurity, WithTheCaACertificateAndTheTokenTheClientWalks) {
  auto server = Start(true, true, true);
  ASSERT_NE(server, nullptr);
  const std::string token = File("token", "# carol's token\n\n" + std::string(kToken) + "\n");
  const Ran r = Client(Headless(*server) + " --json --tls-ca " + Certs().ca_crt + " --tls-cert " + Certs().client_crt +
                       " --tls-key " + Certs().client_key + " --token-file " + token);
  ASSERT_EQ(r.rc, 0) << r.output;
  EXPECT_NE(r.output.find("\"objects_received\""), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("\"objects_received\": 0,"), std::string::npos) << r.output;
  EXPECT_EQ(server->service().Stats().sessions_total(), 1u);
}

TEST(ClientSecurity, ARefusedClientSaysWhyNamingTheOptionAndExitsOne) {
  auto tls = Start(true, false, false);
  auto mutual = Start(true, true, false);
  auto plain = Start(false, false, false);
  auto tokens = Start(false, false, true);
  ASSERT_TRUE(tls && mutual && plain && tokens);
  const std::string ca = " --tls-ca " + Certs().ca_crt;
  const struct {
    std::string args;
    std::string message;
  } cases[] = {
      {Headless(*tls), "it expects a TLS handshake and this client speaks plaintext: give --tls-ca FILE"},
      {Headless(*tls) + " --tls-ca " + Certs().other_ca_crt,
       "TLS handshake failed: the server's certificate is not trusted by --tls-ca " + Certs().other_ca_crt},
      {Headless(*mutual) + ca, "TLS handshake failed: the server requires a client certificate (mutual TLS"},
      {Headless(*plain) + ca, "TLS handshake failed: the server does not answer in TLS"},
      {Headless(*tokens), "requires a token (missing bearer token): give --token-file FILE"},
      {Headless(*tokens) + " --token-file " + File("wrong-token", "carol-0123456789abcdeF\n"),
       "refused the token in " + File("wrong-token", "carol-0123456789abcdeF\n") + " (unknown token)"},
  };
  for (const auto& c : cases) {
    const auto began = std::chrono::steady_clock::now();
    const Ran r = Client(c.args);
    const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
    EXPECT_EQ(r.rc, 1) << c.args << ": " << r.output;
    EXPECT_NE(r.output.find("vistream-client: error: "), std::string::npos) << c.args << ": " << r.output;
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.args << ": " << r.output;
    EXPECT_LT(took, 60.0) << c.args << ": a refusal must not be retried for long";
  }
  EXPECT_EQ(tokens->service().Stats().sessions_total(), 0u);
}

TEST(ClientSecurity, BadSecurityFilesExitTwoNamingTheOptionAndTheFile) {
  const std::string garbage = File("garbage.pem", "hello\n");
  const std::string spaced = File("spaced-token", "carol 0123456789abcdef\n");
  const std::string empty = File("empty-token", "# only a comment\n\n");
  const std::string short_token = File("short-token", "0123\n");
  const std::string server = " --headless --server 127.0.0.1:1";
  const std::pair<std::string, std::string> cases[] = {
      {"--tls-ca /nonexistent/ca.crt", "--tls-ca: /nonexistent/ca.crt: cannot read: No such file or directory"},
      {"--tls-ca " + garbage, "--tls-ca: " + garbage + ": not a PEM certificate"},
      {"--tls-ca " + Certs().ca_crt + " --tls-cert " + Certs().client_crt, "--tls-cert: needs --tls-key"},
      {"--tls-ca " + Certs().ca_crt + " --tls-key " + Certs().client_key, "--tls-key: needs --tls-cert"},
      {"--tls-cert " + Certs().client_crt + " --tls-key " + Certs().client_key, "--tls-cert: needs --tls-ca"},
      {"--tls-ca " + Certs().ca_crt + " --tls-cert " + Certs().client_crt + " --tls-key " + Certs().server_key,
       "--tls-key: " + Certs().server_key + ": the key does not match the certificate in " + Certs().client_crt},
      {"--tls-ca " + Certs().ca_crt + " --tls-cert " + garbage + " --tls-key " + Certs().client_key,
       "--tls-cert: " + garbage + ": not a PEM certificate"},
      {"--tls-ca " + Certs().ca_crt + " --tls-cert " + Certs().client_crt + " --tls-key " + Certs().client_crt,
       "--tls-key: " + Certs().client_crt + ": not a PEM private key"},
      {"--token-file /nonexistent/token", "--token-file: /nonexistent/token: cannot read: No such file or directory"},
      {"--token-file " + spaced, "--token-file: " + spaced + ":1: more than a token on the line"},
      {"--token-file " + empty, "--token-file: " + empty + ": no token in it"},
      {"--token-file " + short_token, "--token-file: " + short_token + ":1: the token is 4 characters long"},
  };
  for (const auto& [args, message] : cases) {
    const Ran r = Client(args + server);
    EXPECT_EQ(r.rc, 2) << args << ": " << r.output;
    EXPECT_NE(r.output.find("vistream-client: error: " + message), std::string::npos) << args << ": " << r.output;
    EXPECT_NE(r.output.find("Run 'vistream-client --help' for the options."), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("0123456789abcdef"), std::string::npos) << "the message shows the token: " << r.output;
  }
  // There is no option that takes the token itself.
  const Ran r = Client("--token " + std::string(kToken) + server);
  EXPECT_EQ(r.rc, 2) << r.output;
}

}  // namespace
}  // namespace vistream::client
