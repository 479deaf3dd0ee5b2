#pragma once
// The PVS store: viewcell PVSs shared in Redis by every replica of a service (issue 33,
// docs/scaling-out.md), behind each replica's own cache. A PVS worker that misses the cache
// reads the store before it computes, and writes what it computed back (SET NX: two replicas
// that computed one cell at once leave the first answer). `vistream pvs --all --store` fills
// it ahead of traffic.
//
// Keys: PREFIX:pvs1:FINGERPRINT:GRID:rRES:BACKEND:CELL (PvsStoreNamespace; GRID hashes the
// cells, and their bands when they follow terrain), so that different
// scenes, grids or settings never mix. Values: visibility::EncodeCellRecord (length, checksum,
// cell id, ids within the scene), checked on every read: a bad entry is counted, logged and
// recomputed (then overwritten), never served.
//
// Redis unreachable, slow or restarted: a read or write fails within its deadline, the store is
// marked down and its callers go on without it (the local cache and computation) until the next
// attempt, with back-off doubling from 0.1 s. Transitions are logged once each, not per call.
// Client: hiredis (Debian libhiredis-dev 0.14: no TLS; docs/scaling-out.md says how to reach a
// TLS Redis).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include <absl/status/statusor.h>

#include "scenes/scene.h"
#include "server/event_log.h"
#include "visibility/viewcell_grid.h"

struct redisContext;

namespace vistream::server {

struct PvsStoreOptions {
  std::string address;               // "host:port", "[v6 address]:port" or "unix:/path/to/socket"
  std::string key_prefix = "vistream";
  double connect_timeout_s = 0.2;
  double read_timeout_s = 0.05;      // a read's deadline: well under a crossing's budget
  double write_timeout_s = 0.5;
  std::string username;              // Redis 6 ACL user; empty: the default user
  std::string password;              // AUTH; empty: none
  double max_backoff_s = 5.0;        // reconnect back-off doubles from 0.1 s up to this
  size_t max_pending_writes = 4096;  // write-back queue; writes beyond it are dropped (counted)
};

struct PvsStoreStats {
  bool up = false;               // the last attempt reached the store
  uint64_t hits = 0;             // reads that found a good entry
  uint64_t misses = 0;           // reads that found none
  uint64_t bad_entries = 0;      // entries refused (length, checksum, cell, ids): recomputed
  uint64_t unavailable = 0;      // reads and writes skipped or failed: store down or too slow
  uint64_t writes = 0;           // entries written back (or found already there)
  uint64_t writes_dropped = 0;   // write-backs lost: queue full or store down
  uint64_t outages = 0;          // times the store went down
};

// The key space of one scene's PVSs: `prefix`, the scene's content (scenes::SceneFingerprint),
// the grid (cell size, extent and corner, bit for bit), the raster `res` and the `backend`.
std::string PvsStoreNamespace(const std::string& prefix, uint64_t scene_fingerprint,
                              const visibility::ViewcellGrid& grid, uint32_t res, const std::string& backend);

class PvsStore {
 public:
  enum class Read { kHit, kMiss, kBad, kUnavailable };
  // Receives the store's events (up, down, bad entry) with a detail; may be null.
  using EventSink = std::function<void(EventLog::Level level, std::string_view event, const std::string& detail)>;

  // Checks the options; connects on first use, not here (Redis may come up later). Errors:
  // INVALID_ARGUMENT naming the address (not host:port or unix:PATH) or a timeout (not > 0).
  static absl::StatusOr<std::unique_ptr<PvsStore>> Create(const PvsStoreOptions& options, EventSink events = nullptr);
  // Stops the writer: write-backs still queued are dropped (counted).
  ~PvsStore();
  PvsStore(const PvsStore&) = delete;
  PvsStore& operator=(const PvsStore&) = delete;

  // Connects now (a PING): OK; PERMISSION_DENIED when Redis answers but refuses (a wrong or
  // missing password); else UNAVAILABLE naming the address and what failed. For tools that
  // cannot go on without the store, and a server's start.
  absl::Status Connect();

  // The PVS of `cell` (a scene of `scene_objects` objects) under namespace `ns`, within the
  // read deadline: kHit fills `objects` (ascending ids); kMiss: none stored; kBad: an entry that
  // fails its checks (logged, counted; the next PutLater of the cell overwrites it);
  // kUnavailable: the store is down, in back-off, or did not answer in time. Thread-safe.
  Read Get(const std::string& ns, visibility::CellId cell, uint64_t scene_objects, std::vector<uint32_t>* objects);
  // Queues `objects` (ascending ids) as the PVS of `cell` for a background write (SET NX, or a
  // plain SET over an entry Get found bad); never blocks. Thread-safe.
  void PutLater(const std::string& ns, visibility::CellId cell, std::span<const uint32_t> objects);
  // Waits until every write queued before the call is done or dropped (tests, tools).
  void Flush();

  // Writes now, pipelined (SET NX: an entry already there is kept); for tools. Errors:
  // UNAVAILABLE naming the address and the failure.
  absl::Status Put(const std::string& ns, std::span<const std::pair<visibility::CellId, std::string>> records);
  // Which of `cells` have an entry under `ns` (pipelined EXISTS); for tools. Errors: UNAVAILABLE.
  absl::StatusOr<std::vector<bool>> Exists(const std::string& ns, std::span<const visibility::CellId> cells);
  // Deletes the entries of `cells` under `ns` (pipelined DEL); for tools. Errors: UNAVAILABLE.
  absl::Status Delete(const std::string& ns, std::span<const visibility::CellId> cells);

  // The key of `cell` under `ns`.
  static std::string Key(const std::string& ns, visibility::CellId cell);
  PvsStoreStats stats() const;
  const std::string& address() const { return options_.address; }
  const std::string& key_prefix() const { return options_.key_prefix; }

 private:
  struct ContextFree {
    void operator()(redisContext* c) const;
  };
  using Context = std::unique_ptr<redisContext, ContextFree>;
  struct Pending {
    std::string key, value;
    bool overwrite = false;
  };
  using Clock = std::chrono::steady_clock;

  explicit PvsStore(PvsStoreOptions options, EventSink events);
  // A connection from the pool (`*pooled` true), or a new one; null while the store is down
  // and in back-off (`why` says so) or when connecting fails (then the store is marked down).
  Context Acquire(std::string* why, bool* pooled = nullptr);
  // Returns `c` to the pool, or (not `ok`) drops it and marks the store down for `why`.
  void Release(Context c, bool ok, const std::string& why);
  Context Dial(std::string* why) const;
  // Closes every pooled connection (one was found closed by Redis: a restart closed them all).
  void DropIdle();
  void MarkDownLocked(const std::string& why);
  void WriterLoop();
  // `verb KEY` for the key of each of `cells`, pipelined: each integer reply (0 for another
  // kind). Errors: UNAVAILABLE.
  absl::StatusOr<std::vector<long long>> PerKey(const char* verb, const std::string& ns,
                                                std::span<const visibility::CellId> cells);
  // Sends `batch` pipelined on `c` with the write deadline; false with `why` on an I/O error.
  bool SendWrites(redisContext* c, const std::vector<Pending>& batch, std::string* why);
  void Event(EventLog::Level level, std::string_view event, const std::string& detail) const;
  std::string Unavailable(const std::string& why) const;

  const PvsStoreOptions options_;
  const EventSink events_;

  mutable std::mutex mu_;
  std::vector<Context> idle_;
  bool up_ = false;
  bool ever_up_ = false;
  bool dialing_ = false;         // a probe after back-off is connecting
  bool down_reported_ = false;   // this outage was logged and counted
  Clock::time_point retry_at_{};
  double backoff_s_ = 0.1;
  std::vector<std::string> overwrite_;  // keys Get found bad (bounded)

  std::mutex write_mu_;
  std::condition_variable write_cv_;
  std::condition_variable flushed_cv_;
  std::deque<Pending> queue_;
  size_t writing_ = 0;  // entries taken by the writer and not yet done
  bool stopping_ = false;

  std::atomic<uint64_t> hits_{0}, misses_{0}, bad_{0}, unavailable_{0}, writes_{0}, writes_dropped_{0}, outages_{0};
  std::jthread writer_;  // last: starts after the members above exist
};

}  // namespace vistream::server
