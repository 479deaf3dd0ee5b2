#include "client/channel_security.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <vector>

#include <absl/strings/match.h>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include "credentials/credential_files.h"

namespace vistream::client {

namespace {

struct Freer {
  void operator()(SSL_CTX* c) const { SSL_CTX_free(c); }
  void operator()(SSL* s) const { SSL_free(s); }
};
template <typename T>
using Owned = std::unique_ptr<T, Freer>;

using credentials::PemCertificates;

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r'; }

absl::StatusOr<std::string> ReadToken(const std::string& path) {
  absl::StatusOr<std::string> text = credentials::ReadCredentialFile(path, "--token-file");
  if (!text.ok()) return text.status();
  for (auto [line_no, line] : credentials::Lines(*text)) {
    while (!line.empty() && IsSpace(line.front())) line.remove_prefix(1);
    while (!line.empty() && IsSpace(line.back())) line.remove_suffix(1);
    if (line.empty() || line.front() == '#') continue;
    const std::string at = absl::StrCat("--token-file: ", path, ":", line_no, ": ");
    if (const size_t k = credentials::FirstNonTokenCharacter(line); k != std::string_view::npos) {
      if (line[k] == ' ' || line[k] == '\t') {
        return absl::InvalidArgumentError(
            absl::StrCat(at, "more than a token on the line (a space at character ", k + 1,
                         "): the file holds the token alone"));
      }
      return absl::InvalidArgumentError(absl::StrCat(at, "the token has ", credentials::NonPrintableAt(line, k)));
    }
    if (line.size() < credentials::kMinTokenLength || line.size() > credentials::kMaxTokenLength) {
      return absl::InvalidArgumentError(
          absl::StrCat(at, "the token is ", line.size(), " characters long: a token has 16 to 256"));
    }
    return std::string(line);
  }
  return absl::InvalidArgumentError(
      absl::StrCat("--token-file: ", path,
                   ": no token in it: the file holds the token alone on its first line (# comments allowed)"));
}

// A TCP connection to `host`:`port` within `timeout_s`, with reads and writes that time out
// as well; -1 when none.
int ConnectTcp(const std::string& host, const std::string& port, double timeout_s) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (getaddrinfo(host.c_str(), port.c_str(), &hints, &found) != 0) return -1;
  int fd = -1;
  for (addrinfo* a = found; a != nullptr && fd < 0; a = a->ai_next) {
    fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) continue;
    const int flags = fcntl(fd, F_GETFL);
    fcntl(fd, F_SETFL, flags | O_NONBLOCK);
    bool ok = connect(fd, a->ai_addr, a->ai_addrlen) == 0;
    if (!ok && errno == EINPROGRESS) {
      pollfd p{fd, POLLOUT, 0};
      int err = 0;
      socklen_t len = sizeof(err);
      ok = poll(&p, 1, static_cast<int>(timeout_s * 1000)) == 1 &&
           getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0;
    }
    if (!ok) {
      close(fd);
      fd = -1;
      continue;
    }
    fcntl(fd, F_SETFL, flags);
    const auto whole = static_cast<time_t>(timeout_s);
    timeval tv{whole, static_cast<suseconds_t>((timeout_s - static_cast<double>(whole)) * 1e6)};
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
    setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof(tv));
  }
  freeaddrinfo(found);
  return fd;
}

// OpenSSL's reasons for the last failure, "; "-separated (e.g. "tlsv13 alert certificate required").
std::string SslReasons() {
  std::string out;
  while (const unsigned long e = ERR_get_error()) {
    const char* r = ERR_reason_error_string(e);
    if (r == nullptr) continue;
    if (!out.empty()) out += "; ";
    out += r;
  }
  return out;
}

// Set when the server asked for a client certificate and the handshake had none to give.
thread_local bool t_certificate_requested = false;
int NoteCertificateRequest(SSL*, X509**, EVP_PKEY**) {
  t_certificate_requested = true;
  return 0;  // none
}

}  // namespace

absl::StatusOr<ChannelSecurity> LoadChannelSecurity(const std::string& ca_file, const std::string& cert_file,
                                                    const std::string& key_file, const std::string& token_file) {
  ChannelSecurity s;
  if (cert_file.empty() != key_file.empty()) {
    return absl::InvalidArgumentError(cert_file.empty()
                                          ? "--tls-key: needs --tls-cert (the certificate of the key)"
                                          : "--tls-cert: needs --tls-key (the certificate's private key)");
  }
  if (!cert_file.empty() && ca_file.empty()) {
    return absl::InvalidArgumentError(
        "--tls-cert: needs --tls-ca (the CA that signed the server's certificate): a client certificate is sent "
        "over TLS only");
  }
  if (!ca_file.empty()) {
    absl::StatusOr<std::string> ca = credentials::ReadCredentialFile(ca_file, "--tls-ca");
    if (!ca.ok()) return ca.status();
    if (PemCertificates(*ca).empty()) {
      return absl::InvalidArgumentError(absl::StrCat("--tls-ca: ", ca_file, ": not a PEM certificate (bundle)"));
    }
    s.tls_ca = *std::move(ca);
    s.tls_ca_file = ca_file;
  }
  if (!cert_file.empty()) {
    absl::StatusOr<std::string> cert = credentials::ReadCredentialFile(cert_file, "--tls-cert");
    if (!cert.ok()) return cert.status();
    absl::StatusOr<std::string> key = credentials::ReadCredentialFile(key_file, "--tls-key");
    if (!key.ok()) return key.status();
    switch (credentials::CheckKeyPair(*cert, *key)) {
      case credentials::KeyPairCheck::kGood:
        break;
      case credentials::KeyPairCheck::kNoCertificate:
        return absl::InvalidArgumentError(absl::StrCat("--tls-cert: ", cert_file, ": not a PEM certificate"));
      case credentials::KeyPairCheck::kEncryptedKey:
        return absl::InvalidArgumentError(
            absl::StrCat("--tls-key: ", key_file, ": the key is encrypted: give it without a passphrase"));
      case credentials::KeyPairCheck::kNotAKey:
        return absl::InvalidArgumentError(absl::StrCat("--tls-key: ", key_file, ": not a PEM private key"));
      case credentials::KeyPairCheck::kKeyMismatch:
        return absl::InvalidArgumentError(
            absl::StrCat("--tls-key: ", key_file, ": the key does not match the certificate in ", cert_file));
    }
    s.tls_cert = *std::move(cert);
    s.tls_key = *std::move(key);
    s.tls_cert_file = cert_file;
  }
  if (!token_file.empty()) {
    absl::StatusOr<std::string> token = ReadToken(token_file);
    if (!token.ok()) return token.status();
    s.token = *std::move(token);
    s.token_file = token_file;
  }
  return s;
}

std::shared_ptr<grpc::ChannelCredentials> ChannelCredentialsFor(const ChannelSecurity& security) {
  if (security.tls_ca.empty()) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = security.tls_ca;
  o.pem_cert_chain = security.tls_cert;
  o.pem_private_key = security.tls_key;
  return grpc::SslCredentials(o);
}

void Authorize(const ChannelSecurity& security, grpc::ClientContext* context) {
  if (!security.token.empty()) context->AddMetadata("authorization", "Bearer " + security.token);
}

std::string DiagnoseTls(const std::string& address, const ChannelSecurity& security, double timeout_s) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos) return "";
  std::string host = address.substr(0, colon);
  const std::string port = address.substr(colon + 1);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  const int fd = ConnectTcp(host, port, timeout_s);
  if (fd < 0) return "";  // nothing listens: not a TLS matter

  const bool tls = !security.tls_ca.empty();
  Owned<SSL_CTX> ctx(SSL_CTX_new(TLS_client_method()));
  if (ctx == nullptr) {
    close(fd);
    return "";
  }
  if (tls) {
    for (const credentials::Certificate& ca : PemCertificates(security.tls_ca)) {
      X509_STORE_add_cert(SSL_CTX_get_cert_store(ctx.get()), ca.get());
    }
    SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_PEER, nullptr);
  } else {
    SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_NONE, nullptr);
  }
  if (!security.tls_cert.empty()) {
    std::vector<credentials::Certificate> chain = PemCertificates(security.tls_cert);
    bool encrypted = false;
    credentials::PrivateKey key = credentials::PemPrivateKey(security.tls_key, &encrypted);
    if (!chain.empty() && key != nullptr) {
      SSL_CTX_use_certificate(ctx.get(), chain.front().get());
      for (size_t k = 1; k < chain.size(); ++k) SSL_CTX_add_extra_chain_cert(ctx.get(), chain[k].release());
      SSL_CTX_use_PrivateKey(ctx.get(), key.get());
    }
  }
  SSL_CTX_set_client_cert_cb(ctx.get(), NoteCertificateRequest);
  t_certificate_requested = false;
  static const unsigned char kAlpn[] = {2, 'h', '2'};
  SSL_CTX_set_alpn_protos(ctx.get(), kAlpn, sizeof(kAlpn));
  Owned<SSL> ssl(SSL_new(ctx.get()));
  SSL_set_fd(ssl.get(), fd);
  in6_addr ip{};
  const bool is_ip = inet_pton(AF_INET, host.c_str(), &ip) == 1 || inet_pton(AF_INET6, host.c_str(), &ip) == 1;
  if (!is_ip) SSL_set_tlsext_host_name(ssl.get(), host.c_str());
  if (tls) SSL_set1_host(ssl.get(), host.c_str());  // the name (or IP address) the certificate must be for
  ERR_clear_error();
  bool failed = SSL_connect(ssl.get()) != 1;
  std::string reasons = SslReasons();
  if (!failed) {
    // TLS 1.3: a server that wants a client certificate says so just after the handshake.
    char byte = 0;
    const int n = SSL_read(ssl.get(), &byte, 1);
    if (n <= 0 && SSL_get_error(ssl.get(), n) == SSL_ERROR_SSL) {
      failed = true;
      reasons = SslReasons();
    }
    ERR_clear_error();
  }
  const bool peer_certificate = SSL_get0_peer_certificate(ssl.get()) != nullptr;
  const long verify = SSL_get_verify_result(ssl.get());
  ssl.reset();
  close(fd);

  if (!tls) {
    if (peer_certificate || !failed || absl::StrContains(reasons, "alert")) {
      return "it expects a TLS handshake and this client speaks plaintext: give --tls-ca FILE (the CA that signed "
             "the server's certificate)";
    }
    return "";
  }
  if (verify != X509_V_OK) {
    return absl::StrCat("TLS handshake failed: the server's certificate is not trusted by --tls-ca ",
                        security.tls_ca_file, " (", X509_verify_cert_error_string(verify),
                        "): give --tls-ca the CA that signed it");
  }
  if (!failed) return "";
  // A server that requires a client certificate ends the handshake, often without an alert
  // (gRPC's servers just close), once it has asked for one and got none.
  if (t_certificate_requested) {
    return absl::StrCat("TLS handshake failed: the server requires a client certificate (mutual TLS; ", reasons,
                        "): give --tls-cert and --tls-key");
  }
  if (!security.tls_cert.empty() && peer_certificate) {
    return absl::StrCat("TLS handshake failed: the server refused the client certificate in ", security.tls_cert_file,
                        " (", reasons, "): give --tls-cert a certificate signed by a CA the server trusts");
  }
  if (!peer_certificate) {
    return absl::StrCat("TLS handshake failed: the server does not answer in TLS (",
                        reasons.empty() ? std::string("it closed the connection") : reasons,
                        "): is it a plaintext server? Then leave out --tls-ca");
  }
  return absl::StrCat("TLS handshake failed: ", reasons);
}

absl::Status ExplainRefusal(const absl::Status& status, const ChannelSecurity& security, const std::string& address) {
  if (status.code() != absl::StatusCode::kUnauthenticated) return status;
  if (security.token.empty()) {
    return absl::UnauthenticatedError(absl::StrCat("the server at ", address, " requires a token (", status.message(),
                                                   "): give --token-file FILE, a file that holds the token"));
  }
  return absl::UnauthenticatedError(absl::StrCat("the server at ", address, " refused the token in ",
                                                 security.token_file, " (", status.message(),
                                                 "): check --token-file (the token may have been revoked)"));
}

}  // namespace vistream::client
