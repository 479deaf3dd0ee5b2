// vistream: scene preparation, visibility tools, benchmarks and reports.
#include <CLI/CLI.hpp>

#include "bench/cli_common.h"
#include "bench/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"vistream: visibility streaming for city walkthroughs", "vistream"};
  app.require_subcommand(1);
  int exit_code = 0;
  auto done = [&exit_code](int code) { exit_code = code; };
  vistream::cli::AddSceneCommands(app, done);
  vistream::cli::AddPvsCommand(app, done);
  vistream::cli::AddEpsilonCommand(app, done);
  vistream::cli::AddAgvsCommand(app, done);
  vistream::cli::AddCheckCommand(app, done);
  vistream::cli::AddBenchCommands(app, done);
  vistream::cli::InstallCancelHandler();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return exit_code;
}
