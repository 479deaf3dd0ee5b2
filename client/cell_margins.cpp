#include "client/cell_margins.h"

#include "client/cell_completion.h"

#include <algorithm>

#include <absl/strings/str_format.h>

namespace vistream::client {

void CellMargins::Observe(double t_s, const std::map<uint32_t, std::vector<uint32_t>>& lists,
                          const std::function<bool(uint32_t)>& ready, std::optional<uint32_t> current, int grid_nx,
                          bool stalled) {
  // Which cells are complete now, and since when (a cell that lost an object starts again).
  for (auto it = complete_since_.begin(); it != complete_since_.end();) {
    it = lists.count(it->first) == 0 ? complete_since_.erase(it) : std::next(it);
  }
  for (const auto& [cell, objects] : lists) {
    const bool complete = CellComplete(&objects, ready);
    if (!complete) {
      complete_since_.erase(cell);
    } else if (complete_since_.count(cell) == 0) {
      complete_since_[cell] = t_s;
    }
  }
  if (current != current_) {
    if (waiting_ && !entries_.empty()) {  // left before it completed: a bound
      entries_.back().complete_s = t_s;
      entries_.back().margin_s = entries_.back().entered_s - t_s;
    }
    waiting_ = false;
    current_ = current;
    if (current.has_value()) {
      CellEntry e;
      e.cell = *current;
      e.i = grid_nx > 0 ? static_cast<int>(*current % static_cast<uint32_t>(grid_nx)) : 0;
      e.j = grid_nx > 0 ? static_cast<int>(*current / static_cast<uint32_t>(grid_nx)) : 0;
      e.entered_s = t_s;
      e.start = entries_.empty();
      entries_.push_back(e);
      waiting_ = true;
    }
  }
  if (!current_.has_value() || entries_.empty()) return;
  CellEntry& e = entries_.back();
  if (waiting_) {
    if (auto it = complete_since_.find(*current_); it != complete_since_.end()) {
      e.complete_s = it->second;
      e.margin_s = e.entered_s - e.complete_s;
      waiting_ = false;
    }
  }
  if (stalled) e.stalled = true;
}

void CellMargins::Shift(double dt_s) {
  for (auto& [cell, since] : complete_since_) since += dt_s;
  for (CellEntry& e : entries_) {
    e.entered_s += dt_s;
    e.complete_s += dt_s;
  }
}

void CellMargins::Finish(double t_s) {
  if (waiting_ && !entries_.empty()) {
    entries_.back().complete_s = t_s;
    entries_.back().margin_s = entries_.back().entered_s - t_s;
  }
  waiting_ = false;
}

MarginSummary CellMargins::Summary() const {
  MarginSummary s;
  double sum = 0.0;
  for (const CellEntry& e : entries_) {
    if (e.start) continue;
    ++s.cells_entered;
    if (e.stalled) ++s.stalled_cells;
    sum += e.margin_s;
    s.min_margin_s = std::min(s.min_margin_s.value_or(e.margin_s), e.margin_s);
  }
  if (s.cells_entered > 0) s.mean_margin_s = sum / static_cast<double>(s.cells_entered);
  return s;
}

std::string CellMargins::Csv() const {
  std::string out = "cell_id,i,j,entered_s,complete_s,margin_s,stalled\n";
  for (const CellEntry& e : entries_) {
    absl::StrAppendFormat(&out, "%d,%d,%d,%.4f,%.4f,%.4f,%d\n", e.cell, e.i, e.j, e.entered_s, e.complete_s,
                          e.margin_s, e.stalled ? 1 : 0);
  }
  return out;
}

}  // namespace vistream::client
