// The server's security units (server/security.h, server/admission.h): which credentials a
// listen address and TLS files give, the token file and its reload, bearer metadata, peer
// addresses and per-address / per-tenant session counts.
#include <filesystem>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "server/admission.h"
#include "server/security.h"
#include "tests/temp_dir.h"
#include "tests/tls_test_util.h"

namespace vistream::server {
namespace {

using testing::Certs;
using testing::ReadText;
using testing::WriteText;

std::string TempFile(const std::string& name, const std::string& text) {
  const std::string dir = (std::filesystem::path(vistream::testing::ProcessTempDir()) / "security").string();
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/" + name;
  EXPECT_TRUE(WriteText(path, text));
  return path;
}

TEST(ServerCredentials, PlaintextIsServedOnLoopbackOnlyUnlessInsecure) {
  for (const char* listen : {"127.0.0.1:50051", "127.3.4.5:0", "[::1]:50051", "::1:50051", "localhost:0",
                             "LocalHost:7"}) {
    EXPECT_TRUE(IsLoopbackListen(listen)) << listen;
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> c = ServerCredentialsFor({}, listen);
    EXPECT_TRUE(c.ok()) << listen << ": " << c.status();
  }
  for (const char* listen : {"0.0.0.0:50051", "[::]:50051", "192.168.1.20:1", "10.0.0.1:0", "example.com:443",
                             "128.0.0.1:5", "[::2]:5"}) {
    EXPECT_FALSE(IsLoopbackListen(listen)) << listen;
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> c = ServerCredentialsFor({}, listen);
    ASSERT_EQ(c.status().code(), absl::StatusCode::kFailedPrecondition) << listen << ": " << c.status();
    EXPECT_NE(c.status().message().find(std::string("refusing to serve plaintext on ") + listen), std::string::npos)
        << c.status();
    EXPECT_NE(c.status().message().find("give tls.cert and tls.key"), std::string::npos) << c.status();
    EXPECT_NE(c.status().message().find("tls.insecure = true"), std::string::npos) << c.status();
    TlsSettings insecure;
    insecure.insecure = true;
    EXPECT_TRUE(ServerCredentialsFor(insecure, listen).ok()) << listen;
  }
}

TEST(ServerCredentials, GoodTlsFilesServeAnyAddress) {
  TlsSettings tls{Certs().server_crt, Certs().server_key, "", false};
  EXPECT_TRUE(ServerCredentialsFor(tls, "0.0.0.0:50051").ok());
  tls.client_ca = Certs().ca_crt;
  absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> c = ServerCredentialsFor(tls, "[::]:50051");
  EXPECT_TRUE(c.ok()) << c.status();
  // A chain file with the CA after the server's certificate (the usual fullchain.pem).
  tls.cert = TempFile("fullchain.pem", ReadText(Certs().server_crt) + ReadText(Certs().ca_crt));
  EXPECT_TRUE(ServerCredentialsFor(tls, "0.0.0.0:1").ok());
}

TEST(ServerCredentials, BadTlsFilesAreNamedWithWhatIsWrong) {
  const std::string garbage = TempFile("garbage.pem", "hello\n");
  const std::string encrypted = Certs().dir + "/encrypted.key";
  ASSERT_EQ(std::system(("openssl pkey -in " + Certs().server_key + " -aes256 -passout pass:secret -out " + encrypted +
                         " 2>/dev/null")
                            .c_str()),
            0);
  struct Case {
    TlsSettings tls;
    std::string message;
  };
  const testing::TestCerts& c = Certs();
  const Case cases[] = {
      {{c.server_crt, "", "", false}, "tls.cert is given without tls.key"},
      {{"", c.server_key, "", false}, "tls.key is given without tls.cert"},
      {{"", "", c.ca_crt, true}, "tls.client_ca is given without tls.cert and tls.key"},
      {{"/nonexistent/server.crt", c.server_key, "", false},
       "tls.cert: /nonexistent/server.crt: cannot read: No such file or directory"},
      {{c.server_crt, "/nonexistent/server.key", "", false},
       "tls.key: /nonexistent/server.key: cannot read: No such file or directory"},
      {{garbage, c.server_key, "", false}, "tls.cert: " + garbage + ": not a PEM certificate"},
      {{c.server_key, c.server_key, "", false}, "tls.cert: " + c.server_key + ": not a PEM certificate"},
      {{c.server_crt, c.server_crt, "", false}, "tls.key: " + c.server_crt + ": not a PEM private key"},
      {{c.server_crt, encrypted, "", false}, "tls.key: " + encrypted + ": the key is encrypted"},
      {{c.server_crt, c.client_key, "", false},
       "tls.key: " + c.client_key + ": the key does not match the certificate in " + c.server_crt},
      {{c.server_crt, c.server_key, garbage, false}, "tls.client_ca: " + garbage + ": not a PEM CA bundle"},
      {{c.server_crt, c.server_key, "/nonexistent/ca.crt", false}, "tls.client_ca: /nonexistent/ca.crt: cannot read"},
  };
  for (const Case& k : cases) {
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> got = ServerCredentialsFor(k.tls, "127.0.0.1:0");
    ASSERT_EQ(got.status().code(), absl::StatusCode::kInvalidArgument) << k.message << ": " << got.status();
    EXPECT_NE(got.status().message().find(k.message), std::string::npos) << got.status();
  }
}

TEST(TokenStore, FindsTheTenantOfEachTokenAndNoneForOthers) {
  const std::string path = TempFile("tokens", "# tenants\n\n  alice   aaaaaaaaaaaaaaaaaaaa-1\r\n"
                                              "bob\tbbbbbbbbbbbbbbbbbbbb+/=~\n   # indented comment\n");
  absl::StatusOr<std::shared_ptr<TokenStore>> store = TokenStore::Load(path);
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ((*store)->size(), 2u);
  EXPECT_EQ((*store)->path(), path);
  EXPECT_EQ((*store)->TenantFor("aaaaaaaaaaaaaaaaaaaa-1"), "alice");
  EXPECT_EQ((*store)->TenantFor("bbbbbbbbbbbbbbbbbbbb+/=~"), "bob");
  EXPECT_EQ((*store)->TenantFor("aaaaaaaaaaaaaaaaaaaa-"), std::nullopt);
  EXPECT_EQ((*store)->TenantFor("aaaaaaaaaaaaaaaaaaaa-12"), std::nullopt);
  EXPECT_EQ((*store)->TenantFor(""), std::nullopt);
  EXPECT_EQ((*store)->TenantFor("alice"), std::nullopt);
  // An empty file is a store that lets no one in.
  absl::StatusOr<std::shared_ptr<TokenStore>> none = TokenStore::Load(TempFile("no-tokens", "# nobody yet\n"));
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_EQ((*none)->size(), 0u);
  EXPECT_EQ((*none)->TenantFor("aaaaaaaaaaaaaaaaaaaa-1"), std::nullopt);
}

TEST(TokenStore, ParseErrorsNamePathAndLineAndNeverTheToken) {
  const std::string good = "alice aaaaaaaaaaaaaaaaaaaaaaaa\n";
  const std::pair<std::string, std::string> cases[] = {
      {"# c\nalice\n", ":2: 'alice' has no token: expected `name token`"},
      {"alice aaaaaaaaaaaaaaaaaaaaaaaa # laptop\n", ":1: expected `name token`, found 4 fields"},
      {"# c\n\nalice short-token\n", ":3: the token of 'alice' is 11 characters long: a token has 16 to 256"},
      {"alice " + std::string(257, 'x') + "\n", ":1: the token of 'alice' is 257 characters long"},
      {"alice aaaaaaaaaaaa\x07zzzzzzzzzz\n", ":1: the token of 'alice' has a non-printable character (byte 0x07) at "
                                            "character 13"},
      {"alice aaaaaaaaaaaa\xc3\xa9zzzzzzzzzz\n", ":1: the token of 'alice' has a non-printable character (byte 0xc3)"},
      {good + "bob bbbbbbbbbbbbbbbbbbbbbbbbbbb\nalice cccccccccccccccccccccccc\n",
       ":3: 'alice' is listed twice (also on line 1)"},
      {good + "\nbob aaaaaaaaaaaaaaaaaaaaaaaa\n",
       ":3: the token of 'bob' is the token of 'alice' (line 1): each tenant needs a token of its own"},
      {std::string(65, 'n') + " aaaaaaaaaaaaaaaaaaaaaaaa\n", ":1: the tenant's name is 65 characters long"},
      {"al\x01ice aaaaaaaaaaaaaaaaaaaaaaaa\n", ":1: the tenant's name has a non-printable character (byte 0x01)"},
  };
  int k = 0;
  for (const auto& [text, message] : cases) {
    const std::string path = TempFile("bad-tokens-" + std::to_string(k++), text);
    absl::StatusOr<std::shared_ptr<TokenStore>> store = TokenStore::Load(path);
    ASSERT_EQ(store.status().code(), absl::StatusCode::kInvalidArgument) << text << ": " << store.status();
    EXPECT_NE(store.status().message().find(path + message), std::string::npos) << store.status();
    for (const char* token : {"aaaaaaaaaaaaaaaaaaaaaaaa", "short-token", "cccccccccccccccccccccccc"}) {
      EXPECT_EQ(store.status().message().find(token), std::string::npos)
          << "the message repeats a token: " << store.status();
    }
  }
  absl::StatusOr<std::shared_ptr<TokenStore>> missing = TokenStore::Load("/nonexistent/tokens");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("/nonexistent/tokens: cannot read: No such file or directory"),
            std::string::npos)
      << missing.status();
}

TEST(TokenStore, ReloadServesTheNewFileAndKeepsTheOldTokensWhenItIsBad) {
  const std::string path = TempFile("reload-tokens", "alice aaaaaaaaaaaaaaaaaaaaaaaa\nbob bbbbbbbbbbbbbbbbbbbbbbbb\n");
  absl::StatusOr<std::shared_ptr<TokenStore>> loaded = TokenStore::Load(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  TokenStore& store = **loaded;
  // Lookups from other threads while the file changes under them never see a half-made set.
  std::atomic<bool> stop{false};
  std::atomic<int> odd{0};
  std::thread reader([&] {
    while (!stop) {
      const std::optional<std::string> t = store.TenantFor("aaaaaaaaaaaaaaaaaaaaaaaa");
      if (t.has_value() && *t != "alice") ++odd;
    }
  });
  ASSERT_TRUE(WriteText(path, "bob bbbbbbbbbbbbbbbbbbbbbbbb\ncarol cccccccccccccccccccccccc\n"));
  ASSERT_TRUE(store.Reload().ok());
  EXPECT_EQ(store.TenantFor("aaaaaaaaaaaaaaaaaaaaaaaa"), std::nullopt) << "alice was revoked";
  EXPECT_EQ(store.TenantFor("cccccccccccccccccccccccc"), "carol");
  EXPECT_EQ(store.TenantFor("bbbbbbbbbbbbbbbbbbbbbbbb"), "bob");
  ASSERT_TRUE(WriteText(path, "bob bbbbbbbbbbbbbbbbbbbbbbbb\ndave\n"));
  const absl::Status bad = store.Reload();
  ASSERT_EQ(bad.code(), absl::StatusCode::kInvalidArgument) << bad;
  EXPECT_NE(bad.message().find(path + ":2: 'dave' has no token"), std::string::npos) << bad;
  EXPECT_EQ(store.TenantFor("cccccccccccccccccccccccc"), "carol") << "a bad file must leave the tokens as they were";
  EXPECT_EQ(store.size(), 2u);
  std::filesystem::remove(path);
  EXPECT_FALSE(store.Reload().ok());
  EXPECT_EQ(store.size(), 2u);
  stop = true;
  reader.join();
  EXPECT_EQ(odd.load(), 0);
}

TEST(BearerToken, TakesTheTokenOfABearerAuthorizationOnly) {
  auto token = [](const std::vector<std::pair<std::string, std::string>>& entries) {
    Metadata m;  // string_refs into `entries`, as gRPC's point into its own buffers
    for (const auto& [k, v] : entries) {
      m.emplace(grpc::string_ref(k.data(), k.size()), grpc::string_ref(v.data(), v.size()));
    }
    return BearerToken(m);
  };
  EXPECT_EQ(token({{"authorization", "Bearer abc"}}), "abc");
  EXPECT_EQ(token({{"authorization", "bearer abc"}}), "abc");
  EXPECT_EQ(token({{"authorization", "BEARER   abc  "}}), "abc");
  EXPECT_EQ(token({{"authorization", "Basic YWxhZGRpbjpvcGVuc2VzYW1l"}}), std::nullopt);
  EXPECT_EQ(token({{"authorization", "Bearer"}}), std::nullopt);
  EXPECT_EQ(token({{"authorization", "Bearer   "}}), std::nullopt);
  EXPECT_EQ(token({{"authorization", "Bearerabc"}}), std::nullopt);
  EXPECT_EQ(token({{"x-token", "Bearer abc"}}), std::nullopt);
  EXPECT_EQ(token({}), std::nullopt);
  EXPECT_EQ(token({{"authorization", "Basic x"}, {"authorization", "Bearer second"}}), "second");
}

TEST(PeerHost, IsTheClientAddressWithoutPort) {
  EXPECT_EQ(PeerHost("ipv4:127.0.0.1:53422"), "127.0.0.1");
  EXPECT_EQ(PeerHost("ipv6:[::1]:53422"), "::1");
  EXPECT_EQ(PeerHost("ipv6:%5B::1%5D:53422"), "::1");
  EXPECT_EQ(PeerHost("ipv6:[2001:db8::7]:1"), "2001:db8::7");
  EXPECT_EQ(PeerHost("unix:/tmp/socket"), "unix:/tmp/socket");
}

TEST(SessionQuota, LimitsEachAddressAndTenantAndCountsDownOnRelease) {
  SessionQuota q(2, 1);
  EXPECT_TRUE(q.Admit("10.0.0.1", "alice").ok());
  absl::Status s = q.Admit("10.0.0.2", "alice");
  ASSERT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_NE(s.message().find("too many sessions for tenant 'alice': at most 1 at once per token "
                             "(limits.max_sessions_per_token"),
            std::string::npos)
      << s;
  EXPECT_TRUE(q.Admit("10.0.0.1", "bob").ok());
  s = q.Admit("10.0.0.1", "carol");
  ASSERT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_NE(s.message().find("too many sessions from 10.0.0.1: at most 2 at once per client address "
                             "(limits.max_sessions_per_address"),
            std::string::npos)
      << s;
  EXPECT_EQ(q.sessions_from("10.0.0.1"), 2u);
  EXPECT_EQ(q.sessions_of("carol"), 0u) << "a refused session is not counted";
  q.Release("10.0.0.1", "alice");
  EXPECT_EQ(q.sessions_of("alice"), 0u);
  EXPECT_TRUE(q.Admit("10.0.0.1", "alice").ok());
  SessionQuota none(0, 0);
  for (int k = 0; k < 1000; ++k) EXPECT_TRUE(none.Admit("10.0.0.1", "alice").ok());
}

}  // namespace
}  // namespace vistream::server
