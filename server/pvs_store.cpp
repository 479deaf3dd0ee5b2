#include "server/pvs_store.h"

#include <hiredis/hiredis.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>

#include <absl/strings/numbers.h>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "server/server_config.h"
#include "visibility/pvs_file.h"

namespace vistream::server {

namespace {

struct ReplyFree {
  void operator()(redisReply* r) const { freeReplyObject(r); }
};
using Reply = std::unique_ptr<redisReply, ReplyFree>;

struct Endpoint {
  std::string unix_path;  // set: a Unix socket
  std::string host;
  int port = 0;
};

// "host:port", "[v6]:port" or "unix:/path" split; nullopt when it is none of them (IsStoreAddress,
// the configuration's check, decides).
std::optional<Endpoint> ParseAddress(const std::string& address) {
  if (!IsStoreAddress(address)) return std::nullopt;
  Endpoint e;
  if (address.rfind("unix:", 0) == 0) {
    e.unix_path = address.substr(5);
    if (e.unix_path.empty()) return std::nullopt;
    return e;
  }
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon == 0) return std::nullopt;
  e.host = address.substr(0, colon);
  if (e.host.front() == '[') {
    if (e.host.size() < 3 || e.host.back() != ']') return std::nullopt;
    e.host = e.host.substr(1, e.host.size() - 2);
  }
  if (!absl::SimpleAtoi(address.substr(colon + 1), &e.port) || e.port < 1 || e.port > 65535) return std::nullopt;
  return e;
}

timeval ToTimeval(double seconds) {
  timeval tv{};
  tv.tv_sec = static_cast<time_t>(seconds);
  tv.tv_usec = static_cast<suseconds_t>((seconds - static_cast<double>(tv.tv_sec)) * 1e6);
  if (tv.tv_sec == 0 && tv.tv_usec == 0) tv.tv_usec = 1;
  return tv;
}

uint64_t Fnv1a(uint64_t h, const void* data, size_t n) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ULL;
  return h;
}

std::string ErrorOf(const redisContext* c) {
  return c->err != 0 ? std::string(c->errstr) : std::string("no reply");
}

// Whether the last command on `c` failed because the peer had closed the connection (a
// restarted Redis), not because it did not answer in time.
bool ClosedByPeer(const redisContext* c) {
  if (c->err == REDIS_ERR_EOF) return true;
  if (c->err != REDIS_ERR_IO) return false;
  return std::strstr(c->errstr, "reset") != nullptr || std::strstr(c->errstr, "Broken pipe") != nullptr;
}

constexpr size_t kMaxIdle = 16;
constexpr size_t kMaxOverwrite = 1024;
constexpr size_t kWriteBatch = 64;

}  // namespace

std::string PvsStoreNamespace(const std::string& prefix, uint64_t scene_fingerprint,
                              const visibility::ViewcellGrid& grid, uint32_t res, const std::string& backend) {
  uint64_t h = 0xcbf29ce484222325ULL;
  for (double v : {grid.cell_size(), grid.base_z(), grid.height(), grid.corner().x, grid.corner().y}) {
    h = Fnv1a(h, &v, sizeof(v));
  }
  for (int32_t n : {static_cast<int32_t>(grid.nx()), static_cast<int32_t>(grid.ny())}) h = Fnv1a(h, &n, sizeof(n));
  // Cells that follow terrain: their bands too (a flat grid hashes as before bands existed, so
  // its keys are unchanged; a server that ignored a scene's terrain wrote entries for flat
  // cells, which these keys never meet).
  for (const visibility::CellBand& b : grid.bands()) {
    h = Fnv1a(h, &b.z0, sizeof(b.z0));
    h = Fnv1a(h, &b.z1, sizeof(b.z1));
  }
  return absl::StrFormat("%s:pvs1:%016x:%016x:r%u:%s", prefix, scene_fingerprint, h, res, backend);
}

void PvsStore::ContextFree::operator()(redisContext* c) const { redisFree(c); }

absl::StatusOr<std::unique_ptr<PvsStore>> PvsStore::Create(const PvsStoreOptions& options, EventSink events) {
  if (!ParseAddress(options.address)) {
    return absl::InvalidArgumentError(
        absl::StrCat("store address '", options.address, "': expected host:port, [v6 address]:port or unix:/path"));
  }
  for (const auto& [name, value] : {std::pair{"connect timeout", options.connect_timeout_s},
                                    {"read timeout", options.read_timeout_s},
                                    {"write timeout", options.write_timeout_s},
                                    {"back-off", options.max_backoff_s}}) {
    if (!(value > 0.0) || !std::isfinite(value)) {
      return absl::InvalidArgumentError(absl::StrCat("store ", name, " ", value, " s: expected a positive number"));
    }
  }
  if (!IsStoreKeyPrefix(options.key_prefix)) {
    return absl::InvalidArgumentError(absl::StrCat("store key prefix '", options.key_prefix,
                                                   "': expected a non-empty word without spaces"));
  }
  return std::unique_ptr<PvsStore>(new PvsStore(options, std::move(events)));
}

PvsStore::PvsStore(PvsStoreOptions options, EventSink events)
    : options_(std::move(options)), events_(std::move(events)), writer_([this] { WriterLoop(); }) {}

PvsStore::~PvsStore() {
  {
    std::lock_guard lock(write_mu_);
    stopping_ = true;
    writes_dropped_ += queue_.size();
    queue_.clear();
  }
  write_cv_.notify_all();
  writer_ = std::jthread();  // joins
}

void PvsStore::Event(EventLog::Level level, std::string_view event, const std::string& detail) const {
  if (events_) events_(level, event, detail);
}

std::string PvsStore::Unavailable(const std::string& why) const {
  return absl::StrCat("the PVS store at ", options_.address, " is unavailable: ", why);
}

PvsStore::Context PvsStore::Dial(std::string* why) const {
  const Endpoint e = *ParseAddress(options_.address);
  const timeval connect = ToTimeval(options_.connect_timeout_s);
  Context c(e.unix_path.empty() ? redisConnectWithTimeout(e.host.c_str(), e.port, connect)
                                : redisConnectUnixWithTimeout(e.unix_path.c_str(), connect));
  if (c == nullptr) {
    *why = "out of memory";
    return nullptr;
  }
  if (c->err != 0) {
    *why = absl::StrCat("connect: ", c->errstr);
    return nullptr;
  }
  redisSetTimeout(c.get(), ToTimeval(options_.read_timeout_s));
  if (!options_.password.empty()) {
    Reply r(static_cast<redisReply*>(
        options_.username.empty()
            ? redisCommand(c.get(), "AUTH %b", options_.password.data(), options_.password.size())
            : redisCommand(c.get(), "AUTH %b %b", options_.username.data(), options_.username.size(),
                           options_.password.data(), options_.password.size())));
    if (r == nullptr) {
      *why = absl::StrCat("AUTH: ", ErrorOf(c.get()));
      return nullptr;
    }
    if (r->type == REDIS_REPLY_ERROR) {
      *why = absl::StrCat("AUTH refused: ", std::string(r->str, r->len));  // never the password
      return nullptr;
    }
  }
  // Up only once Redis answers: a frozen one accepts the connection but not this, and one that
  // wants a password says NOAUTH here.
  Reply pong(static_cast<redisReply*>(redisCommand(c.get(), "PING")));
  if (pong == nullptr) {
    *why = absl::StrCat("PING: ", ErrorOf(c.get()));
    return nullptr;
  }
  if (pong->type == REDIS_REPLY_ERROR) {
    *why = absl::StrCat("PING refused: ", std::string(pong->str, pong->len));
    return nullptr;
  }
  return c;
}

PvsStore::Context PvsStore::Acquire(std::string* why, bool* pooled) {
  std::unique_lock lock(mu_);
  if (pooled != nullptr) *pooled = !idle_.empty();
  if (!idle_.empty()) {
    Context c = std::move(idle_.back());
    idle_.pop_back();
    return c;
  }
  // Down after a failure (not merely before the first connection): one caller at a time tries
  // again, once the back-off has passed; the rest go on without the store at once.
  const bool probe = down_reported_;
  if (probe) {
    if (dialing_ || Clock::now() < retry_at_) {
      *why = "down (reconnecting with back-off)";
      return nullptr;
    }
    dialing_ = true;
  }
  lock.unlock();
  Context c = Dial(why);
  lock.lock();
  if (probe) dialing_ = false;
  if (c == nullptr) {
    MarkDownLocked(*why);
    return nullptr;
  }
  if (!up_) {
    up_ = true;
    down_reported_ = false;
    backoff_s_ = 0.1;
    const bool again = ever_up_;
    ever_up_ = true;
    lock.unlock();
    Event(EventLog::Level::kInfo, again ? "store reconnected" : "store connected", options_.address);
  }
  return c;
}

void PvsStore::DropIdle() {
  std::lock_guard lock(mu_);
  idle_.clear();
}

void PvsStore::Release(Context c, bool ok, const std::string& why) {
  std::unique_lock lock(mu_);
  if (ok) {
    if (idle_.size() < kMaxIdle) idle_.push_back(std::move(c));
    return;
  }
  MarkDownLocked(why);
}

void PvsStore::MarkDownLocked(const std::string& why) {
  // Every pooled connection is suspect (a restarted Redis closed them all).
  idle_.clear();
  retry_at_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(backoff_s_));
  backoff_s_ = std::min(backoff_s_ * 2.0, options_.max_backoff_s);
  up_ = false;
  // Once per outage (the first failure after the store was up, or before it ever was), not
  // once per attempt.
  if (!down_reported_) {
    down_reported_ = true;
    ++outages_;
    Event(EventLog::Level::kWarn, "store unavailable",
          absl::StrCat(options_.address, ": ", why, "; going on without it, retrying with back-off"));
  }
}

PvsStore::Read PvsStore::Get(const std::string& ns, visibility::CellId cell, uint64_t scene_objects,
                             std::vector<uint32_t>* objects) {
  const std::string key = Key(ns, cell);
  std::string why;
  Context c;
  Reply r;
  // A pooled connection Redis closed (it restarted) fails at once: one more try on a new one,
  // so that a restart costs no read. A timeout is not retried.
  for (int attempt = 0; attempt < 2; ++attempt) {
    bool pooled = false;
    c = Acquire(&why, &pooled);
    if (c == nullptr) {
      ++unavailable_;
      return Read::kUnavailable;
    }
    redisSetTimeout(c.get(), ToTimeval(options_.read_timeout_s));
    r.reset(static_cast<redisReply*>(redisCommand(c.get(), "GET %b", key.data(), key.size())));
    if (r != nullptr || !pooled || !ClosedByPeer(c.get())) break;
    DropIdle();  // the others went with it: the retry dials
  }
  if (r == nullptr || r->type == REDIS_REPLY_ERROR) {
    // No answer in time, a lost connection, or an error reply (LOADING after a restart,
    // NOAUTH, ...): the store cannot answer now; back off rather than ask on every crossing.
    const std::string why_get = r == nullptr ? absl::StrCat("GET: ", ErrorOf(c.get()))
                                             : absl::StrCat("GET: ", std::string(r->str, r->len));
    ++unavailable_;
    Release(std::move(c), false, why_get);
    return Read::kUnavailable;
  }
  Release(std::move(c), true, "");
  if (r->type == REDIS_REPLY_NIL) {
    ++misses_;
    return Read::kMiss;
  }
  absl::StatusOr<std::vector<uint32_t>> ids =
      r->type == REDIS_REPLY_STRING
          ? visibility::DecodeCellRecord(std::string_view(r->str, r->len), cell, scene_objects, key)
          : absl::DataLossError(absl::StrCat(key, ": a reply of Redis type ", r->type, ", not a string"));
  if (!ids.ok()) {
    ++bad_;
    {
      std::lock_guard lock(mu_);
      if (overwrite_.size() < kMaxOverwrite) overwrite_.push_back(key);
    }
    Event(EventLog::Level::kWarn, "store bad entry", absl::StrCat(ids.status().message(), "; recomputing"));
    return Read::kBad;
  }
  ++hits_;
  *objects = std::move(*ids);
  return Read::kHit;
}

void PvsStore::PutLater(const std::string& ns, visibility::CellId cell, std::span<const uint32_t> objects) {
  Pending p{Key(ns, cell), visibility::EncodeCellRecord(cell, objects), false};
  {
    std::lock_guard lock(mu_);
    if (auto it = std::find(overwrite_.begin(), overwrite_.end(), p.key); it != overwrite_.end()) {
      p.overwrite = true;
      overwrite_.erase(it);
    }
  }
  {
    std::lock_guard lock(write_mu_);
    if (stopping_ || queue_.size() >= options_.max_pending_writes) {
      ++writes_dropped_;
      return;
    }
    queue_.push_back(std::move(p));
  }
  write_cv_.notify_one();
}

void PvsStore::Flush() {
  std::unique_lock lock(write_mu_);
  flushed_cv_.wait(lock, [&] { return (queue_.empty() && writing_ == 0) || stopping_; });
}

bool PvsStore::SendWrites(redisContext* c, const std::vector<Pending>& batch, std::string* why) {
  redisSetTimeout(c, ToTimeval(options_.write_timeout_s));
  for (const Pending& p : batch) {
    if (p.overwrite) {
      redisAppendCommand(c, "SET %b %b", p.key.data(), p.key.size(), p.value.data(), p.value.size());
    } else {
      redisAppendCommand(c, "SET %b %b NX", p.key.data(), p.key.size(), p.value.data(), p.value.size());
    }
  }
  for (size_t k = 0; k < batch.size(); ++k) {
    void* raw = nullptr;
    if (redisGetReply(c, &raw) != REDIS_OK || raw == nullptr) {
      *why = absl::StrCat("SET: ", ErrorOf(c));
      return false;
    }
    Reply r(static_cast<redisReply*>(raw));
    if (r->type == REDIS_REPLY_ERROR) {
      *why = absl::StrCat("SET ", batch[k].key, ": ", std::string(r->str, r->len));
      return false;
    }
  }
  return true;
}

void PvsStore::WriterLoop() {
  std::unique_lock lock(write_mu_);
  for (;;) {
    write_cv_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
    if (stopping_) return;
    std::vector<Pending> batch;
    while (!queue_.empty() && batch.size() < kWriteBatch) {
      batch.push_back(std::move(queue_.front()));
      queue_.pop_front();
    }
    writing_ = batch.size();
    lock.unlock();
    std::string why;
    bool ok = false;
    for (int attempt = 0; attempt < 2; ++attempt) {  // as in Get: a closed pooled connection, once
      bool pooled = false;
      Context c = Acquire(&why, &pooled);
      if (c == nullptr) break;
      ok = SendWrites(c.get(), batch, &why);
      if (!ok && pooled && ClosedByPeer(c.get())) {
        DropIdle();  // dropped without marking the store down; the retry dials
        continue;
      }
      Release(std::move(c), ok, why);
      break;
    }
    if (ok) {
      writes_ += batch.size();
    } else {
      writes_dropped_ += batch.size();
      unavailable_ += 1;
    }
    lock.lock();
    writing_ = 0;
    flushed_cv_.notify_all();
  }
}

absl::Status PvsStore::Connect() {
  std::string why;
  Context c = Acquire(&why);  // a new connection has answered PING (Dial)
  if (c == nullptr) {
    // Redis answered but refused us: a configuration error, not an outage.
    if (why.find("AUTH refused") != std::string::npos || why.find("NOAUTH") != std::string::npos ||
        why.find("WRONGPASS") != std::string::npos) {
      return absl::PermissionDeniedError(
          absl::StrCat("the PVS store at ", options_.address, " refused this server: ", why,
                       options_.password.empty() ? " (no password given)" : ""));
    }
    return absl::UnavailableError(Unavailable(why));
  }
  Release(std::move(c), true, "");
  return absl::OkStatus();
}

absl::Status PvsStore::Put(const std::string& ns, std::span<const std::pair<visibility::CellId, std::string>> records) {
  std::vector<Pending> batch;
  for (const auto& [cell, value] : records) batch.push_back(Pending{Key(ns, cell), value, false});
  std::string why;
  Context c = Acquire(&why);
  if (c == nullptr) return absl::UnavailableError(Unavailable(why));
  const bool ok = SendWrites(c.get(), batch, &why);
  Release(std::move(c), ok, why);
  if (!ok) return absl::UnavailableError(Unavailable(why));
  writes_ += batch.size();
  return absl::OkStatus();
}

absl::StatusOr<std::vector<long long>> PvsStore::PerKey(const char* verb, const std::string& ns,
                                                         std::span<const visibility::CellId> cells) {
  std::string why;
  Context c = Acquire(&why);
  if (c == nullptr) return absl::UnavailableError(Unavailable(why));
  redisSetTimeout(c.get(), ToTimeval(options_.write_timeout_s));
  const std::string format = absl::StrCat(verb, " %b");
  for (visibility::CellId cell : cells) {
    const std::string key = Key(ns, cell);
    redisAppendCommand(c.get(), format.c_str(), key.data(), key.size());
  }
  std::vector<long long> out;
  for (size_t k = 0; k < cells.size(); ++k) {
    void* raw = nullptr;
    if (redisGetReply(c.get(), &raw) != REDIS_OK || raw == nullptr) {
      why = absl::StrCat(verb, ": ", ErrorOf(c.get()));
      Release(std::move(c), false, why);
      return absl::UnavailableError(Unavailable(why));
    }
    Reply r(static_cast<redisReply*>(raw));
    out.push_back(r->type == REDIS_REPLY_INTEGER ? r->integer : 0);
  }
  Release(std::move(c), true, "");
  return out;
}

absl::StatusOr<std::vector<bool>> PvsStore::Exists(const std::string& ns, std::span<const visibility::CellId> cells) {
  absl::StatusOr<std::vector<long long>> counts = PerKey("EXISTS", ns, cells);
  if (!counts.ok()) return counts.status();
  std::vector<bool> out;
  for (long long n : *counts) out.push_back(n > 0);
  return out;
}

absl::Status PvsStore::Delete(const std::string& ns, std::span<const visibility::CellId> cells) {
  return PerKey("DEL", ns, cells).status();
}

std::string PvsStore::Key(const std::string& ns, visibility::CellId cell) { return absl::StrCat(ns, ":", cell); }

PvsStoreStats PvsStore::stats() const {
  PvsStoreStats s;
  {
    std::lock_guard lock(mu_);
    s.up = up_;
  }
  s.hits = hits_;
  s.misses = misses_;
  s.bad_entries = bad_;
  s.unavailable = unavailable_;
  s.writes = writes_;
  s.writes_dropped = writes_dropped_;
  s.outages = outages_;
  return s;
}

}  // namespace vistream::server
