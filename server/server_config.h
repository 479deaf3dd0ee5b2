#pragma once
// vistream-server's configuration: a TOML file (`vistream-server --config FILE`, the example
// in deploy/server.toml) whose every key a command-line option may override. The shape of the
// file is part of the interface (issue 32, README "Deploying"):
//
//   listen, threads, max_sessions, catalog, grace_s, drain_s
//   [limits]   hello_timeout_s, max_pose_rate_hz, max_sessions_per_address, max_sessions_per_token
//   [tls]      cert, key, client_ca, insecure
//   [auth]     tokens
//   [metrics]  listen
//   [store]    address, key_prefix, connect_timeout_ms, read_timeout_ms, write_timeout_ms,
//              username, password_file
//   [log]      format ("text" | "json"), file
//   [[scenes]] name, file, pvs_file, cell_size_m, res, backend, cache_mb
//
// Parsed with toml++ (Debian libtomlplusplus-dev). A bad file is refused whole, before any
// scene loads, with "FILE:LINE: KEY: what is wrong" (KEY dotted; the Nth [[scenes]] table is
// scenes[N], counted from 1).

#include <cstdint>
#include <string>
#include <string_view>
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
