#include "tools/report_page.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>

#include "tools/cli_common.h"
#include "tools/subprocess.h"

namespace vistream::tools {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string Thousands(long long n) {
  std::string digits = std::to_string(n < 0 ? -n : n), out;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return (n < 0 ? "-" : "") + out;
}

// A shell-like rendering of one argument: quoted when empty or holding spaces.
std::string Arg(const std::string& a) {
  if (!a.empty() && a.find_first_of(" '\"|&;<>()$`\\*?") == std::string::npos) return a;
  return "'" + a + "'";
}

}  // namespace

std::string Int(const json& v) {
  if (!v.is_number()) return "–";
  return Thousands(std::llround(v.get<double>()));
}

std::string Fixed(double v, int digits) {
  if (!std::isfinite(v)) return "–";
  if (digits == 0 && std::abs(v) >= 1000) return Thousands(std::llround(v));
  return absl::StrFormat("%.*f", digits, v);
}

std::string Fixed(const json& v, int digits) { return v.is_number() ? Fixed(v.get<double>(), digits) : "–"; }

std::string Number(const json& v) { return v.is_number() ? absl::StrFormat("%g", v.get<double>()) : "–"; }

std::string Page::Path(const std::string& name) const { return (fs::path(dir_) / name).string(); }

void Page::Title(const std::string& s) { absl::StrAppend(&md_, "# ", s, "\n\n"); }
void Page::Heading(const std::string& s) { absl::StrAppend(&md_, "## ", s, "\n\n"); }
void Page::Text(const std::string& s) { absl::StrAppend(&md_, s, "\n\n"); }

void Page::Table(const std::vector<std::string>& head, const std::vector<std::vector<std::string>>& rows) {
  absl::StrAppend(&md_, "| ", absl::StrJoin(head, " | "), " |\n|");
  for (size_t c = 0; c < head.size(); ++c) absl::StrAppend(&md_, c == 0 ? "---|" : "---:|");
  md_ += "\n";
  for (const auto& r : rows) absl::StrAppend(&md_, "| ", absl::StrJoin(r, " | "), " |\n");
  md_ += "\n";
}

void Page::Image(const std::string& name, const std::string& alt) {
  absl::StrAppend(&md_, "![", alt, "](", name, ")\n\n");
  images_.push_back(name);
}

std::string Page::Command(const std::vector<std::string>& args) const {
  std::string s = "vistream";
  for (const std::string& a : args) absl::StrAppend(&s, " ", Arg(a));
  return s;
}

void Page::Log(const Step& s, bool counted) {
  // A step whose failure is an answer (a probe) shows its result, not a failure.
  // (A probe's page result is set after this line: here only that its exit was its answer.)
  // A step cut short by ^C or SIGTERM shows as stopped, not failed.
  const std::string state = s.ok                    ? ""
                            : s.result == "stopped" ? "STOPPED  "
                            : counted               ? "FAILED  "
                                                    : "(probe: its exit status is the answer)  ";
  std::fprintf(stderr, "report: [%zu] %-22s %7.1f s  %s%s\n", steps_.size(), s.name.c_str(), s.seconds, state.c_str(),
               s.command.c_str());
  std::fflush(stderr);
}

void Page::Failed(const std::string& command, const std::string& what) {
  ++failures_;
  absl::StrAppend(&md_, "**Not produced**: `", command, "` failed: ", what, "\n\n");
}

Page::Raw Page::RunRaw(const std::string& step, const std::vector<std::string>& args, bool counts_as_failure) {
  // Stopped (^C, SIGTERM): no more steps; the report says so and writes no page.
  if (CancelFlag().load()) return {130, "", "stopped"};
  std::vector<std::string> argv = {self_};
  argv.insert(argv.end(), args.begin(), args.end());
  const std::string command = Command(args);
  std::fprintf(stderr, "report: [%zu] %s ...\n", steps_.size() + 1, step.c_str());
  std::fflush(stderr);
  const absl::StatusOr<ProcessResult> r = RunProcess(argv, &CancelFlag());
  Step s{step, command, r.ok() ? r->seconds : 0.0, r.ok() && r->exit_code == 0, ""};
  s.result = s.ok                  ? "ok"
             : CancelFlag().load() ? "stopped"
             : r.ok()              ? absl::StrCat("failed (exit ", r->exit_code, ")")
                                   : "failed (not started)";
  steps_.push_back(s);
  Log(s, counts_as_failure);
  if (!r.ok()) {
    if (counts_as_failure) Failed(command, std::string(r.status().message()));
    return {255, "", std::string(r.status().message())};
  }
  if (r->exit_code != 0 && counts_as_failure) {
    Failed(command, absl::StrCat("exit ", r->exit_code, "\n\n```\n", LastLines(r->err, 8), "\n```"));
  }
  return {r->exit_code, r->out, r->err};
}

std::optional<json> Page::Run(const std::string& step, const std::vector<std::string>& args, bool show_command) {
  if (show_command) absl::StrAppend(&md_, "Command: `", Command(args), "`\n\n");
  const Raw r = RunRaw(step, args, true);
  if (r.exit_code != 0) return std::nullopt;
  json j = json::parse(r.out, nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    steps_.back().ok = false;
    steps_.back().result = "failed (no JSON)";
    Failed(Command(args), "its output is not one JSON object");
    return std::nullopt;
  }
  return j;
}

bool Page::RunForFile(const std::string& step, const std::vector<std::string>& args, const std::string& file) {
  absl::StrAppend(&md_, "Command: `", Command(args), "`\n\n");
  if (RunRaw(step, args, true).exit_code != 0) return false;
  return CheckFile(file);
}

bool Page::Plot(const std::string& step, const GnuplotPlot& plot) {
  const auto start = std::chrono::steady_clock::now();
  const absl::Status st = RunGnuplot(plot);
  const std::string name = fs::path(plot.png).filename().string();
  Step s{step, "gnuplot " + fs::path(plot.png).stem().string() + ".gp", SecondsSince(start), st.ok(), ""};
  s.result = st.ok() ? "ok" : "failed";
  steps_.push_back(s);
  Log(s, true);
  if (!st.ok()) {
    Failed(s.command, std::string(st.message()));
    return false;
  }
  absl::StrAppend(&md_, "Plot: gnuplot, from the numbers above (`", fs::path(plot.png).stem().string(),
                  ".gp` and its data files beside the PNG redraw it).\n\n");
  return true;
}

bool Page::CheckFile(const std::string& name) {
  std::error_code ec;
  if (fs::exists(Path(name), ec) && fs::file_size(Path(name), ec) > 0) return true;
  Failed(name, "the step did not write it");
  return false;
}

void Page::NotProduced(const std::string& why) { absl::StrAppend(&md_, "**Not produced**: ", why, "\n\n"); }

void Page::SetLastResult(const std::string& result) {
  if (!steps_.empty()) steps_.back().result = result;
}

void Page::StepTable() {
  std::vector<std::vector<std::string>> rows;
  for (const Step& s : steps_) rows.push_back({s.name, "`" + s.command + "`", Fixed(s.seconds, 1), s.result});
  Table({"step", "command", "seconds", "result"}, rows);
}

absl::Status Page::Write(const std::string& name) const { return WriteFile(Path(name), md_); }

json Page::Summary() const {
  json j;
  j["out"] = dir_;
  j["report"] = Path("report.md");
  j["images"] = images_;
  j["failures"] = failures_;
  j["steps"] = json::array();
  for (const Step& s : steps_) {
    j["steps"].push_back({{"name", s.name}, {"command", s.command}, {"seconds", s.seconds}, {"ok", s.ok}, {"result", s.result}});
  }
  return j;
}

}  // namespace vistream::tools
