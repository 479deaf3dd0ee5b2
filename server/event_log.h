#pragma once
// The server's log: one line per event (start, ready, session start, crossing, PVS computed or
// from the cache, eviction, session end with its status), as text or as JSON lines. Every line
// has the time (UTC), a level (info, warn, error), the event, and for a session's events the
// session id and, once its Hello picked one, the scene.

#include <cstdint>
#include <cstdio>
#include <initializer_list>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>

namespace vistream::server {

class EventLog {
 public:
  // Writes to `out` (not owned; null: discard), JSON lines when `json`.
  EventLog(std::FILE* out, bool json) : out_(out), json_(json) {}

  // A field's value: text or a number, written as JSON values when json.
  struct Value {
    Value(std::string_view s) : text(s), quoted(true) {}            // NOLINT(runtime/explicit)
    Value(const std::string& s) : text(s), quoted(true) {}          // NOLINT(runtime/explicit)
    Value(const char* s) : text(s), quoted(true) {}                 // NOLINT(runtime/explicit)
    Value(double v);                                                // NOLINT(runtime/explicit)
    Value(uint64_t v) : text(std::to_string(v)) {}                  // NOLINT(runtime/explicit)
    Value(int64_t v) : text(std::to_string(v)) {}                   // NOLINT(runtime/explicit)
    Value(uint32_t v) : text(std::to_string(v)) {}                  // NOLINT(runtime/explicit)
    Value(int v) : text(std::to_string(v)) {}                       // NOLINT(runtime/explicit)
    std::string text;
    bool quoted = false;
  };
  using Field = std::pair<std::string_view, Value>;

  enum class Level { kInfo, kWarn, kError };

  // `session` 0: a server event. Thread-safe; one line per call.
  void Write(uint64_t session, std::string_view event, std::initializer_list<Field> fields) {
    Write(Level::kInfo, session, event, fields);
  }
  void Write(Level level, uint64_t session, std::string_view event, std::initializer_list<Field> fields);
  // Lines of `session` name `scene` from now on, until ForgetSession.
  void SetScene(uint64_t session, std::string_view scene);
  void ForgetSession(uint64_t session);

 private:
  std::FILE* out_;
  bool json_;
  std::mutex mu_;
  std::unordered_map<uint64_t, std::string> scenes_;  // by session
};

}  // namespace vistream::server
