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
#include <type_traits>
#include <utility>

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
        const std::vector<ServerSetting>& settings = ServerSettings();
        const bool top_level = !prefix.empty() && std::any_of(settings.begin(), settings.end(), [&](const ServerSetting& st) {
          return *st.table == '\0' && name == st.key;
        });
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
  // A path (relative: to the configuration file's folder; empty allowed: the feature is off)
  // that `problem` finds nothing wrong with: it says what is wrong with the resolved path, or "".
  Handler Path(std::string* out, std::function<std::string(const std::string& path)> problem) const {
    return [this, out, problem](const toml::node& n, const std::string& key) -> absl::Status {
      if (absl::Status st = String(out)(n, key); !st.ok()) return st;
      if (out->empty()) return absl::OkStatus();
      *out = Resolve(*out);
      if (std::string what = problem(*out); !what.empty()) return Error(LineOf(n), key, what);
      return absl::OkStatus();
    };
  }
  // A file this process can read.
  Handler ReadableFile(std::string* out) const {
    return Path(out, [](const std::string& path) -> std::string {
      std::error_code ec;
      if (!fs::is_regular_file(path, ec)) return absl::StrCat(path, ": no such file");
      if (::access(path.c_str(), R_OK) != 0) return absl::StrCat(path, ": cannot be read");
      return "";
    });
  }
  Handler Folder(std::string* out) const {
    return Path(out, [](const std::string& path) -> std::string {
      std::error_code ec;
      return fs::is_directory(path, ec) ? "" : absl::StrCat(path, ": no such folder");
    });
  }
  // A file the server will append to: its folder must exist and be writable.
  Handler WritableFile(std::string* out) const {
    return Path(out, [](const std::string& path) -> std::string {
      const fs::path p(path);
      const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
      std::error_code ec;
      if (fs::is_directory(p, ec)) return absl::StrCat(path, ": is a folder, not a file");
      if (!fs::is_directory(dir, ec)) return absl::StrCat(dir.string(), ": no such folder");
      const bool exists = fs::exists(p, ec);
      if (::access(exists ? path.c_str() : dir.c_str(), W_OK) != 0) return absl::StrCat(path, ": cannot be written");
      return "";
    });
  }
  // A string that passes `check`.
  Handler Text(std::string* out, TextCheck check) const {
    return [this, out, check](const toml::node& n, const std::string& key) -> absl::Status {
      if (absl::Status st = String(out)(n, key); !st.ok()) return st;
      if (check.empty_ok && out->empty()) return absl::OkStatus();
      if (!check.ok(*out)) return Error(LineOf(n), key, absl::StrCat("'", *out, "' is ", check.what));
      return absl::OkStatus();
    };
  }
  // `read`, then `also` on the number it read.
  template <typename T>
  Handler Also(Handler read, T* out, std::string (*also)(double)) const {
    if (also == nullptr) return read;
    return [this, read, out, also](const toml::node& n, const std::string& key) -> absl::Status {
      if (absl::Status st = read(n, key); !st.ok()) return st;
      if (std::string what = also(static_cast<double>(*out)); !what.empty()) return Error(LineOf(n), key, what);
      return absl::OkStatus();
    };
  }
  // The handler of a setting whose value goes to `config` or `scene` (as its field says).
  Handler Setting(const ServerSetting& setting, ServerConfig* config, SceneConfig* scene) const {
    const FileRule& rule = setting.file;
    using Kind = FileRule::Kind;
    auto target = [&](auto member) {
      if constexpr (std::is_invocable_v<decltype(member), ServerConfig&>) {
        return &std::invoke(member, *config);
      } else {
        return &std::invoke(member, *scene);
      }
    };
    return std::visit(
        [&](auto member) -> Handler {
          auto* out = target(member);
          using T = std::remove_pointer_t<decltype(out)>;
          if constexpr (std::is_same_v<T, std::string>) {
            switch (rule.kind) {
              case Kind::kText: return Text(out, rule.text);
              case Kind::kChoice: return Choice(out, rule.choices);
              case Kind::kReadableFile: return ReadableFile(out);
              case Kind::kFolder: return Folder(out);
              case Kind::kWritableFile: return WritableFile(out);
              default: return String(out);
            }
          } else if constexpr (std::is_same_v<T, bool>) {
            if (rule.kind != Kind::kChoice) return Bool(out);
            // A choice of words for a bool: true for the last (log.format = "json").
            return [this, out, choices = rule.choices](const toml::node& n, const std::string& key) -> absl::Status {
              std::string word;
              if (absl::Status st = Choice(&word, choices)(n, key); !st.ok()) return st;
              *out = word == choices.back();
              return absl::OkStatus();
            };
          } else if constexpr (std::is_same_v<T, double>) {
            return Also(Number(out, rule.lo, rule.hi, rule.above_lo), out, rule.also);
          } else {
            return Also(Whole(out, static_cast<int64_t>(rule.lo), static_cast<int64_t>(rule.hi)), out, rule.also);
          }
        },
        setting.field);
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
    std::vector<Reader::Key> keys;
    for (const ServerSetting& setting : ServerSettings()) {
      if (std::string_view(setting.table) == "scenes") keys.push_back({setting.key, r.Setting(setting, nullptr, &s)});
    }
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

namespace {

using FK = FileRule::Kind;
using OK = OptionRule::Kind;

FileRule File(FK kind) { return FileRule{.kind = kind}; }
FileRule FileRange(FK kind, double lo, double hi) { return FileRule{.kind = kind, .lo = lo, .hi = hi}; }
OptionRule Option(OK kind, double lo = 0.0, double hi = 0.0, bool show_default = false) {
  return OptionRule{.kind = kind, .lo = lo, .hi = hi, .show_default = show_default};
}
constexpr bool kShowDefault = true;
// A key of the file that no option overrides.
ServerSetting FileOnly(const char* table, const char* key, SettingField field, FileRule rule) {
  return ServerSetting{table, key, field, std::move(rule), nullptr, "", OptionRule{}, 0};
}

const TextCheck kListenCheck{IsHostPort, "not host:port with a port from 0 to 65535 (e.g. 127.0.0.1:50051)", false};
const TextCheck kStoreAddressCheck{IsStoreAddress, "not host:port or unix:/path (e.g. 127.0.0.1:6379)", false};

std::string CellSizeAlso(double v) {
  if (v != 0.0 && v < 0.01) return absl::StrCat(Format(v), " is out of range (0: the catalog's, or 0.01 to 1e+06)");
  return "";
}

std::string PowerOfTwoAlso(double v) {
  const auto n = static_cast<uint32_t>(v);
  if ((n & (n - 1)) != 0) return absl::StrCat(n, " is not a power of two from 1 to 256");
  return "";
}

std::vector<ServerSetting> MakeSettings() {
  std::vector<ServerSetting> t;
  // Top level.
  t.push_back({"", "listen", &ServerConfig::listen, {.kind = FK::kText, .text = kListenCheck}, "--listen",
               "address to listen on, host:port (port 0: any free one)",
               {.kind = OK::kText, .text = kListenCheck, .type_name = "HOST:PORT", .show_default = true}, 2});
  t.push_back({"", "threads", &ServerConfig::threads, FileRange(FK::kWhole, 0, 1024), "--threads",
               "PVS worker threads, shared by every scene (0: one per core)", Option(OK::kWhole, 0, 1024, kShowDefault), 3});
  t.push_back({"", "max_sessions", &ServerConfig::max_sessions, FileRange(FK::kWhole, 1, 100000), "--max-sessions",
               "sessions at once; more are refused", Option(OK::kWhole, 1, 100000, kShowDefault), 8});
  t.push_back({"", "catalog", &ServerConfig::catalog, File(FK::kFolder), "--catalog",
               "folder of catalog entries (default: the built-in catalog)", Option(OK::kAny), 1});
  t.push_back({"", "grace_s", &ServerConfig::grace_s, FileRange(FK::kNumber, 0.0, 3600.0), "--grace",
               "seconds sessions get to end on shutdown", Option(OK::kNumber, 0, 3600, kShowDefault), 11});
  t.push_back({"", "drain_s", &ServerConfig::drain_s, FileRange(FK::kNumber, 0.0, 3600.0), "--drain",
               "seconds from SIGTERM to the end of the sessions: /healthz says 503 while they are served on, so "
               "that a load balancer takes this replica out first (0: end them at once)",
               Option(OK::kNumber, 0, 3600, kShowDefault), 12});
  // [limits]
  t.push_back({"limits", "hello_timeout_s", &ServerConfig::hello_timeout_s, FileRange(FK::kNumber, 0.0, 86400.0),
               "--hello-timeout",
               "seconds a new stream may take to send its Hello (then DEADLINE_EXCEEDED; 0: no limit)",
               Option(OK::kNumber, 0, 86400, kShowDefault), 13});
  t.push_back({"limits", "max_pose_rate_hz", &ServerConfig::max_pose_rate_hz, FileRange(FK::kNumber, 0.1, 100000.0),
               "--max-pose-rate", "poses per second a session may send", Option(OK::kNumber, 0.1, 100000, kShowDefault),
               10});
  t.push_back({"limits", "max_sessions_per_address", &ServerConfig::max_sessions_per_address,
               FileRange(FK::kWhole, 0, 100000), "--max-sessions-per-address",
               "sessions at once from one client address (0: no limit)", Option(OK::kWhole, 0, 100000, kShowDefault), 14});
  t.push_back({"limits", "max_sessions_per_token", &ServerConfig::max_sessions_per_token,
               FileRange(FK::kWhole, 0, 100000), "--max-sessions-per-token", "sessions at once per token (0: no limit)",
               Option(OK::kWhole, 0, 100000, kShowDefault), 15});
  // [tls]
  t.push_back({"tls", "cert", &ServerConfig::tls_cert, File(FK::kReadableFile), "--tls-cert",
               "PEM certificate chain: serve TLS (with --tls-key)", Option(OK::kAny), 16});
  t.push_back({"tls", "key", &ServerConfig::tls_key, File(FK::kReadableFile), "--tls-key",
               "PEM private key of --tls-cert", Option(OK::kAny), 17});
  t.push_back({"tls", "client_ca", &ServerConfig::tls_client_ca, File(FK::kReadableFile), "--tls-client-ca",
               "PEM CA bundle: clients must present a certificate it signed (mutual TLS)", Option(OK::kAny), 18});
  t.push_back({"tls", "insecure", &ServerConfig::tls_insecure, File(FK::kBool), "--insecure",
               "allow plaintext on an address that is not loopback", Option(OK::kFlag), 19});
  // [auth]
  t.push_back({"auth", "tokens", &ServerConfig::tokens, File(FK::kReadableFile), "--tokens",
               "file of 'name token' lines: clients must send one as a bearer token", Option(OK::kAny), 20});
  // [metrics]
  t.push_back({"metrics", "listen", &ServerConfig::metrics_listen,
               {.kind = FK::kText, .text = {IsHostPort, kListenCheck.what, true}}, "--metrics-listen",
               "host:port of the HTTP /metrics and /healthz endpoint",
               {.kind = OK::kText,
                .text = {IsHostPort, "not host:port with a port from 0 to 65535 (e.g. 127.0.0.1:9464)", true},
                .type_name = "HOST:PORT"},
               21});
  // [web]: the browser client (server/web_server.h)
  t.push_back({"web", "listen", &ServerConfig::web_listen,
               {.kind = FK::kText, .text = {IsHostPort, kListenCheck.what, true}}, "--web-listen",
               "host:port of the browser client: its page over HTTP(S) and its sessions over WebSocket (/session)",
               {.kind = OK::kText,
                .text = {IsHostPort, "not host:port with a port from 0 to 65535 (e.g. 127.0.0.1:8080)", true},
                .type_name = "HOST:PORT"},
               21});
  t.push_back({"web", "root", &ServerConfig::web_root, File(FK::kFolder), "--web-root",
               "folder of the browser client's page (default: the installed or built one)", Option(OK::kAny), 21});
  // [store]
  t.push_back({"store", "address", &ServerConfig::store_address, {.kind = FK::kText, .text = kStoreAddressCheck},
               "--store",
               "Redis host:port or unix:PATH of the PVS store shared by replicas (docs/scaling-out.md)",
               {.kind = OK::kText, .text = kStoreAddressCheck, .type_name = "HOST:PORT"}, 22});
  // The prefix is checked once the file is read (ParseServerConfig): a [store] without the key keeps the default.
  t.push_back({"store", "key_prefix", &ServerConfig::store_key_prefix, File(FK::kString), "--store-prefix",
               "key prefix in the PVS store",
               {.kind = OK::kText,
                .text = {IsStoreKeyPrefix, "not a non-empty word without spaces", false},
                .type_name = "WORD",
                .show_default = true},
               23});
  t.push_back(FileOnly("store", "connect_timeout_ms", &ServerConfig::store_connect_timeout_ms,
                       {.kind = FK::kNumber, .lo = 0.0, .hi = 60000.0, .above_lo = true}));
  t.push_back({"store", "read_timeout_ms", &ServerConfig::store_read_timeout_ms,
               {.kind = FK::kNumber, .lo = 0.0, .hi = 60000.0, .above_lo = true}, "--store-read-timeout-ms",
               "a store read's deadline in ms (then the PVS is computed)",
               Option(OK::kNumber, 0.001, 60000, kShowDefault), 24});
  t.push_back(FileOnly("store", "write_timeout_ms", &ServerConfig::store_write_timeout_ms,
                       {.kind = FK::kNumber, .lo = 0.0, .hi = 60000.0, .above_lo = true}));
  t.push_back(FileOnly("store", "username", &ServerConfig::store_username, File(FK::kString)));
  t.push_back({"store", "password_file", &ServerConfig::store_password_file, File(FK::kReadableFile),
               "--store-password-file", "file whose first line is the store's password", Option(OK::kAny), 25});
  // [log]
  t.push_back({"log", "format", &ServerConfig::log_json, {.kind = FK::kChoice, .choices = {"text", "json"}},
               "--json-log", "log JSON lines instead of text", Option(OK::kFlag), 26});
  t.push_back({"log", "file", &ServerConfig::log_file, File(FK::kWritableFile), "--log-file",
               "append the log to this file instead of stderr", Option(OK::kAny), 27});
  // [[scenes]]: the options apply to every scene (or to --scene's).
  t.push_back(FileOnly("scenes", "name", &SceneConfig::name, File(FK::kString)));
  t.push_back(FileOnly("scenes", "file", &SceneConfig::file, File(FK::kReadableFile)));
  t.push_back({"scenes", "pvs_file", &SceneConfig::pvs_file, File(FK::kReadableFile), "--pvs-file",
               "serve the PVSs of this file (vistream agvs -o, vistream pvs --all -o) instead of computing them "
               "(one scene only)",
               Option(OK::kAny), 7});
  t.push_back({"scenes", "cell_size_m", &SceneConfig::cell_size_m,
               {.kind = FK::kNumber, .lo = 0.0, .hi = 1e6, .also = CellSizeAlso}, "--cell-size",
               "viewcell edge in metres (default: the catalog entry's)", Option(OK::kNumber, 0.01, 1e6), 4});
  t.push_back({"scenes", "res", &SceneConfig::res, {.kind = FK::kWhole, .lo = 1, .hi = 256, .also = PowerOfTwoAlso},
               "--res", "finest dual-ray-space raster (power of two, 1 to 256)",
               Option(OK::kPowerOfTwo, 1, 256, kShowDefault), 5});
  t.push_back({"scenes", "backend", &SceneConfig::backend, {.kind = FK::kChoice, .choices = {"cpu", "gl", "exact"}},
               "--backend", "cpu | gl | exact",
               {.kind = OK::kChoice, .choices = {"cpu", "gl", "exact"}, .show_default = true}, 6});
  t.push_back({"scenes", "cache_mb", &SceneConfig::cache_mb, FileRange(FK::kNumber, 1.0, 1e6), "--cache-mb",
               "PVS cache budget of each scene in MiB", Option(OK::kNumber, 1, 1e6, kShowDefault), 9});
  t.push_back({"scenes", "levels", &SceneConfig::levels, File(FK::kBool), "--levels",
               "make levels of detail at start for scenes without their own (vistream scene levels makes them "
               "ahead), so that clients asking for a screen error get them",
               Option(OK::kFlag), 28});
  return t;
}

}  // namespace

const std::vector<ServerSetting>& ServerSettings() {
  static const std::vector<ServerSetting> settings = MakeSettings();
  return settings;
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
  // The keys of the top level and of each table, in the settings' order; [[scenes]] last.
  std::vector<Reader::Key> keys;
  std::vector<std::pair<std::string, std::vector<Reader::Key>>> tables;
  for (const ServerSetting& setting : ServerSettings()) {
    const std::string table = setting.table;
    if (table == "scenes") continue;
    Reader::Key key{setting.key, r.Setting(setting, &c, nullptr)};
    if (table.empty()) {
      keys.push_back(std::move(key));
      continue;
    }
    if (tables.empty() || tables.back().first != table) tables.emplace_back(table, std::vector<Reader::Key>{});
    tables.back().second.push_back(std::move(key));
  }
  for (auto& [table, table_keys] : tables) keys.push_back({table.c_str(), r.Subtable(table_keys)});
  keys.push_back({"scenes", [&](const toml::node& n, const std::string& key) { return ReadScenes(r, n, key, &c.scenes); }});
  if (absl::Status st = r.Table(root, "", keys); !st.ok()) return st;
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
