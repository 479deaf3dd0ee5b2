#pragma once
// Little-endian byte strings for the files visibility results are saved to: a writer, and a
// reader whose every failure names the source and the byte offset.

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>

#include <absl/status/status.h>
#include <absl/strings/str_cat.h>

namespace vistream::visibility {

class ByteWriter {
 public:
  // Appends each value's bytes, in order.
  template <typename T, typename... More>
  void Put(T value, More... more) {
    static_assert(std::is_trivially_copyable_v<T>);
    char b[sizeof(T)];
    std::memcpy(b, &value, sizeof(T));
    out_.append(b, sizeof(T));
    if constexpr (sizeof...(More) > 0) Put(more...);
  }
  void PutVarint(uint64_t v) {
    while (v >= 0x80) {
      out_.push_back(static_cast<char>((v & 0x7f) | 0x80));
      v >>= 7;
    }
    out_.push_back(static_cast<char>(v));
  }
  void PutString(std::string_view s) {
    PutVarint(s.size());
    out_.append(s);
  }
  void PutRaw(std::string_view s) { out_.append(s); }
  std::string& bytes() { return out_; }

 private:
  std::string out_;
};

class ByteReader {
 public:
  ByteReader(std::string_view bytes, std::string where) : in_(bytes), where_(std::move(where)) {}

  // Reads `value`, then each further (pointer, what) pair in order; stops at the first that the
  // bytes cannot hold, with "truncated while reading <its what>".
  template <typename T, typename... More>
  absl::Status Get(T* value, const std::string& what, More... more) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (in_.size() - pos_ < sizeof(T)) return Truncated(what);
    std::memcpy(value, in_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    if constexpr (sizeof...(More) > 0) return Get(more...);
    return absl::OkStatus();
  }
  absl::Status GetVarint(uint64_t* value, const std::string& what) {
    uint64_t v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (pos_ >= in_.size()) return Truncated(what);
      const auto b = static_cast<uint8_t>(in_[pos_++]);
      if (shift == 63 && b > 1) return Error(absl::StrCat(what, ": varint overflows 64 bits"));
      v |= static_cast<uint64_t>(b & 0x7f) << shift;
      if ((b & 0x80) == 0) {
        *value = v;
        return absl::OkStatus();
      }
    }
    return Error(absl::StrCat(what, ": varint longer than 10 bytes"));
  }
  absl::Status GetString(std::string* s, const std::string& what, size_t max_size) {
    uint64_t n = 0;
    if (absl::Status st = GetVarint(&n, what); !st.ok()) return st;
    if (n > max_size) return Error(absl::StrCat(what, ": length ", n, " exceeds ", max_size));
    if (in_.size() - pos_ < n) return Truncated(what);
    s->assign(in_.data() + pos_, n);
    pos_ += n;
    return absl::OkStatus();
  }
  // Reads the magic that opens a file of `kind` ("PVS file"): an error naming the source when
  // the bytes end first (while reading "the magic"), else when they are not `magic`
  // ("<where>: not a vistream <kind> (no <magic> magic)").
  absl::Status ExpectMagic(std::string_view magic, std::string_view kind) {
    std::string read(magic.size(), '\0');
    for (char& ch : read) {
      if (absl::Status st = Get(&ch, "the magic"); !st.ok()) return st;
    }
    if (read != magic) {
      return absl::InvalidArgumentError(
          absl::StrCat(where_, ": not a vistream ", std::string(kind), " (no ", std::string(magic), " magic)"));
    }
    return absl::OkStatus();
  }
  bool AtEnd() const { return pos_ == in_.size(); }
  size_t remaining() const { return in_.size() - pos_; }
  size_t offset() const { return pos_; }
  // An InvalidArgument error naming the source and the current offset.
  absl::Status Error(const std::string& message) const {
    return absl::InvalidArgumentError(absl::StrCat(where_, ": byte ", pos_, ": ", message));
  }

 private:
  absl::Status Truncated(const std::string& what) const {
    return Error(absl::StrCat("truncated while reading ", what));
  }
  std::string_view in_;
  size_t pos_ = 0;
  std::string where_;
};

}  // namespace vistream::visibility
