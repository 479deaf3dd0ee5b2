#include "server/server_command_line.h"

#include <algorithm>
#include <functional>
#include <string_view>
#include <type_traits>
#include <variant>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli/number_options.h"

namespace vistream::server {

namespace {

CLI::Validator TextValidator(const TextCheck& check, const char* type_name) {
  return CLI::Validator(
      [check](std::string& text) -> std::string {
        if (check.empty_ok && text.empty()) return "";
        if (!check.ok(text)) return "'" + text + "' is " + check.what;
        return "";
      },
      type_name);
}

// The settings that have an option, in --help's order.
std::vector<const ServerSetting*> OptionSettings() {
  std::vector<const ServerSetting*> out;
  for (const ServerSetting& s : ServerSettings()) {
    if (s.option != nullptr) out.push_back(&s);
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const ServerSetting* a, const ServerSetting* b) { return a->help_order < b->help_order; });
  return out;
}

}  // namespace

ServerCommandLine::ServerCommandLine(CLI::App* app) : app_(app) {
  for (const ServerSetting* s : OptionSettings()) {
    const OptionRule& rule = s->check;
    std::visit(
        [&](auto member) {
          auto* value = [&] {
            if constexpr (std::is_invocable_v<decltype(member), ServerConfig&>) {
              return &std::invoke(member, values_);
            } else {
              return &std::invoke(member, scene_values_);
            }
          }();
          using T = std::remove_pointer_t<decltype(value)>;
          if constexpr (std::is_same_v<T, bool>) {
            app_->add_flag(s->option, *value, s->help);
          } else {
            CLI::Option* o = app_->add_option(s->option, *value, s->help);
            switch (rule.kind) {
              case OptionRule::Kind::kWhole:
                o->check(vistream::cli::WholeRange(static_cast<int64_t>(rule.lo), static_cast<int64_t>(rule.hi)));
                break;
              case OptionRule::Kind::kNumber: o->check(vistream::cli::FiniteRange(rule.lo, rule.hi)); break;
              case OptionRule::Kind::kPowerOfTwo:
                o->check(vistream::cli::PowerOfTwo(static_cast<int64_t>(rule.lo), static_cast<int64_t>(rule.hi)));
                break;
              case OptionRule::Kind::kChoice: o->check(CLI::IsMember(rule.choices)); break;
              case OptionRule::Kind::kText: o->check(TextValidator(rule.text, rule.type_name)); break;
              case OptionRule::Kind::kAny:
              case OptionRule::Kind::kFlag: break;
            }
            if (rule.show_default) o->capture_default_str();
          }
        },
        s->field);
  }
}

bool ServerCommandLine::given(const char* option) const { return app_->count(option) > 0; }

std::string ServerCommandLine::StoreOptionWithoutStore(const ServerConfig& file) const {
  if (!file.store_address.empty()) return "";
  const ServerSetting* address = nullptr;
  for (const ServerSetting& s : ServerSettings()) {
    if (std::string_view(s.table) == "store" && std::string_view(s.key) == "address") address = &s;
  }
  if (address != nullptr && given(address->option)) return "";
  for (const ServerSetting& s : ServerSettings()) {
    if (std::string_view(s.table) == "store" && &s != address && s.option != nullptr && given(s.option)) return s.option;
  }
  return "";
}

SceneConfig ServerCommandLine::SceneFromOptions(const std::string& name) const {
  SceneConfig scene = scene_values_;
  scene.name = name;
  return scene;
}

void ServerCommandLine::MergeInto(ServerConfig* config) const {
  for (const ServerSetting* s : OptionSettings()) {
    if (!given(s->option)) continue;
    std::visit(
        [&](auto member) {
          if constexpr (std::is_invocable_v<decltype(member), ServerConfig&>) {
            std::invoke(member, *config) = std::invoke(member, values_);
          } else {
            for (SceneConfig& scene : config->scenes) std::invoke(member, scene) = std::invoke(member, scene_values_);
          }
        },
        s->field);
  }
}

}  // namespace vistream::server
