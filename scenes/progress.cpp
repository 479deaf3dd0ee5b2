#include "scenes/progress.h"

namespace vistream::scenes {

Progress::Progress(const RunControl& run, std::string label, uint64_t total)
    : run_(run), label_(std::move(label)), total_(total == 0 ? 1 : total), start_(std::chrono::steady_clock::now()) {
  if (run_.progress != nullptr) run_.progress->Start(label_, total_);
}

Progress::~Progress() {
  if (!ended_ && run_.progress != nullptr) {
    run_.progress->End(label_, std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(),
                       false);
  }
}

void Progress::Advance(uint64_t units) {
  done_ += units;
  if (done_ > total_) done_ = total_;
  Report(false);
}

void Progress::Finish() {
  if (ended_) return;
  ended_ = true;
  if (run_.progress == nullptr) return;
  const bool completed = !Cancelled();
  if (completed) {
    done_ = total_;
    Report(true);
  }
  run_.progress->End(label_, std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(),
                     completed);
}

void Progress::Report(bool force) {
  if (run_.progress == nullptr) return;
  const int permille = static_cast<int>(1000 * done_ / total_);
  if (!force && permille == last_permille_) return;
  last_permille_ = permille;
  run_.progress->Update(label_, done_, total_,
                        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(), detail_);
}

}  // namespace vistream::scenes
