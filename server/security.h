#pragma once
// Who may talk to the server: TLS credentials from PEM files (optionally mutual TLS), the rule
// that plaintext is served on loopback only unless the configuration says insecure = true, and
// bearer tokens from a file of `name token` lines (the logs name the tenant, never the token).
// The names in messages are the configuration file's keys (tls.cert, tls.key, tls.client_ca,
// tls.insecure, auth.tokens); their command-line options are --tls-cert, --tls-key,
// --tls-client-ca, --insecure and --tokens.

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <shared_mutex>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/status.h>
#include <absl/status/statusor.h>
#include <grpcpp/grpcpp.h>

namespace vistream::server {

struct TlsSettings {
  std::string cert;       // PEM certificate chain file (tls.cert); empty: no TLS
  std::string key;        // PEM private key file (tls.key), unencrypted
  std::string client_ca;  // PEM CA bundle file (tls.client_ca): clients must present a certificate it signed
  bool insecure = false;  // tls.insecure: allow plaintext on an address that is not loopback
};

// Whether the host of `listen` (HOST:PORT) is a loopback address: 127.0.0.0/8, ::1 (with or
// without brackets) or localhost.
bool IsLoopbackListen(std::string_view listen);

// The first line of `path` (a secret such as the PVS store's password), without its line end
// or surrounding spaces. Errors: NOT_FOUND naming `path` (cannot read), INVALID_ARGUMENT when
// the first line is empty.
absl::StatusOr<std::string> ReadSecretLine(const std::string& path);

// The credentials to serve `listen` with. TLS when tls.cert and tls.key are given: both files
// are read and checked (PEM, the key matches the certificate, tls.client_ca a PEM bundle of at
// least one certificate); with tls.client_ca, clients must present a certificate it verifies.
// Without them: plaintext, only on a loopback address or with tls.insecure.
// Errors: INVALID_ARGUMENT naming the key and the file and what is wrong with it (cannot read,
// not a PEM certificate / private key, an encrypted key, the key does not match the
// certificate; one of tls.cert and tls.key without the other; tls.client_ca without them);
// FAILED_PRECONDITION when plaintext would be served on another address, saying why.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(const TlsSettings& tls,
                                                                              const std::string& listen);

// The tenants allowed in and their tokens, from a file of lines `name token` (whitespace
// between them; `#` starts a comment line; blank lines are skipped). Names are 1 to 64
// printable ASCII characters, tokens 16 to 256, neither with spaces; each name and each token
// once. Only SHA-256 digests of the tokens are kept. Thread-safe: lookups run while Reload
// swaps in a new set.
class TokenStore {
 public:
  // Reads `path`. Errors: INVALID_ARGUMENT "PATH:LINE: what is wrong" (a name without a token,
  // more than two fields, a token too short, too long or with a non-printable character, a
  // name or token listed twice), or "PATH: cannot read: why". No message repeats a token.
  static absl::StatusOr<std::shared_ptr<TokenStore>> Load(const std::string& path);

  // The tenant whose token `token` is; none for an unknown (or empty) token. Takes the same
  // time whichever entry matches, or none: every entry's digest is compared in constant time.
  std::optional<std::string> TenantFor(std::string_view token) const;
  // Reads the file again and, when it is good, serves its tokens from now on (sessions open
  // already are not affected). On an error (as Load's) the tokens held stay and it is returned.
  absl::Status Reload();
  size_t size() const;
  const std::string& path() const { return path_; }

 private:
  struct Entry {
    std::string name;
    std::array<uint8_t, 32> digest;  // SHA-256 of the token
  };
  explicit TokenStore(std::string path) : path_(std::move(path)) {}
  static absl::StatusOr<std::vector<Entry>> Parse(const std::string& path);

  const std::string path_;
  mutable std::shared_mutex mu_;
  std::vector<Entry> entries_;
};

using Metadata = std::multimap<grpc::string_ref, grpc::string_ref>;

// The token of an `authorization: Bearer TOKEN` entry of call metadata (the scheme's case does
// not matter); none without one.
std::optional<std::string> BearerToken(const Metadata& metadata);

// The tenant of a call with `metadata`. Errors: UNAUTHENTICATED "missing bearer token" (no
// authorization: Bearer entry) or "unknown token".
absl::StatusOr<std::string> Authenticate(const TokenStore& tokens, const Metadata& metadata);

}  // namespace vistream::server
