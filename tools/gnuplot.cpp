#include "tools/gnuplot.h"

#include <stdlib.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>

#include <absl/strings/str_cat.h>

#include "tools/cli_common.h"
#include "tools/subprocess.h"

namespace vistream::tools {

namespace fs = std::filesystem;

std::string GnuplotQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    out += c;
    if (c == '\'') out += '\'';
  }
  return out + "'";
}

GnuplotPlot GnuplotPlot::Kept(std::string png, int width, int height) {
  GnuplotPlot plot;
  plot.png = std::move(png);
  plot.width = width;
  plot.height = height;
  plot.keep_sources = true;
  return plot;
}

absl::Status RunGnuplot(const GnuplotPlot& plot) {
  std::error_code ec;
  const fs::path png = fs::absolute(plot.png, ec);
  if (ec) return absl::InvalidArgumentError(absl::StrCat("'", plot.png, "': ", ec.message()));
  // Where the script and data go, and what they are called there.
  fs::path dir;
  std::string prefix;
  if (plot.keep_sources) {
    dir = png.parent_path();
    prefix = png.stem().string() + ".";
  } else {
    std::string tmpl = (fs::temp_directory_path(ec) / "vistream-gnuplot-XXXXXX").string();
    if (mkdtemp(tmpl.data()) == nullptr) {
      return absl::UnavailableError(absl::StrCat("cannot make a temporary folder for gnuplot: ", std::strerror(errno)));
    }
    dir = tmpl;
  }
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ignored;
      if (!dir.empty()) fs::remove_all(dir, ignored);
    }
  } cleanup{plot.keep_sources ? fs::path() : dir};

  std::string script = absl::StrCat("# Written by vistream; redraw with: gnuplot ", prefix, "gp\n",
                                    "set terminal pngcairo size ", plot.width, ",", plot.height,
                                    " enhanced font 'DejaVu Sans,12' linewidth 1.5\n", "set output ",
                                    GnuplotQuote(plot.keep_sources ? png.filename().string() : png.string()),  // kept: beside its script
                                    "\n", "set encoding utf8\n");
  std::string body = plot.script;
  for (const GnuplotData& d : plot.data) {
    if (d.name.empty() || d.name.find('/') != std::string::npos) {
      return absl::InvalidArgumentError(absl::StrCat("gnuplot data file name '", d.name, "': expected a plain name"));
    }
    if (absl::Status s = WriteFile((dir / (prefix + d.name)).string(), d.text); !s.ok()) return s;
    // The script names its data without the prefix: rename the references.
    if (!prefix.empty()) {
      const std::string from = GnuplotQuote(d.name), to = GnuplotQuote(prefix + d.name);
      for (size_t at = 0; (at = body.find(from, at)) != std::string::npos; at += to.size()) body.replace(at, from.size(), to);
    }
  }
  script += body;
  const fs::path script_path = dir / (prefix + "gp");
  if (absl::Status s = WriteFile(script_path.string(), script); !s.ok()) return s;

  const char* env = std::getenv("VISTREAM_GNUPLOT");
  const std::string program = env != nullptr && *env != '\0' ? env : "gnuplot";
  fs::remove(png, ec);
  // The script reads its data by relative names: gnuplot's first command moves it to `dir`.
  const absl::StatusOr<ProcessResult> run =
      RunProcess({program, "-e", absl::StrCat("cd ", GnuplotQuote(dir.string())), script_path.string()});
  if (!run.ok() && absl::IsNotFound(run.status())) {
    return absl::NotFoundError(absl::StrCat("cannot run gnuplot ('", program,
                                            "' not found): install Debian's gnuplot-nox (./vistream.sh installs "
                                            "it) or set VISTREAM_GNUPLOT to its path"));
  }
  if (!run.ok()) return run.status();
  const std::string message = LastLines(run->err + run->out, 12);
  if (run->exit_code != 0) {
    return absl::InternalError(absl::StrCat("gnuplot failed (exit ", run->exit_code, ") on ", script_path.string(),
                                            ": ", message));
  }
  if (!fs::exists(png, ec) || fs::file_size(png, ec) == 0) {
    return absl::InternalError(absl::StrCat("gnuplot wrote no ", png.string(), ": ", message));
  }
  return absl::OkStatus();
}

}  // namespace vistream::tools
