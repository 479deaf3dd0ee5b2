#pragma once
// Certificates for the TLS tests, made with the `openssl` command in the test process's
// temporary folder: a CA, a server certificate it signed for 127.0.0.1 and localhost, a client
// certificate it signed, and a second CA that signed neither but a client certificate of its
// own (a stranger's). Also small file helpers.

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "tests/temp_dir.h"

namespace vistream::testing {

struct TestCerts {
  std::string dir;
  std::string ca_crt, ca_key;          // the CA that signed the two below
  std::string server_crt, server_key;  // for IP 127.0.0.1 and DNS localhost
  std::string client_crt, client_key;  // a client certificate (mutual TLS)
  std::string other_ca_crt, other_ca_key;      // a CA that signed neither
  std::string stranger_crt, stranger_key;      // a client certificate that the other CA signed
};

// Writes `text` to `path` (replacing it); false on failure.
inline bool WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  return static_cast<bool>(out);
}

inline std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Made once per test process (P-256 keys: quick).
inline const TestCerts& Certs() {
  static const TestCerts* certs = [] {
    auto* c = new TestCerts;
    c->dir = (std::filesystem::path(ProcessTempDir()) / "tls").string();
    std::filesystem::create_directories(c->dir);
    const std::string d = c->dir + "/";
    c->ca_crt = d + "ca.crt";
    c->ca_key = d + "ca.key";
    c->server_crt = d + "server.crt";
    c->server_key = d + "server.key";
    c->client_crt = d + "client.crt";
    c->client_key = d + "client.key";
    c->other_ca_crt = d + "other-ca.crt";
    c->other_ca_key = d + "other-ca.key";
    c->stranger_crt = d + "stranger.crt";
    c->stranger_key = d + "stranger.key";
    EXPECT_TRUE(WriteText(d + "server.ext", "subjectAltName=IP:127.0.0.1,DNS:localhost\n"));
    EXPECT_TRUE(WriteText(d + "client.ext", "extendedKeyUsage=clientAuth\n"));
    const std::string key = "-newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes";
    const std::string commands[] = {
        "openssl req -x509 " + key + " -keyout " + c->ca_key + " -out " + c->ca_crt +
            " -days 3 -subj /CN=vistream-test-ca",
        "openssl req -x509 " + key + " -keyout " + c->other_ca_key + " -out " + c->other_ca_crt +
            " -days 3 -subj /CN=another-ca",
        "openssl req " + key + " -keyout " + c->server_key + " -out " + d + "server.csr -subj /CN=localhost",
        "openssl x509 -req -in " + d + "server.csr -CA " + c->ca_crt + " -CAkey " + c->ca_key +
            " -CAcreateserial -days 3 -extfile " + d + "server.ext -out " + c->server_crt,
        "openssl req " + key + " -keyout " + c->client_key + " -out " + d + "client.csr -subj /CN=vistream-client",
        "openssl x509 -req -in " + d + "client.csr -CA " + c->ca_crt + " -CAkey " + c->ca_key +
            " -CAcreateserial -days 3 -extfile " + d + "client.ext -out " + c->client_crt,
        "openssl req " + key + " -keyout " + c->stranger_key + " -out " + d + "stranger.csr -subj /CN=stranger",
        "openssl x509 -req -in " + d + "stranger.csr -CA " + c->other_ca_crt + " -CAkey " + c->other_ca_key +
            " -CAcreateserial -days 3 -extfile " + d + "client.ext -out " + c->stranger_crt,
    };
    for (const std::string& command : commands) {
      const int rc = std::system((command + " >" + d + "openssl.log 2>&1").c_str());
      EXPECT_EQ(rc, 0) << command << ": " << ReadText(d + "openssl.log");
    }
    return c;
  }();
  return *certs;
}

}  // namespace vistream::testing
