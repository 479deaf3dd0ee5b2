#pragma once
// The vistream tool's progress sink: a bar on stderr when it is a terminal, a line per 10%
// otherwise (logs, CI), nothing when quiet (--json output).

#include <string>

#include "scenes/progress.h"

namespace vistream::tools {

class TerminalProgress : public scenes::ProgressSink {
 public:
  TerminalProgress();
  void set_quiet(bool quiet) { quiet_ = quiet; }

  void Start(std::string_view label, uint64_t total) override;
  void Update(std::string_view label, uint64_t done, uint64_t total, double seconds,
              std::string_view detail) override;
  void End(std::string_view label, double seconds, bool completed) override;

 private:
  bool terminal_;
  bool quiet_ = false;
  bool bar_open_ = false;  // a bar line without its newline yet
  int last_decile_ = -1;
};

// The tool's one sink (commands set it quiet for --json).
TerminalProgress& ToolProgress();

}  // namespace vistream::tools
