#pragma once
// vistream-server's command-line options for its settings, made from the one settings table
// (server/server_config.h ServerSettings()): each setting with an option gets it (name, help
// text, check, default shown or not, in --help's order), and each option given overrides its
// key of the configuration file (docs/server.md). The options that are no setting
// (--config, --scene, the link emulation's) stay with vistream-server's main.

#include <string>

#include "server/server_config.h"

namespace CLI {
class App;
}  // namespace CLI

namespace vistream::server {

class ServerCommandLine {
 public:
  // Adds every setting's option to `app` (not owned; it must outlive this object, which holds
  // the values the options are parsed into). Not copyable: `app` holds pointers into it.
  explicit ServerCommandLine(CLI::App* app);
  ServerCommandLine(const ServerCommandLine&) = delete;
  ServerCommandLine& operator=(const ServerCommandLine&) = delete;

  // Whether `option` ("--listen") was given (after CLI::App::parse).
  bool given(const char* option) const;

  // The first option of the [store] table given while there is no store (neither --store nor
  // the file's store.address in `file`): store options without a store would be ignored.
  // Empty when there is none.
  std::string StoreOptionWithoutStore(const ServerConfig& file) const;

  // The scene settings given on the command line, for --scene's one scene (`name`): the
  // defaults where no option was given.
  SceneConfig SceneFromOptions(const std::string& name) const;

  // Overrides the keys of `config` whose options were given; a scene option applies to every
  // scene of `config`.
  void MergeInto(ServerConfig* config) const;

 private:
  CLI::App* app_;
  ServerConfig values_;      // what the options parse into
  SceneConfig scene_values_;
};

}  // namespace vistream::server
