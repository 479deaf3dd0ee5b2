#include "scenes/progress.h"

#include <unistd.h>

#include <cstdio>

namespace vistream::scenes {

namespace {
std::atomic<bool> g_quiet{false};
}  // namespace

void Progress::SetQuiet(bool quiet) { g_quiet.store(quiet); }

Progress::Progress(std::string label, uint64_t total, const std::atomic<bool>* cancel)
    : label_(std::move(label)),
      total_(total == 0 ? 1 : total),
      terminal_(isatty(STDERR_FILENO) != 0),
      cancel_(cancel),
      start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() {
  if (!finished_ && terminal_ && last_permille_ >= 0 && !g_quiet.load()) std::fputc('\n', stderr);
}

void Progress::Advance(uint64_t units) {
  done_ += units;
  if (done_ > total_) done_ = total_;
  Print(false);
}

void Progress::Finish() {
  if (finished_) return;
  done_ = total_;
  Print(true);
  finished_ = true;
}

void Progress::Print(bool final_line) {
  if (g_quiet.load()) return;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const int permille = static_cast<int>(1000 * done_ / total_);
  if (terminal_) {
    if (!final_line && permille == last_permille_) return;
    last_permille_ = permille;
    constexpr int kWidth = 30;
    const int filled = permille * kWidth / 1000;
    std::fprintf(stderr, "\r%-24s [%.*s%*s] %5.1f%%  %6.1f s  %s", label_.c_str(), filled,
                 "##############################", kWidth - filled, "", permille / 10.0, seconds, detail_.c_str());
    if (final_line) std::fputc('\n', stderr);
    std::fflush(stderr);
    return;
  }
  const int decile = permille / 100;
  if (!final_line && decile == last_decile_) return;
  last_decile_ = decile;
  if (final_line) {
    std::fprintf(stderr, "%s: done in %.2f s\n", label_.c_str(), seconds);
  } else {
    std::fprintf(stderr, "%s: %d%% after %.1f s  %s\n", label_.c_str(), decile * 10, seconds, detail_.c_str());
  }
}

}  // namespace vistream::scenes
