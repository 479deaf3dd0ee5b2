#pragma once
// Plots through gnuplot (Debian's gnuplot-nox, its pngcairo terminal), run as a subprocess:
// the caller writes the plot commands and the data as text; this unit writes them to files,
// runs gnuplot on them and reports its errors. Used by `bench agvs --plot` and `report`.

#include <string>
#include <vector>

#include <absl/status/status.h>

namespace vistream::tools {

struct GnuplotData {
  std::string name;  // a file name the script reads, e.g. "agvs.dat" (no folders)
  std::string text;  // whitespace-separated columns; blank lines separate data blocks
};

struct GnuplotPlot {
  std::string png;     // the PNG to write
  int width = 1200;    // pixels
  int height = 800;
  std::string script;  // the plot commands, after the terminal and output lines this unit writes
  std::vector<GnuplotData> data;
  // Keep the script and the data beside the PNG (OUT.gp, OUT.<name>) so that the figure can
  // be redrawn; else they go to a temporary folder that is removed afterwards.
  bool keep_sources = false;

  // A `width` x `height` pixel plot to `png` whose script and data are kept beside it: the
  // report's figures, which a reader can redraw. The caller adds the script and the data.
  static GnuplotPlot Kept(std::string png, int width, int height);
};

// Writes the script and data, runs gnuplot (VISTREAM_GNUPLOT if set, else `gnuplot` on PATH)
// in the folder that holds them, and checks that the PNG was written. Errors: NOT_FOUND when
// gnuplot is missing (the message names it and the Debian package), INTERNAL with gnuplot's
// own message when it fails, UNAVAILABLE when a file cannot be written.
absl::Status RunGnuplot(const GnuplotPlot& plot);

// `s` as a gnuplot string literal (single quotes; a quote doubled).
std::string GnuplotQuote(const std::string& s);

}  // namespace vistream::tools
