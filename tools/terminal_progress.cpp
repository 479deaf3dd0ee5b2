#include "tools/terminal_progress.h"

#include <unistd.h>

#include <cstdio>

namespace vistream::tools {

TerminalProgress::TerminalProgress() : terminal_(isatty(STDERR_FILENO) != 0) {}

void TerminalProgress::Start(std::string_view, uint64_t) { last_decile_ = -1; }

void TerminalProgress::Update(std::string_view label, uint64_t done, uint64_t total, double seconds,
                              std::string_view detail) {
  if (quiet_) return;
  const int permille = static_cast<int>(1000 * done / (total == 0 ? 1 : total));
  if (terminal_) {
    constexpr int kWidth = 30;
    const int filled = permille * kWidth / 1000;
    std::fprintf(stderr, "\r%-24.*s [%.*s%*s] %5.1f%%  %6.1f s  %.*s", static_cast<int>(label.size()), label.data(),
                 filled, "##############################", kWidth - filled, "", permille / 10.0, seconds,
                 static_cast<int>(detail.size()), detail.data());
    std::fflush(stderr);
    bar_open_ = true;
    return;
  }
  const int decile = permille / 100;
  if (decile == last_decile_ || done == total) return;  // the end gets its own line
  last_decile_ = decile;
  std::fprintf(stderr, "%.*s: %d%% after %.1f s  %.*s\n", static_cast<int>(label.size()), label.data(), decile * 10,
               seconds, static_cast<int>(detail.size()), detail.data());
}

void TerminalProgress::End(std::string_view label, double seconds, bool completed) {
  if (quiet_) return;
  if (bar_open_) std::fputc('\n', stderr);
  bar_open_ = false;
  std::fprintf(stderr, "%.*s: %s %.2f s\n", static_cast<int>(label.size()), label.data(),
               completed ? "done in" : "stopped after", seconds);
}

TerminalProgress& ToolProgress() {
  static TerminalProgress sink;
  return sink;
}

}  // namespace vistream::tools
