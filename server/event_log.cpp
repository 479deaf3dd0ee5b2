#include "server/event_log.h"

#include <chrono>
#include <cmath>
#include <ctime>

#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

namespace vistream::server {

EventLog::Value::Value(double v) : text(std::isfinite(v) ? absl::StrFormat("%.6g", v) : "null") {}

void EventLog::SetScene(uint64_t session, std::string_view scene) {
  std::lock_guard lock(mu_);
  scenes_[session] = std::string(scene);
}

void EventLog::ForgetSession(uint64_t session) {
  std::lock_guard lock(mu_);
  scenes_.erase(session);
}

void EventLog::Write(Level level, uint64_t session, std::string_view event, std::initializer_list<Field> fields) {
  if (out_ == nullptr) return;
  const char* level_name = level == Level::kInfo ? "info" : level == Level::kWarn ? "warn" : "error";
  std::string scene;
  if (session != 0) {
    std::lock_guard lock(mu_);
    if (auto it = scenes_.find(session); it != scenes_.end()) scene = it->second;
  }
  bool has_scene_field = false;
  for (const Field& f : fields) has_scene_field = has_scene_field || f.first == "scene";
  const bool add_scene = !scene.empty() && !has_scene_field;
  const auto now = std::chrono::system_clock::now();
  const std::time_t t = std::chrono::system_clock::to_time_t(now);
  const int ms = static_cast<int>(
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000);
  std::tm tm{};
  gmtime_r(&t, &tm);
  const std::string stamp = absl::StrFormat("%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1,
                                            tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, ms);
  std::string line;
  if (json_) {
    line = "{\"time\":" + nlohmann::json(stamp).dump() + ",\"level\":\"" + level_name +
           "\",\"event\":" + nlohmann::json(std::string(event)).dump();
    if (session != 0) line += ",\"session\":" + std::to_string(session);
    if (add_scene) line += ",\"scene\":" + nlohmann::json(scene).dump();
    for (const Field& f : fields) {
      line += "," + nlohmann::json(std::string(f.first)).dump() + ":" +
              (f.second.quoted ? nlohmann::json(f.second.text).dump() : f.second.text);
    }
    line += "}";
  } else {
    line = stamp + " " + level_name + " " + std::string(event);
    if (session != 0) line += " session=" + std::to_string(session);
    if (add_scene) line += " scene=" + scene;
    for (const Field& f : fields) {
      const bool spaced = f.second.quoted && (f.second.text.empty() || f.second.text.find(' ') != std::string::npos);
      line += " " + std::string(f.first) + "=" + (spaced ? nlohmann::json(f.second.text).dump() : f.second.text);
    }
  }
  line += "\n";
  std::lock_guard lock(mu_);
  std::fputs(line.c_str(), out_);
  std::fflush(out_);
}

}  // namespace vistream::server
