#pragma once
// The page `vistream report` writes: Markdown with tables and images, built section by section
// from the steps it runs (this binary as a subprocess, with --json). A step that fails leaves a
// "not produced" note naming the command and what it said, never a number.

#include <optional>
#include <string>
#include <vector>

#include <absl/status/status.h>
#include <nlohmann/json.hpp>

#include "tools/gnuplot.h"

namespace vistream::tools {

// Numbers from the steps' JSON as the page prints them: whole with thousands separators,
// fixed decimals, or the shortest form.
std::string Int(const nlohmann::json& v);
std::string Fixed(const nlohmann::json& v, int digits);
std::string Fixed(double v, int digits);
std::string Number(const nlohmann::json& v);

class Page {
 public:
  // `self`: this binary; `dir`: where the page and its images go.
  Page(std::string self, std::string dir) : self_(std::move(self)), dir_(std::move(dir)) {}

  std::string Path(const std::string& name) const;

  void Title(const std::string& s);
  void Heading(const std::string& s);
  void Text(const std::string& s);
  void Table(const std::vector<std::string>& head, const std::vector<std::vector<std::string>>& rows);
  void Image(const std::string& name, const std::string& alt);  // a file in the folder

  // Runs `vistream ARGS` (which must print one JSON object), names the command on the page
  // (unless `show_command` is false: a sweep names its commands once, in its own words; every
  // command is in the steps table anyway) and returns the object; on failure writes why on the
  // page and returns nothing.
  std::optional<nlohmann::json> Run(const std::string& step, const std::vector<std::string>& args,
                                    bool show_command = true);
  // The same for a command that writes `file` (in the folder) and prints no JSON.
  bool RunForFile(const std::string& step, const std::vector<std::string>& args, const std::string& file);
  // The raw result, for a step whose failure may be an answer (a missing subcommand); a
  // failure is counted and said on the page only when `counts_as_failure`.
  struct Raw {
    int exit_code = 0;
    std::string out, err;
  };
  Raw RunRaw(const std::string& step, const std::vector<std::string>& args, bool counts_as_failure);
  // Draws a gnuplot plot (its sources kept beside the PNG).
  bool Plot(const std::string& step, const GnuplotPlot& plot);
  // Whether a step wrote `name`; notes it on the page when it did not.
  bool CheckFile(const std::string& name);
  // A section that could not be produced, and why (not counted as a failure: e.g. a
  // subcommand this build does not have yet).
  void NotProduced(const std::string& why);
  // A step that failed: counted, and said on the page.
  void Failed(const std::string& command, const std::string& what);
  // "vistream ARGS" as the page shows it.
  std::string Command(const std::vector<std::string>& args) const;

  // What the last step's non-zero exit meant, when it was an answer rather than a failure.
  void SetLastResult(const std::string& result);
  void StepTable();
  absl::Status Write(const std::string& name) const;
  nlohmann::json Summary() const;
  size_t failures() const { return failures_; }
  const std::vector<std::string>& images() const { return images_; }

 private:
  struct Step {
    std::string name, command;
    double seconds = 0.0;
    bool ok = false;
    std::string result;  // for the step table: "ok", "failed", or what a non-zero exit meant
  };
  void Log(const Step& s, bool counted);

  std::string self_, dir_;
  std::string md_;
  std::vector<Step> steps_;
  std::vector<std::string> images_;
  size_t failures_ = 0;
};

}  // namespace vistream::tools
