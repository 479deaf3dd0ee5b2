#include "server/server_config.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_join.h>
#include <toml++/toml.h>

namespace vistream::server {

namespace {

namespace fs = std::filesystem;

const char* TypeName(const toml::node& n) {
  switch (n.type()) {
    case toml::node_type::string: return "a string";
    case toml::node_type::integer: return "a whole number";
    case toml::node_type::floating_point: return "a number with a fraction";
    case toml::node_type::boolean: return "true or false";
    case toml::node_type::table: return "a table";
    case toml::node_type::array: return "an array";
    case toml::node_type::date: return "a date";
    case toml::node_type::time: return "a time";
    case toml::node_type::date_time: return "a date-time";
    default: return "nothing";
  }
}

int LineOf(const toml::node& n) { return static_cast<int>(n.source().begin.line); }

std::string Format(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

// Reads one table's keys into a ServerConfig, each by its handler; any other key is an error.
class Reader {
 public:
  Reader(std::string path, fs::path base) : path_(std::move(path)), base_(std::move(base)) {}

  absl::Status Error(int line, const std::string& key, const std::string& what) const {
    return absl::InvalidArgumentError(absl::StrCat(path_, ":", line, ": ", key, ": ", what));
  }

  using Handler = std::function<absl::Status(const toml::node&, const std::string& key)>;
  struct Key {
    const char* name;
    Handler read;
  };

  // Runs each key of `table` through its handler; `prefix` is the table's dotted name.
  absl::Status Table(const toml::table& table, const std::string& prefix, const std::vector<Key>& keys) const {
    for (auto&& [k, node] : table) {
      const std::string name(k.str());
      const std::string dotted = prefix.empty() ? name : prefix + "." + name;
      const Key* found = nullptr;
      for (const Key& key : keys) {
        if (name == key.name) found = &key;
      }
      if (found == nullptr) {
        std::vector<std::string> known;
        for (const Key& key : keys) known.emplace_back(key.name);
        const int line = k.source().begin.line != 0 ? static_cast<int>(k.source().begin.line) : LineOf(node);
        // TOML puts every key after a [table] header into that table: a top-level key written
        // below one lands there.
        static const char* const kTopLevel[] = {"listen", "threads", "max_sessions", "catalog", "grace_s", "drain_s"};
        const bool top_level = !prefix.empty() && std::find(std::begin(kTopLevel), std::end(kTopLevel), name) !=
                                                      std::end(kTopLevel);
        return Error(line, dotted,
                     absl::StrCat("unknown key (", prefix.empty() ? "top level" : "[" + prefix + "]",
                                  " keys: ", absl::StrJoin(known, ", "), ")",
                                  top_level ? "; top-level keys go above the first [table] in the file" : ""));
      }
      if (absl::Status st = found->read(node, dotted); !st.ok()) return st;
    }
    return absl::OkStatus();
  }

  Handler String(std::string* out) const {
    return [this, out](const toml::node& n, const std::string& key) -> absl::Status {
      if (!n.is_string()) return Error(LineOf(n), key, absl::StrCat("expected a string, got ", TypeName(n)));
      *out = *n.value<std::string>();
      return absl::OkStatus();
    };
  }
  // One of `allowed`.
  Handler Choice(std::string* out, std::vector<std::string> allowed) const {
    return [this, out, allowed](const toml::node& n, const std::string& key) -> absl::Status {
      if (!n.is_string()) return Error(LineOf(n), key, absl::StrCat("expected a string, got ", TypeName(n)));
      const std::string v = *n.value<std::string>();
      for (const std::string& a : allowed) {
        if (v == a) {
          *out = v;
          return absl::OkStatus();
        }
      }
      return Error(LineOf(n), key, absl::StrCat("'", v, "' is not one of ", absl::StrJoin(allowed, ", ")));
    };
  }
  Handler Bool(bool* out) const {
    return [this, out](const toml::node& n, const std::string& key) -> absl::Status {
      if (!n.is_boolean()) return Error(LineOf(n), key, absl::StrCat("expected true or false, got ", TypeName(n)));
      *out = *n.value<bool>();
      return absl::OkStatus();
    };
  }
  template <typename T>
  Handler Whole(T* out, int64_t lo, int64_t hi) const {
    return [this, out, lo, hi](const toml::node& n, const std::string& key) -> absl::Status {
      if (!n.is_integer()) return Error(LineOf(n), key, absl::StrCat("expected a whole number, got ", TypeName(n)));
      const int64_t v = *n.value<int64_t>();
      if (v < lo || v > hi) return Error(LineOf(n), key, absl::StrCat(v, " is out of range (", lo, " to ", hi, ")"));
      *out = static_cast<T>(v);
      return absl::OkStatus();
    };
  }
  // A finite number in [lo, hi] (whole numbers allowed); `above_lo`: lo itself excluded.
  Handler Number(double* out, double lo, double hi, bool above_lo = false) const {
    return [this, out, lo, hi, above_lo](const toml::node& n, const std::string& key) -> absl::Status {
      if (!n.is_number()) return Error(LineOf(n), key, absl::StrCat("expected a number, got ", TypeName(n)));
      const double v = *n.value<double>();
      if (!std::isfinite(v) || v < lo || v > hi || (above_lo && v == lo)) {
        return Error(LineOf(n), key,
                     absl::StrCat(Format(v), " is out of range (", above_lo ? "above " : "", Format(lo), " to ",
                                  Format(hi), ")"));
      }
      *out = v;
      return absl::OkStatus();
    };
  }
  // A path to a file this process can read (relative: to the configuration file's folder);
  // empty allowed (the feature is off).
  Handler ReadableFile(std::string* out) const {
    return [this, out](const toml::node& n, const std::string& key) -> absl::Status {
      if (absl::Status st = String(out)(n, key); !st.ok()) return st;
      if (out->empty()) return absl::OkStatus();
      *out = Resolve(*out);
      std::error_code ec;
      if (!fs::is_regular_file(*out, ec)) return Error(LineOf(n), key, absl::StrCat(*out, ": no such file"));
      if (::access(out->c_str(), R_OK) != 0) return Error(LineOf(n), key, absl::StrCat(*out, ": cannot be read"));
      return absl::OkStatus();
    };
  }
  Handler Folder(std::string* out) const {
    return [this, out](const toml::node& n, const std::string& key) -> absl::Status {
      if (absl::Status st = String(out)(n, key); !st.ok()) return st;
      if (out->empty()) return absl::OkStatus();
      *out = Resolve(*out);
      std::error_code ec;
      if (!fs::is_directory(*out, ec)) return Error(LineOf(n), key, absl::StrCat(*out, ": no such folder"));
      return absl::OkStatus();
    };
  }
  // A file the server will append to: its folder must exist and be writable.
  Handler WritableFile(std::string* out) const {
    return [this, out](const toml::node& n, const std::string& key) -> absl::Status {
      if (absl::Status st = String(out)(n, key); !st.ok()) return st;
      if (out->empty()) return absl::OkStatus();
      *out = Resolve(*out);
      const fs::path p(*out);
      const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
      std::error_code ec;
      if (fs::is_directory(p, ec)) return Error(LineOf(n), key, absl::StrCat(*out, ": is a folder, not a file"));
      if (!fs::is_directory(dir, ec)) return Error(LineOf(n), key, absl::StrCat(dir.string(), ": no such folder"));
      const bool exists = fs::exists(p, ec);
      if (::access(exists ? out->c_str() : dir.c_str(), W_OK) != 0) {
        return Error(LineOf(n), key, absl::StrCat(*out, ": cannot be written"));
      }
      return absl::OkStatus();
    };
  }
  Handler Address(std::string* out, bool allow_empty) const {
    return [this, out, allow_empty](const toml::node& n, const std::string& key) -> absl::Status {
      if (absl::Status st = String(out)(n, key); !st.ok()) return st;
      if (allow_empty && out->empty()) return absl::OkStatus();
      if (!IsHostPort(*out)) {
        return Error(LineOf(n), key,
                     absl::StrCat("'", *out, "' is not host:port with a port from 0 to 65535 (e.g. 127.0.0.1:50051)"));
      }
      return absl::OkStatus();
    };
  }
  Handler Subtable(const std::vector<Key>& keys) const {
    return [this, keys](const toml::node& n, const std::string& key) -> absl::Status {
      if (!n.is_table()) return Error(LineOf(n), key, absl::StrCat("expected a table ([", key, "]), got ", TypeName(n)));
      return Table(*n.as_table(), key, keys);
    };
  }

 private:
  std::string Resolve(const std::string& p) const {
    if (p.empty() || fs::path(p).is_absolute()) return p;
    return (base_ / p).lexically_normal().string();
  }

  std::string path_;
  fs::path base_;
};

absl::Status ReadScenes(const Reader& r, const toml::node& n, const std::string& key, std::vector<SceneConfig>* out) {
  if (!n.is_array_of_tables()) {
    return r.Error(LineOf(n), key, absl::StrCat("expected [[scenes]] tables, got ", TypeName(n)));
  }
  const toml::array& scenes = *n.as_array();
  for (size_t k = 0; k < scenes.size(); ++k) {
    const toml::table& t = *scenes[k].as_table();
    SceneConfig s;
    s.line = LineOf(t);
    const std::string prefix = absl::StrCat("scenes[", k + 1, "]");
    const std::vector<Reader::Key> keys = {
        {"name", r.String(&s.name)},
        {"file", r.ReadableFile(&s.file)},
        {"pvs_file", r.ReadableFile(&s.pvs_file)},
        {"cell_size_m", [&](const toml::node& v, const std::string& name) -> absl::Status {
           if (absl::Status st = r.Number(&s.cell_size_m, 0.0, 1e6)(v, name); !st.ok()) return st;
           if (s.cell_size_m != 0.0 && s.cell_size_m < 0.01) {
             return r.Error(LineOf(v), name, absl::StrCat(Format(s.cell_size_m),
                                                          " is out of range (0: the catalog's, or 0.01 to 1e+06)"));
           }
           return absl::OkStatus();
         }},
        {"res", [&](const toml::node& v, const std::string& name) -> absl::Status {
           if (absl::Status st = r.Whole(&s.res, 1, 256)(v, name); !st.ok()) return st;
           if ((s.res & (s.res - 1)) != 0) {
             return r.Error(LineOf(v), name, absl::StrCat(s.res, " is not a power of two from 1 to 256"));
           }
           return absl::OkStatus();
         }},
        {"backend", r.Choice(&s.backend, {"cpu", "gl", "exact"})},
        {"cache_mb", r.Number(&s.cache_mb, 1.0, 1e6)},
    };
    if (absl::Status st = r.Table(t, prefix, keys); !st.ok()) return st;
    if (s.name.empty()) {
      return r.Error(s.line, prefix + ".name",
                     t.contains("name") ? "must not be empty" : "missing (every scene needs the name Hello gives)");
    }
    for (const SceneConfig& other : *out) {
      if (other.name == s.name) {
        return r.Error(s.line, prefix + ".name",
                       absl::StrCat("a second scene named '", s.name, "' (the first is at line ", other.line, ")"));
      }
    }
    out->push_back(std::move(s));
  }
  return absl::OkStatus();
}

}  // namespace

bool IsHostPort(std::string_view text) {
  const size_t colon = text.rfind(':');
  if (colon == std::string_view::npos || colon == 0) return false;
  const std::string_view port = text.substr(colon + 1);
  if (port.empty() || port.size() > 5) return false;
  int value = 0;
  for (char c : port) {
    if (c < '0' || c > '9') return false;
    value = value * 10 + (c - '0');
  }
  if (value > 65535) return false;
  const std::string_view host = text.substr(0, colon);
  if (host.front() == '[') return host.size() > 2 && host.back() == ']';
  return host.find(':') == std::string_view::npos && host.find(' ') == std::string_view::npos;
}

bool IsStoreAddress(std::string_view text) {
  if (text.rfind("unix:", 0) == 0) return text.size() > 5;
  return IsHostPort(text) && !text.ends_with(":0");
}

bool IsStoreKeyPrefix(std::string_view text) {
  return !text.empty() && text.find_first_of(" \t\r\n") == std::string_view::npos;
}

absl::StatusOr<ServerConfig> ParseServerConfig(std::string_view text, const std::string& path) {
  toml::table root;
  try {
    root = toml::parse(text, path);
  } catch (const toml::parse_error& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ":", e.source().begin.line, ":", e.source().begin.column,
                                                   ": ", std::string(e.description())));
  }
  ServerConfig c;
  c.path = path;
  const fs::path base = fs::path(path).has_parent_path() ? fs::path(path).parent_path() : fs::path(".");
  const Reader r(path, base);
  std::string log_format = "text";
  const std::vector<Reader::Key> keys = {
      {"listen", r.Address(&c.listen, false)},
      {"threads", r.Whole(&c.threads, 0, 1024)},
      {"max_sessions", r.Whole(&c.max_sessions, 1, 100000)},
      {"catalog", r.Folder(&c.catalog)},
      {"grace_s", r.Number(&c.grace_s, 0.0, 3600.0)},
      {"drain_s", r.Number(&c.drain_s, 0.0, 3600.0)},
      {"limits", r.Subtable({
                     {"hello_timeout_s", r.Number(&c.hello_timeout_s, 0.0, 86400.0)},
                     {"max_pose_rate_hz", r.Number(&c.max_pose_rate_hz, 0.1, 100000.0)},
                     {"max_sessions_per_address", r.Whole(&c.max_sessions_per_address, 0, 100000)},
                     {"max_sessions_per_token", r.Whole(&c.max_sessions_per_token, 0, 100000)},
                 })},
      {"tls", r.Subtable({
                  {"cert", r.ReadableFile(&c.tls_cert)},
                  {"key", r.ReadableFile(&c.tls_key)},
                  {"client_ca", r.ReadableFile(&c.tls_client_ca)},
                  {"insecure", r.Bool(&c.tls_insecure)},
              })},
      {"auth", r.Subtable({{"tokens", r.ReadableFile(&c.tokens)}})},
      {"metrics", r.Subtable({{"listen", r.Address(&c.metrics_listen, true)}})},
      {"store", r.Subtable({
                    {"address", [&](const toml::node& n, const std::string& key) -> absl::Status {
                       if (absl::Status st = r.String(&c.store_address)(n, key); !st.ok()) return st;
                       if (!IsStoreAddress(c.store_address)) {
                         return r.Error(LineOf(n), key, absl::StrCat("'", c.store_address,
                                                                     "' is not host:port or unix:/path (e.g. 127.0.0.1:6379)"));
                       }
                       return absl::OkStatus();
                     }},
                    {"key_prefix", r.String(&c.store_key_prefix)},
                    {"connect_timeout_ms", r.Number(&c.store_connect_timeout_ms, 0.0, 60000.0, true)},
                    {"read_timeout_ms", r.Number(&c.store_read_timeout_ms, 0.0, 60000.0, true)},
                    {"write_timeout_ms", r.Number(&c.store_write_timeout_ms, 0.0, 60000.0, true)},
                    {"username", r.String(&c.store_username)},
                    {"password_file", r.ReadableFile(&c.store_password_file)},
                })},
      {"log", r.Subtable({
                  {"format", r.Choice(&log_format, {"text", "json"})},
                  {"file", r.WritableFile(&c.log_file)},
              })},
      {"scenes", [&](const toml::node& n, const std::string& key) { return ReadScenes(r, n, key, &c.scenes); }},
  };
  if (absl::Status st = r.Table(root, "", keys); !st.ok()) return st;
  c.log_json = log_format == "json";
  if (const toml::node* n = root.get("listen")) c.listen_line = LineOf(*n);
  if (const toml::node* n = root.get("tls")) c.tls_line = LineOf(*n);
  // Pairs of keys that only work together.
  if (c.tls_cert.empty() != c.tls_key.empty()) {
    const toml::node* tls = root.get("tls");
    return r.Error(tls != nullptr ? LineOf(*tls) : 1, c.tls_cert.empty() ? "tls.cert" : "tls.key",
                   "tls.cert and tls.key go together (the certificate chain and its private key)");
  }
  if (c.store_address.empty() && root.get("store") != nullptr) {
    return r.Error(LineOf(*root.get("store")), "store.address", "missing: where the Redis of the PVS store listens");
  }
  if (!IsStoreKeyPrefix(c.store_key_prefix)) {
    const toml::node* prefix = root.at_path("store.key_prefix").node();
    return r.Error(LineOf(prefix != nullptr ? *prefix : *root.get("store")), "store.key_prefix",
                   "expected a non-empty word without spaces");
  }
  if (!c.tls_client_ca.empty() && c.tls_cert.empty()) {
    return r.Error(LineOf(*root.get("tls")), "tls.client_ca",
                   "mutual TLS needs the server's own tls.cert and tls.key too");
  }
  return c;
}

absl::StatusOr<ServerConfig> LoadServerConfig(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return absl::NotFoundError(absl::StrCat(path, ": cannot read: is a folder"));
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot read: ", std::strerror(errno)));
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return absl::NotFoundError(absl::StrCat(path, ": cannot read: ", std::strerror(errno)));
  return ParseServerConfig(text.str(), path);
}

absl::Status CheckServerConfig(const ServerConfig& config) {
  const std::string where = config.path.empty() ? "" : config.path + ": ";
  if (config.scenes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(where, "no scene to serve: give --scene NAME or [[scenes]] tables",
                                                   config.path.empty() ? "" : " in the configuration"));
  }
  for (size_t a = 0; a < config.scenes.size(); ++a) {
    for (size_t b = 0; b < a; ++b) {
      if (config.scenes[a].name == config.scenes[b].name) {
        return absl::InvalidArgumentError(absl::StrCat(where, "two scenes are named '", config.scenes[a].name, "'"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace vistream::server
