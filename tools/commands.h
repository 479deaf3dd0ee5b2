#pragma once
// Subcommand registration for the vistream tool. Each Add* function adds its subcommands to
// `app`; a subcommand's callback reports its exit code through `done`.

#include <functional>

#include <CLI/CLI.hpp>

namespace vistream::tools {

void AddSceneCommands(CLI::App& app, std::function<void(int)> done);
void AddPvsCommand(CLI::App& app, std::function<void(int)> done);
void AddEpsilonCommand(CLI::App& app, std::function<void(int)> done);
void AddAgvsCommand(CLI::App& app, std::function<void(int)> done);
void AddCheckCommand(CLI::App& app, std::function<void(int)> done);
void AddReportCommand(CLI::App& app, std::function<void(int)> done);
void AddBenchCommands(CLI::App& app, std::function<void(int)> done);
void AddSimulateCommand(CLI::App& app, std::function<void(int)> done);
// `bench epsilon`, added to the bench subcommand by AddBenchCommands.
void AddBenchEpsilonCommand(CLI::App* bench, std::function<void(int)> done);
// `bench agvs`, likewise.
void AddBenchAgvsCommand(CLI::App* bench, std::function<void(int)> done);
// `bench server`, likewise.
void AddBenchServerCommand(CLI::App* bench, std::function<void(int)> done);
// `bench client`, likewise.
void AddBenchClientCommand(CLI::App* bench, std::function<void(int)> done);
void AddBenchWebCommand(CLI::App* bench, std::function<void(int)> done);

}  // namespace vistream::tools
