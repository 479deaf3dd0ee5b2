#pragma once
// How the client proves itself and checks the server (server/security.h is the other side):
// TLS with a CA that verifies the server's certificate (and a client certificate for mutual
// TLS), and a bearer token sent as `authorization: Bearer TOKEN` on every call. Also what to
// tell the user when a connection fails for one of these reasons: gRPC itself only says that
// the server is unavailable.

#include <memory>
#include <string>

#include <absl/status/status.h>
#include <absl/status/statusor.h>
#include <grpcpp/grpcpp.h>

namespace vistream::client {

struct ChannelSecurity {
  // PEM text, not file names (LoadChannelSecurity reads the files). tls_ca empty: plaintext.
  std::string tls_ca;              // CA bundle that must have signed the server's certificate
  std::string tls_cert, tls_key;   // client certificate chain and its key (mutual TLS); need tls_ca
  std::string token;               // sent as `authorization: Bearer TOKEN`; empty: none
  // Where they came from, for messages: the files of --tls-ca, --tls-cert, --token-file.
  std::string tls_ca_file, tls_cert_file, token_file;
};

// Reads and checks the files of --tls-ca, --tls-cert, --tls-key and --token-file (empty: not
// given). The token file holds the token alone on its first line that is not blank or a `#`
// comment (16 to 256 printable characters, no spaces). Errors: INVALID_ARGUMENT
// "OPTION: FILE: what is wrong" (cannot read, not PEM, the key does not match the
// certificate, no token or a malformed one, never quoting it), or naming the options that go
// together (--tls-cert with --tls-key, both need --tls-ca).
absl::StatusOr<ChannelSecurity> LoadChannelSecurity(const std::string& ca_file, const std::string& cert_file,
                                                    const std::string& key_file, const std::string& token_file);

// SSL credentials when security.tls_ca is set, else insecure ones.
std::shared_ptr<grpc::ChannelCredentials> ChannelCredentialsFor(const ChannelSecurity& security);
// Adds the bearer token (if any) to a call's metadata.
void Authorize(const ChannelSecurity& security, grpc::ClientContext* context);

// Why a connection to `address` (HOST:PORT) fails, when TLS is the reason; empty otherwise.
// Makes one TLS handshake of its own (OpenSSL, at most `timeout_s` seconds) as the client's
// channel would: it tells a plaintext client that the server expects TLS, a TLS client that
// the server does not speak it or that its certificate is not trusted (and why), and a client
// without a certificate that the server requires one.
std::string DiagnoseTls(const std::string& address, const ChannelSecurity& security, double timeout_s);

// UNAUTHENTICATED from the server, said for people: the token was missing (give --token-file)
// or refused (naming the file). Any other status is returned as it is.
absl::Status ExplainRefusal(const absl::Status& status, const ChannelSecurity& security, const std::string& address);

}  // namespace vistream::client
