#pragma once
// The files that say who may talk to whom, read one way on both sides of the connection: PEM
// certificates and private keys (the server's tls.cert, tls.key and tls.client_ca,
// server/security.h; the client's --tls-ca, --tls-cert and --tls-key,
// client/channel_security.h) and token files (the server's `name token` lines of auth.tokens,
// the client's --token-file). What is wrong is named by the caller (a configuration key or a
// command-line option): these functions say what they found, the callers word it.

#include <cstddef>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>
#include <openssl/evp.h>
#include <openssl/x509.h>

namespace vistream::credentials {

struct OpenSslFree {
  void operator()(X509* x) const { X509_free(x); }
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
using Certificate = std::unique_ptr<X509, OpenSslFree>;
using PrivateKey = std::unique_ptr<EVP_PKEY, OpenSslFree>;

// The whole of the file `path` (bytes, as they are). Errors: INVALID_ARGUMENT
// "NAME: PATH: cannot read: why" (`name` empty: "PATH: cannot read: why"), naming the
// configuration key or option that gave the path.
absl::StatusOr<std::string> ReadCredentialFile(const std::string& path, std::string_view name);

// The PEM certificates in `pem`, in order; none when it holds no PEM certificate. Leaves no
// error on OpenSSL's queue.
std::vector<Certificate> PemCertificates(std::string_view pem);

// The PEM private key in `pem`, or null when there is none. An encrypted key is never
// prompted for: it gives null with *encrypted set (`encrypted` must not be null).
PrivateKey PemPrivateKey(std::string_view pem, bool* encrypted);

// What a certificate chain and its private key (PEM text of both) are worth for TLS.
enum class KeyPairCheck {
  kGood,            // the key is the private key of the chain's first certificate
  kNoCertificate,   // `cert_pem` holds no PEM certificate
  kNotAKey,         // `key_pem` holds no PEM private key
  kEncryptedKey,    // the key is encrypted (a passphrase would be needed)
  kKeyMismatch,     // the key is not the first certificate's
};
KeyPairCheck CheckKeyPair(std::string_view cert_pem, std::string_view key_pem);

// ---- token files ----

// A token is 16 to 256 printable ASCII characters (0x21 to 0x7e), without spaces.
inline constexpr size_t kMinTokenLength = 16;
inline constexpr size_t kMaxTokenLength = 256;

// One line of a text file: its number (from 1) and its text, without the line end ("\n" or
// "\r\n"). A final line without a line end counts; nothing after the last line end does.
struct TextLine {
  int number = 0;
  std::string_view text;
};
// The lines of `text` (views into it: `text` must outlive them).
std::vector<TextLine> Lines(std::string_view text);

// Whether `c` may stand in a tenant's name or a token: printable ASCII, no space.
inline bool TokenCharacter(unsigned char c) { return c > 0x20 && c < 0x7f; }
// The index of the first character of `field` that is not a TokenCharacter; npos when none.
size_t FirstNonTokenCharacter(std::string_view field);
// "a non-printable character (byte 0xHH) at character N" for the character at index `k` of
// `field` (N counts from 1), for messages; `k` < field.size().
std::string NonPrintableAt(std::string_view field, size_t k);

}  // namespace vistream::credentials
