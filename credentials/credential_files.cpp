#include "credentials/credential_files.h"

#include <cerrno>
#include <cstdio>
#include <cstring>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/pem.h>

namespace vistream::credentials {

namespace {

struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
using Bio = std::unique_ptr<BIO, BioFree>;

Bio MemoryBio(std::string_view text) { return Bio(BIO_new_mem_buf(text.data(), static_cast<int>(text.size()))); }

// A passphrase callback that refuses (an encrypted key is reported, never prompted for).
int RefusePassphrase(char*, int, int, void* asked) {
  *static_cast<bool*>(asked) = true;
  return -1;
}

}  // namespace

absl::StatusOr<std::string> ReadCredentialFile(const std::string& path, std::string_view name) {
  const std::string prefix = name.empty() ? path : absl::StrCat(std::string(name), ": ", path);
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

std::vector<Certificate> PemCertificates(std::string_view pem) {
  std::vector<Certificate> out;
  Bio bio = MemoryBio(pem);
  while (X509* x = PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr)) out.emplace_back(x);
  ERR_clear_error();  // the read that found no more
  return out;
}

PrivateKey PemPrivateKey(std::string_view pem, bool* encrypted) {
  Bio bio = MemoryBio(pem);
  PrivateKey key(PEM_read_bio_PrivateKey(bio.get(), nullptr, RefusePassphrase, encrypted));
  ERR_clear_error();
  return key;
}

KeyPairCheck CheckKeyPair(std::string_view cert_pem, std::string_view key_pem) {
  const std::vector<Certificate> chain = PemCertificates(cert_pem);
  if (chain.empty()) return KeyPairCheck::kNoCertificate;
  bool encrypted = false;
  const PrivateKey key = PemPrivateKey(key_pem, &encrypted);
  if (key == nullptr) return encrypted ? KeyPairCheck::kEncryptedKey : KeyPairCheck::kNotAKey;
  if (X509_check_private_key(chain.front().get(), key.get()) != 1) {
    ERR_clear_error();
    return KeyPairCheck::kKeyMismatch;
  }
  return KeyPairCheck::kGood;
}

std::vector<TextLine> Lines(std::string_view text) {
  std::vector<TextLine> out;
  int number = 0;
  for (size_t begin = 0; begin < text.size();) {
    size_t end = text.find('\n', begin);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(begin, end - begin);
    begin = end + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    out.push_back(TextLine{++number, line});
  }
  return out;
}

size_t FirstNonTokenCharacter(std::string_view field) {
  for (size_t k = 0; k < field.size(); ++k) {
    if (!TokenCharacter(static_cast<unsigned char>(field[k]))) return k;
  }
  return std::string_view::npos;
}

std::string NonPrintableAt(std::string_view field, size_t k) {
  return absl::StrFormat("a non-printable character (byte 0x%02x) at character %d",
                         static_cast<unsigned char>(field[k]), k + 1);
}

}  // namespace vistream::credentials
