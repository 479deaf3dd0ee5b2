// vistream-server: serves the scenes of its configuration (a TOML file, --config, whose keys the
// command-line options override; server/server_config.h, server/server_command_line.h) to
// walkthrough clients over gRPC (DESIGN.md, "Server and client", "Deployment"). This main parses
// the options, merges them over the file and checks them (bad options exit 2 before any scene
// loads); server/server_process.h runs and drains the server.

#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>
#include <absl/status/statusor.h>

#include "cli/number_options.h"
#include "cli/unexpected_arguments.h"
#include "server/link_model.h"
#include "server/server_command_line.h"
#include "server/server_config.h"
#include "server/server_process.h"

int main(int argc, char** argv) {
  std::string config_path, scene_option;
  CLI::App app{"vistream-server: streams the visible part of a city to walkthrough clients over gRPC"};
  app.add_option("--config", config_path,
                 "TOML configuration file (deploy/server.toml documents every key); options given here override its keys");
  app.add_option("--scene", scene_option,
                 "serve this one scene: catalog name, catalog .json or .glb/.gltf file (replaces the configuration's "
                 "[[scenes]])");
  // Every setting's option, from the settings table (server/server_config.h ServerSettings()).
  const vistream::server::ServerCommandLine options(&app);
  bool emulate_link = false;
  std::string link_option, time_scale_option;
  uint64_t link_seed = 1;
  app.add_flag("--emulate-link", emulate_link,
               "put each session's traffic through the link its scene's catalog entry declares "
               "(simulation.link; none declared: an ideal link)");
  app.add_option("--link", link_option,
                 "BPS,LATENCY_MS: emulate this bandwidth (bits/s, k/M/G) and one-way latency instead of the "
                 "declared ones (keeps the declared jitter and loss); implies --emulate-link");
  app.add_option("--time-scale", time_scale_option,
                 "K > 0: the emulated link runs K times faster (bandwidth x K, times / K), for walks replayed "
                 "K times faster (default 1)");
  app.add_option("--link-seed", link_seed, "seed of the emulated links' jitter and loss draws")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 9007199254740991.0));  // a whole number from 0 to 2^53 - 1
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (dynamic_cast<const CLI::Success*>(&e) != nullptr) return app.exit(e);
    // Bad options exit 2 before the scene loads, in the vistream tool's form; unknown ones
    // first (a misspelt option often hides a required one).
    std::string message = vistream::cli::UnexpectedArguments(app.remaining(), "vistream-server");
    if (message.empty()) message = e.what();
    for (const std::string& r : app.remaining()) {
      if (r == "--port" || r.rfind("--port=", 0) == 0) message += " (the address is --listen HOST:PORT)";
    }
    std::fprintf(stderr, "vistream-server: error: %s\nRun 'vistream-server --help' for the options.\n", message.c_str());
    return 2;
  }
  double time_scale = 1.0;
  if (app.count("--time-scale") > 0) {
    if (!vistream::cli::internal::ParseFinite(time_scale_option, &time_scale) || !(time_scale > 0.0) ||
        time_scale > 1e6) {
      std::fprintf(stderr, "vistream-server: error: --time-scale: '%s' is not a number greater than 0 and at most "
                           "1e6 (e.g. 20: the link runs 20 times faster)\n",
                   time_scale_option.c_str());
      return 2;
    }
  }
  if (app.count("--link") > 0) {
    // Checked now (bad options exit 2 before the scene loads); applied to the declared link below.
    absl::StatusOr<vistream::scenes::LinkSpec> check = vistream::server::ParseLinkOption(link_option, std::nullopt);
    if (!check.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s\n", std::string(check.status().message()).c_str());
      return 2;
    }
    emulate_link = true;
  }
  if (!emulate_link && (app.count("--time-scale") > 0 || app.count("--link-seed") > 0)) {
    std::fprintf(stderr, "vistream-server: error: --time-scale and --link-seed need --emulate-link or --link\n");
    return 2;
  }
  // The configuration: the file's, then what the command line gives.
  vistream::server::ServerConfig config;
  if (!config_path.empty()) {
    absl::StatusOr<vistream::server::ServerConfig> loaded = vistream::server::LoadServerConfig(config_path);
    if (!loaded.ok()) {
      std::fprintf(stderr, "vistream-server: error: %s\n", std::string(loaded.status().message()).c_str());
      return 2;
    }
    config = std::move(*loaded);
  }
  const auto given = [&](const char* option) { return app.count(option) > 0; };
  if (const std::string option = options.StoreOptionWithoutStore(config); !option.empty()) {
    // Store options without a store would be ignored: say so.
    std::fprintf(stderr, "vistream-server: error: %s: needs a PVS store: give --store HOST:PORT (or [store] "
                         "address)\nRun 'vistream-server --help' for the options.\n", option.c_str());
    return 2;
  }
  if (given("--scene")) config.scenes = {options.SceneFromOptions(scene_option)};
  options.MergeInto(&config);
  if (absl::Status st = vistream::server::CheckServerConfig(config); !st.ok()) {
    std::fprintf(stderr, "vistream-server: error: %s\nRun 'vistream-server --help' for the options.\n",
                 std::string(st.message()).c_str());
    return 2;
  }
  if (given("--pvs-file") && config.scenes.size() > 1) {
    std::fprintf(stderr, "vistream-server: error: --pvs-file: the configuration serves %zu scenes; give each its "
                         "pvs_file in [[scenes]]\n", config.scenes.size());
    return 2;
  }
  if (emulate_link && config.scenes.size() > 1) {
    std::fprintf(stderr, "vistream-server: error: --emulate-link and --link serve one scene only (the link its "
                         "catalog entry declares); this configuration serves %zu\n", config.scenes.size());
    return 2;
  }
  vistream::server::ServerProcessOptions run;
  run.config = std::move(config);
  run.given = given;
  run.emulate_link = emulate_link;
  if (app.count("--link") > 0) run.link_option = link_option;
  run.time_scale = time_scale;
  run.link_seed = link_seed;
  return vistream::server::RunServerProcess(run);
}
