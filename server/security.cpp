#include "server/security.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <strings.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>

#include <absl/strings/ascii.h>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>

#include "credentials/credential_files.h"

namespace vistream::server {

namespace {

bool IsSpace(char c) { return c == ' ' || c == '\t'; }

std::array<uint8_t, 32> Sha256(std::string_view text) {
  std::array<uint8_t, 32> d{};
  unsigned int n = 0;
  EVP_Digest(text.data(), text.size(), d.data(), &n, EVP_sha256(), nullptr);
  return d;
}

// What is wrong with `field` as a name or token (a character that cannot stand in one), or empty.
std::string Unprintable(std::string_view field) {
  const size_t k = credentials::FirstNonTokenCharacter(field);
  return k == std::string_view::npos ? "" : credentials::NonPrintableAt(field, k);
}

}  // namespace

bool IsLoopbackListen(std::string_view listen) {
  const size_t colon = listen.rfind(':');
  std::string host(colon == std::string_view::npos ? listen : listen.substr(0, colon));
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  if (absl::AsciiStrToLower(host) == "localhost") return true;
  in_addr v4{};
  if (inet_pton(AF_INET, host.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  if (inet_pton(AF_INET6, host.c_str(), &v6) == 1) {
    if (IN6_IS_ADDR_LOOPBACK(&v6)) return true;
    return IN6_IS_ADDR_V4MAPPED(&v6) && v6.s6_addr[12] == 127;
  }
  return false;
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(const TlsSettings& tls,
                                                                              const std::string& listen) {
  if (tls.cert.empty() != tls.key.empty()) {
    const char* given = tls.cert.empty() ? "tls.key" : "tls.cert";
    const char* missing = tls.cert.empty() ? "tls.cert" : "tls.key";
    return absl::InvalidArgumentError(absl::StrCat(given, " is given without ", missing,
                                                   ": TLS needs both tls.cert (the certificate chain) and tls.key "
                                                   "(its private key)"));
  }
  if (tls.cert.empty()) {
    if (!tls.client_ca.empty()) {
      return absl::InvalidArgumentError(
          "tls.client_ca is given without tls.cert and tls.key: client certificates need TLS, which needs both");
    }
    if (IsLoopbackListen(listen) || tls.insecure) return grpc::InsecureServerCredentials();
    return absl::FailedPreconditionError(absl::StrCat(
        "refusing to serve plaintext on ", listen,
        ", which is not a loopback address: give tls.cert and tls.key (--tls-cert, --tls-key), or set "
        "tls.insecure = true (--insecure) to serve plaintext there anyway"));
  }

  absl::StatusOr<std::string> cert = credentials::ReadCredentialFile(tls.cert, "tls.cert");
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::string> key = credentials::ReadCredentialFile(tls.key, "tls.key");
  if (!key.ok()) return key.status();
  switch (credentials::CheckKeyPair(*cert, *key)) {
    case credentials::KeyPairCheck::kGood:
      break;
    case credentials::KeyPairCheck::kNoCertificate:
      return absl::InvalidArgumentError(absl::StrCat("tls.cert: ", tls.cert, ": not a PEM certificate"));
    case credentials::KeyPairCheck::kEncryptedKey:
      return absl::InvalidArgumentError(
          absl::StrCat("tls.key: ", tls.key, ": the key is encrypted: give it without a passphrase"));
    case credentials::KeyPairCheck::kNotAKey:
      return absl::InvalidArgumentError(absl::StrCat("tls.key: ", tls.key, ": not a PEM private key"));
    case credentials::KeyPairCheck::kKeyMismatch:
      return absl::InvalidArgumentError(absl::StrCat("tls.key: ", tls.key, ": the key does not match the certificate in ",
                                                     tls.cert, " (tls.cert)"));
  }

  grpc::SslServerCredentialsOptions options(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  options.pem_key_cert_pairs.push_back({*key, *cert});
  if (!tls.client_ca.empty()) {
    absl::StatusOr<std::string> ca = credentials::ReadCredentialFile(tls.client_ca, "tls.client_ca");
    if (!ca.ok()) return ca.status();
    if (credentials::PemCertificates(*ca).empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat("tls.client_ca: ", tls.client_ca, ": not a PEM CA bundle (no PEM certificate in it)"));
    }
    options.pem_root_certs = *ca;
    options.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(options);
}

absl::StatusOr<std::vector<TokenStore::Entry>> TokenStore::Parse(const std::string& path) {
  absl::StatusOr<std::string> text = credentials::ReadCredentialFile(path, "");
  if (!text.ok()) return text.status();
  std::vector<Entry> entries;
  std::map<std::string, int> name_line;
  std::map<std::array<uint8_t, 32>, size_t> token_entry;  // digest -> index in entries
  std::vector<int> entry_line;
  for (const auto& [line_no, line] : credentials::Lines(*text)) {
    std::vector<std::string_view> fields;
    for (size_t k = 0; k < line.size();) {
      while (k < line.size() && IsSpace(line[k])) ++k;
      const size_t start = k;
      while (k < line.size() && !IsSpace(line[k])) ++k;
      if (k > start) fields.push_back(line.substr(start, k - start));
    }
    if (fields.empty() || fields.front().front() == '#') continue;
    const std::string at = absl::StrCat(path, ":", line_no, ": ");
    if (std::string bad = Unprintable(fields[0]); !bad.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(at, "the tenant's name has ", bad));
    }
    const std::string name(fields[0]);
    if (name.size() > 64) {
      return absl::InvalidArgumentError(absl::StrCat(at, "the tenant's name is ", name.size(),
                                                     " characters long: at most 64 are allowed"));
    }
    if (fields.size() == 1) {
      return absl::InvalidArgumentError(absl::StrCat(at, "'", name, "' has no token: expected `name token`"));
    }
    if (fields.size() > 2) {
      return absl::InvalidArgumentError(absl::StrCat(
          at, "expected `name token`, found ", fields.size(),
          " fields (a token has no spaces; a comment goes on a line of its own, starting with #)"));
    }
    const std::string_view token = fields[1];
    if (token.size() < credentials::kMinTokenLength || token.size() > credentials::kMaxTokenLength) {
      return absl::InvalidArgumentError(absl::StrCat(at, "the token of '", name, "' is ", token.size(),
                                                     " characters long: a token has 16 to 256"));
    }
    if (std::string bad = Unprintable(token); !bad.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(at, "the token of '", name, "' has ", bad));
    }
    if (auto it = name_line.find(name); it != name_line.end()) {
      return absl::InvalidArgumentError(
          absl::StrCat(at, "'", name, "' is listed twice (also on line ", it->second, ")"));
    }
    const std::array<uint8_t, 32> digest = Sha256(token);
    if (auto it = token_entry.find(digest); it != token_entry.end()) {
      return absl::InvalidArgumentError(absl::StrCat(at, "the token of '", name, "' is the token of '",
                                                     entries[it->second].name, "' (line ", entry_line[it->second],
                                                     "): each tenant needs a token of its own"));
    }
    name_line[name] = line_no;
    token_entry[digest] = entries.size();
    entry_line.push_back(line_no);
    entries.push_back(Entry{name, digest});
  }
  return entries;
}

absl::StatusOr<std::shared_ptr<TokenStore>> TokenStore::Load(const std::string& path) {
  absl::StatusOr<std::vector<Entry>> entries = Parse(path);
  if (!entries.ok()) return entries.status();
  std::shared_ptr<TokenStore> store(new TokenStore(path));
  store->entries_ = std::move(*entries);
  return store;
}

absl::Status TokenStore::Reload() {
  absl::StatusOr<std::vector<Entry>> entries = Parse(path_);
  if (!entries.ok()) return entries.status();
  std::unique_lock lock(mu_);
  entries_ = std::move(*entries);
  return absl::OkStatus();
}

size_t TokenStore::size() const {
  std::shared_lock lock(mu_);
  return entries_.size();
}

std::optional<std::string> TokenStore::TenantFor(std::string_view token) const {
  const std::array<uint8_t, 32> digest = Sha256(token);
  std::shared_lock lock(mu_);
  // Every entry is compared, whichever matches: the time taken says nothing about the token.
  size_t found = entries_.size();
  for (size_t k = 0; k < entries_.size(); ++k) {
    const int differs = CRYPTO_memcmp(digest.data(), entries_[k].digest.data(), digest.size());
    found = differs == 0 ? k : found;
  }
  if (found == entries_.size()) return std::nullopt;
  return entries_[found].name;
}

std::optional<std::string> BearerToken(const Metadata& metadata) {
  const auto [first, last] = metadata.equal_range("authorization");
  for (auto it = first; it != last; ++it) {
    std::string_view v(it->second.data(), it->second.size());
    while (!v.empty() && IsSpace(v.front())) v.remove_prefix(1);
    while (!v.empty() && IsSpace(v.back())) v.remove_suffix(1);
    constexpr std::string_view kScheme = "bearer";
    if (v.size() <= kScheme.size() || strncasecmp(v.data(), kScheme.data(), kScheme.size()) != 0 ||
        !IsSpace(v[kScheme.size()])) {
      continue;
    }
    v.remove_prefix(kScheme.size());
    while (!v.empty() && IsSpace(v.front())) v.remove_prefix(1);
    if (!v.empty()) return std::string(v);
  }
  return std::nullopt;
}

absl::StatusOr<std::string> Authenticate(const TokenStore& tokens, const Metadata& metadata) {
  const std::optional<std::string> token = BearerToken(metadata);
  if (!token.has_value()) return absl::UnauthenticatedError("missing bearer token");
  std::optional<std::string> tenant = tokens.TenantFor(*token);
  if (!tenant.has_value()) return absl::UnauthenticatedError("unknown token");
  return *std::move(tenant);
}

absl::StatusOr<std::string> ReadSecretLine(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return absl::NotFoundError(absl::StrCat(path, ": is a folder, not a file"));
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot read: ", std::strerror(errno)));
  std::string line;
  std::getline(in, line);
  const std::string trimmed(absl::StripAsciiWhitespace(line));
  if (trimmed.empty()) return absl::InvalidArgumentError(absl::StrCat(path, ": the first line is empty"));
  return trimmed;
}

}  // namespace vistream::server
