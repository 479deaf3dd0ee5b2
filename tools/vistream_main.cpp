// vistream: scene preparation, visibility tools, benchmarks and reports.
#include <CLI/CLI.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"vistream: visibility streaming for city walkthroughs", "vistream"};
  app.require_subcommand(1);
  int exit_code = 0;
  auto done = [&exit_code](int code) { exit_code = code; };
  vistream::tools::AddSceneCommands(app, done);
  vistream::tools::AddPvsCommand(app, done);
  vistream::tools::AddEpsilonCommand(app, done);
  vistream::tools::AddAgvsCommand(app, done);
  vistream::tools::AddCheckCommand(app, done);
  vistream::tools::AddBenchCommands(app, done);
  vistream::tools::AddSimulateCommand(app, done);
  vistream::tools::AddReportCommand(app, done);
  vistream::tools::InstallCancelHandler();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return vistream::tools::ParseFailure(app, e);  // 0 after --help, else 2
  }
  return exit_code;
}
