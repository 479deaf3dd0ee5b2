#pragma once
// Running the vistream tool in cli_test: the real binary (VISTREAM_BIN), its output and exit code.
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "tests/temp_dir.h"

namespace vistream::testing {

// The tool's exit codes (docs/tool.md): run-time errors 1, bad options 2.
inline constexpr int kRunTimeError = 1;
inline constexpr int kBadOption = 2;

struct RunResult {
  int exit_code;    // the tool's own; 128 + N when a signal N ended it (a crash is no exit code a test expects)
  std::string out;  // stdout and stderr
};

// What a shell command line printed on stdout (its own redirections decide the rest).
inline std::string ShellOutput(const std::string& cmd) {
  FILE* pipe = popen(cmd.c_str(), "r");
  EXPECT_NE(pipe, nullptr) << cmd;
  if (pipe == nullptr) return "";
  std::string out;
  std::array<char, 4096> buf;
  while (size_t n = fread(buf.data(), 1, buf.size(), pipe)) out.append(buf.data(), n);
  pclose(pipe);
  return out;
}

// `shell` runs in the shell first (e.g. "ulimit -f 64; "), and applies to the tool.
inline RunResult Vistream(const std::string& args, const std::string& shell = "") {
  // exec: the shell becomes the tool, so a crash shows as the tool's signal, not as sh's status.
  const std::string cmd = shell + "exec " + std::string(VISTREAM_BIN " ") + args + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  EXPECT_NE(pipe, nullptr);
  std::string out;
  std::array<char, 4096> buf;
  while (size_t n = fread(buf.data(), 1, buf.size(), pipe)) out.append(buf.data(), n);
  const int status = pclose(pipe);
  if (WIFSIGNALED(status)) return {128 + WTERMSIG(status), out + "\n[killed by signal " + std::to_string(WTERMSIG(status)) + "]"};
  return {WIFEXITED(status) ? WEXITSTATUS(status) : 255, out};
}

// A bad option: exit 2, "vistream: error: " then `message` (which starts with the option's
// name), and a hint to --help; no CLI11 bounds with hundreds of digits.
inline void ExpectBadOption(const std::string& args, const std::string& message) {
  const RunResult r = Vistream(args);
  EXPECT_EQ(r.exit_code, kBadOption) << args << "\n" << r.out;
  EXPECT_NE(r.out.find("vistream: error: " + message), std::string::npos) << args << "\n" << r.out;
  EXPECT_NE(r.out.find("--help' for the options"), std::string::npos) << args << "\n" << r.out;
  EXPECT_EQ(r.out.find("179769"), std::string::npos) << args << "\n" << r.out;
  EXPECT_LT(r.out.size(), 400u) << args << "\n" << r.out;
}

// A run-time error: exit 1 and "vistream: error: ..." holding `message`.
inline void ExpectRunTimeError(const std::string& args, const std::string& message) {
  const RunResult r = Vistream(args);
  EXPECT_EQ(r.exit_code, kRunTimeError) << args << "\n" << r.out;
  EXPECT_NE(r.out.find("vistream: error: "), std::string::npos) << args << "\n" << r.out;
  EXPECT_NE(r.out.find(message), std::string::npos) << args << "\n" << r.out;
}

// A path in the process's own temporary folder (emptied at start, removed at exit).
inline std::string Tmp(const std::string& name) { return ProcessTempDir() + "/" + name; }

}  // namespace vistream::testing
