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
#include <openssl/bio.h>
#include <openssl/crypto.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

namespace vistream::server {

namespace {

// The whole of `path`, or "KEY: PATH: cannot read: why" (KEY empty: "PATH: cannot read: why").
absl::StatusOr<std::string> ReadWhole(const std::string& path, const std::string& key) {
  const std::string prefix = key.empty() ? path : absl::StrCat(key, ": ", path);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return absl::InvalidArgumentError(absl::StrCat(prefix, ": cannot read: ", std::strerror(errno)));
  std::string text;
  char buf[8192];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), f)) > 0;) text.append(buf, n);
  const bool failed = std::ferror(f) != 0;
  const int err = errno;
  std::fclose(f);
  if (failed) return absl::InvalidArgumentError(absl::StrCat(prefix, ": cannot read: ", std::strerror(err)));
  return text;
}

struct BioDeleter {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Deleter {
  void operator()(X509* x) const { X509_free(x); }
};
struct KeyDeleter {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
using Bio = std::unique_ptr<BIO, BioDeleter>;
using Cert = std::unique_ptr<X509, X509Deleter>;

Bio MemoryBio(const std::string& text) { return Bio(BIO_new_mem_buf(text.data(), static_cast<int>(text.size()))); }

// The PEM certificates in `text`, in order (none: not PEM certificates).
std::vector<Cert> PemCertificates(const std::string& text) {
  std::vector<Cert> out;
  Bio bio = MemoryBio(text);
  while (X509* x = PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr)) out.emplace_back(x);
  ERR_clear_error();  // the read that found no more
  return out;
}

// A passphrase callback that refuses (an encrypted key is reported, never prompted for).
int RefusePassphrase(char*, int, int, void* asked) {
  *static_cast<bool*>(asked) = true;
  return -1;
}

bool IsSpace(char c) { return c == ' ' || c == '\t'; }
bool Printable(unsigned char c) { return c > 0x20 && c < 0x7f; }

std::array<uint8_t, 32> Sha256(std::string_view text) {
  std::array<uint8_t, 32> d{};
  unsigned int n = 0;
  EVP_Digest(text.data(), text.size(), d.data(), &n, EVP_sha256(), nullptr);
  return d;
}

// What is wrong with `field` as a name (max 64) or token (16 to 256), or empty.
std::string Unprintable(std::string_view field) {
  for (size_t k = 0; k < field.size(); ++k) {
    const auto c = static_cast<unsigned char>(field[k]);
    if (!Printable(c)) return absl::StrFormat("a non-printable character (byte 0x%02x) at character %d", c, k + 1);
  }
  return "";
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

  absl::StatusOr<std::string> cert = ReadWhole(tls.cert, "tls.cert");
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::string> key = ReadWhole(tls.key, "tls.key");
  if (!key.ok()) return key.status();
  const std::vector<Cert> chain = PemCertificates(*cert);
  if (chain.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("tls.cert: ", tls.cert, ": not a PEM certificate"));
  }
  bool asked = false;
  Bio key_bio = MemoryBio(*key);
  std::unique_ptr<EVP_PKEY, KeyDeleter> pkey(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, RefusePassphrase, &asked));
  ERR_clear_error();
  if (pkey == nullptr) {
    return absl::InvalidArgumentError(
        asked ? absl::StrCat("tls.key: ", tls.key, ": the key is encrypted: give it without a passphrase")
              : absl::StrCat("tls.key: ", tls.key, ": not a PEM private key"));
  }
  if (X509_check_private_key(chain.front().get(), pkey.get()) != 1) {
    ERR_clear_error();
    return absl::InvalidArgumentError(absl::StrCat("tls.key: ", tls.key, ": the key does not match the certificate in ",
                                                   tls.cert, " (tls.cert)"));
  }

  grpc::SslServerCredentialsOptions options(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  options.pem_key_cert_pairs.push_back({*key, *cert});
  if (!tls.client_ca.empty()) {
    absl::StatusOr<std::string> ca = ReadWhole(tls.client_ca, "tls.client_ca");
    if (!ca.ok()) return ca.status();
    if (PemCertificates(*ca).empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat("tls.client_ca: ", tls.client_ca, ": not a PEM CA bundle (no PEM certificate in it)"));
    }
    options.pem_root_certs = *ca;
    options.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(options);
}

absl::StatusOr<std::vector<TokenStore::Entry>> TokenStore::Parse(const std::string& path) {
  absl::StatusOr<std::string> text = ReadWhole(path, "");
  if (!text.ok()) return text.status();
  std::vector<Entry> entries;
  std::map<std::string, int> name_line;
  std::map<std::array<uint8_t, 32>, size_t> token_entry;  // digest -> index in entries
  std::vector<int> entry_line;
  int line_no = 0;
  for (size_t begin = 0; begin < text->size();) {
    size_t end = text->find('\n', begin);
    if (end == std::string::npos) end = text->size();
    std::string_view line(text->data() + begin, end - begin);
    begin = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
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
    if (token.size() < 16 || token.size() > 256) {
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
