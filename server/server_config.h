#pragma once
// vistream-server's configuration: a TOML file (`vistream-server --config FILE`, the example
// in deploy/server.toml) whose every key a command-line option may override. The shape of the
// file is part of the interface (issue 32; docs/deploying.md, docs/server.md):
//
//   listen, threads, max_sessions, catalog, grace_s, drain_s
//   [limits]   hello_timeout_s, max_pose_rate_hz, max_sessions_per_address, max_sessions_per_token
//   [tls]      cert, key, client_ca, insecure
//   [auth]     tokens
//   [metrics]  listen
//   [web]      listen, root
//   [store]    address, key_prefix, connect_timeout_ms, read_timeout_ms, write_timeout_ms,
//              username, password_file
//   [log]      format ("text" | "json"), file
//   [[scenes]] name, file, pvs_file, cell_size_m, res, backend, cache_mb
//
// Parsed with toml++ (Debian libtomlplusplus-dev). A bad file is refused whole, before any
// scene loads, with "FILE:LINE: KEY: what is wrong" (KEY dotted; the Nth [[scenes]] table is
// scenes[N], counted from 1).
//
// Every setting is stated once, in ServerSettings(): its key in the file, where its value
// goes, how the file's value is checked, and its command-line option (server/server_command_line.h
// declares the options and merges them over the file from the same table). A setting is added
// there and nowhere else.

#include <cstdint>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <absl/status/statusor.h>

namespace vistream::server {

// One [[scenes]] table: a city the server serves.
struct SceneConfig {
  std::string name;          // what Hello.scene names; a catalog name unless `file` is given
  std::string file;          // a catalog .json or a .glb/.gltf file served under `name`; empty: the catalog's `name`
  std::string pvs_file;      // serve these sets instead of computing them; empty: compute
  double cell_size_m = 0.0;  // viewcell edge in metres; 0: the catalog entry's
  uint32_t res = 128;        // dual-ray-space raster, a power of two from 1 to 256
  std::string backend = "cpu";  // cpu | gl | exact
  double cache_mb = 256.0;   // this scene's PVS cache, MiB
  bool levels = false;       // make levels of detail at start when the scene has none (issue 45)
  int line = 0;              // where the table starts in the file (0: not from a file)
  // What LoadScene reads: `file`, else `name`.
  const std::string& source() const { return file.empty() ? name : file; }
};

struct ServerConfig {
  std::string path;  // the file read; empty: defaults and the command line only

  std::string listen = "127.0.0.1:50051";  // host:port; port 0: any free one
  unsigned threads = 0;                    // PVS workers shared by every scene; 0: one per core
  uint64_t max_sessions = 256;             // sessions at once, all scenes together
  std::string catalog;                     // scene catalog folder; empty: scenes::CatalogDir()
  double grace_s = 5.0;                    // seconds sessions get to end on SIGTERM
  // Seconds between the first SIGTERM and the end of the sessions: health says 503 and
  // NOT_SERVING while every session, new ones too, is served on, so that a load balancer's
  // checks take the replica out first (deploy/haproxy.cfg marks it DOWN within 2.5 s); ends
  // early once no session is open. 0: end the sessions at once.
  double drain_s = 5.0;

  // [limits]
  double hello_timeout_s = 30.0;           // a stream without Hello by then ends DEADLINE_EXCEEDED; 0: never
  double max_pose_rate_hz = 120.0;
  uint64_t max_sessions_per_address = 0;   // 0: no limit
  uint64_t max_sessions_per_token = 0;     // 0: no limit

  // [tls]
  std::string tls_cert, tls_key, tls_client_ca;  // PEM files; cert and key together turn TLS on
  bool tls_insecure = false;               // allow plaintext on an address that is not loopback

  // [auth]
  std::string tokens;                      // file of `name token` lines; empty: no authentication

  // [metrics]
  std::string metrics_listen;              // host:port of /metrics and /healthz; empty: off

  // [web]: the browser client (server/web_server.h)
  std::string web_listen;                  // host:port of the page and its WebSocket sessions; empty: off
  std::string web_root;                    // the page's folder; empty: DefaultWebRoot()

  // [store]: the PVS store shared by replicas (server/pvs_store.h)
  std::string store_address;               // Redis host:port or unix:PATH; empty: no store
  std::string store_key_prefix = "vistream";
  double store_connect_timeout_ms = 200.0;
  double store_read_timeout_ms = 50.0;     // a read's deadline, well under a crossing's budget
  double store_write_timeout_ms = 500.0;
  std::string store_username;              // Redis 6 ACL user; empty: the default user
  std::string store_password_file;         // the password on its first line; empty: no AUTH

  // [log]
  bool log_json = false;                   // format = "json"
  std::string log_file;                    // empty: stderr

  std::vector<SceneConfig> scenes;

  // Where the file set `listen` and the [tls] table (0: not in the file), for later errors.
  int listen_line = 0, tls_line = 0;
};

// ---- the settings table ----

// A check of a text value: `ok(value)`, else the message "'VALUE' is " + `what`.
struct TextCheck {
  bool (*ok)(std::string_view text) = nullptr;
  const char* what = "";
  bool empty_ok = false;  // the empty text passes (the feature is off)
};

// How a setting's value is read from the file; errors "FILE:LINE: KEY: what is wrong".
struct FileRule {
  enum class Kind {
    kString,        // any string
    kText,          // a string that passes `text`
    kChoice,        // one of `choices` (on a bool field: true for the last one)
    kBool,          // true or false
    kWhole,         // a whole number in [lo, hi]
    kNumber,        // a finite number in [lo, hi] (whole numbers allowed; `above_lo`: lo excluded)
    kReadableFile,  // a file this process can read (relative: to the file's folder); empty: off
    kFolder,        // a folder (relative: to the file's folder); empty: the default
    kWritableFile,  // a file whose folder exists and that can be written; empty: off
  };
  Kind kind = Kind::kString;
  double lo = 0.0, hi = 0.0;
  bool above_lo = false;
  std::vector<std::string> choices = {};
  TextCheck text = {};
  // A further check of a number once it is in range: what is wrong with it, or "" (e.g. a
  // raster that is no power of two).
  std::string (*also)(double value) = nullptr;
};

// How a setting's command-line option is checked (CLI11 validators, cli/number_options.h);
// their messages are CLI11's "OPTION: what is wrong".
struct OptionRule {
  enum class Kind {
    kAny,         // any text
    kFlag,        // a flag without a value (a bool field)
    kWhole,       // a whole number in [lo, hi] (vistream::cli::WholeRange)
    kNumber,      // a finite number in [lo, hi] (vistream::cli::FiniteRange)
    kPowerOfTwo,  // a power of two in [lo, hi] (vistream::cli::PowerOfTwo)
    kChoice,      // one of `choices` (CLI::IsMember)
    kText,        // passes `text`; `type_name` names the value in --help (HOST:PORT)
  };
  Kind kind = Kind::kAny;
  double lo = 0.0, hi = 0.0;
  std::vector<std::string> choices = {};
  TextCheck text = {};
  const char* type_name = "";
  bool show_default = false;  // --help shows the default value
};

// Where a setting's value lives: a member of ServerConfig, or of SceneConfig (a setting of
// every [[scenes]] table; its option applies to every scene).
using SettingField = std::variant<std::string ServerConfig::*, bool ServerConfig::*, unsigned ServerConfig::*,
                                  uint64_t ServerConfig::*, double ServerConfig::*, std::string SceneConfig::*,
                                  uint32_t SceneConfig::*, double SceneConfig::*, bool SceneConfig::*>;

struct ServerSetting {
  const char* table;  // the file's table: "" (top level), "limits", "tls", ..., "scenes" ([[scenes]])
  const char* key;    // the key in it
  SettingField field;
  FileRule file;
  const char* option = nullptr;  // the command-line option ("--listen"); null: the file only
  const char* help = "";
  OptionRule check;
  int help_order = 0;            // the option's place in --help (the file's order differs)
};

// Every setting of vistream-server, in the file's order (top-level keys, then the tables as
// the header above lists them).
const std::vector<ServerSetting>& ServerSettings();

// Reads and checks `path`. Errors: INVALID_ARGUMENT "PATH:LINE: KEY: what is wrong" for a
// key that is unknown, of the wrong type, out of range, a file it names that cannot be read,
// or two scenes of one name; NOT_FOUND "PATH: cannot read: why" for the file itself; TOML
// syntax errors as "PATH:LINE:COLUMN: what toml++ says".
absl::StatusOr<ServerConfig> LoadServerConfig(const std::string& path);

// As LoadServerConfig, from text that came from `path` (named in errors only).
absl::StatusOr<ServerConfig> ParseServerConfig(std::string_view text, const std::string& path);

// host:port with a port from 0 to 65535 (a host of at least one character, [::1] allowed).
bool IsHostPort(std::string_view text);

// A Redis address for the store: host:port (port 1 to 65535) or unix:PATH.
bool IsStoreAddress(std::string_view text);
// A key prefix for the store: a non-empty word without white space.
bool IsStoreKeyPrefix(std::string_view text);

// Checks what the configuration and the command line make together: at least one scene,
// distinct scene names. Errors name the file.
absl::Status CheckServerConfig(const ServerConfig& config);

}  // namespace vistream::server
