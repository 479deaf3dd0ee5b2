#pragma once
// Arrival margins as the client sees them (DESIGN.md "Measures"): for each viewcell the walk
// enters, when it entered, when the cell's PVS was complete (its list and every object on it
// held and uploaded), and the margin between the two: positive when the geometry was there
// first, negative when the client walked in before it (a stall). The discrete-event simulator
// (simulation/simulator.h) reports the same records for the same walk.

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace vistream::client {

struct CellEntry {
  uint32_t cell = 0;
  int i = 0, j = 0;          // the cell's grid coordinates
  double entered_s = 0.0;    // walk clock: the first frame drawn in it
  // The latest time before the entry at which the cell was complete (and stayed so up to the
  // entry); if it was incomplete at the entry, when it completed afterwards; if the walk left
  // the cell (or ended) before that, the time it left: a bound, the true margin is lower.
  double complete_s = 0.0;
  double margin_s = 0.0;     // entered_s - complete_s
  bool stalled = false;      // a frame was drawn in it incomplete
  bool start = false;        // the walk's first cell: the walk waited for it; not a margin
};

struct MarginSummary {
  uint64_t cells_entered = 0;  // entries after the start cell (a cell entered twice counts twice)
  uint64_t stalled_cells = 0;  // of those, entries with a stalled frame
  std::optional<double> min_margin_s, mean_margin_s;  // over those entries; none without any
};

class CellMargins {
 public:
  // One frame at walk-clock `t_s` (seconds; earlier frames had smaller times): `lists` are the
  // PVS lists the client holds by cell, `ready(id)` whether an object is held and uploaded,
  // `current` the eye's cell, `stalled` whether this frame was a stall.
  void Observe(double t_s, const std::map<uint32_t, std::vector<uint32_t>>& lists,
               const std::function<bool(uint32_t)>& ready, std::optional<uint32_t> current, int grid_nx,
               bool stalled);
  // Shifts every time recorded so far by `dt_s` (the walk's clock starts after start-up).
  void Shift(double dt_s);
  // The walk ended at `t_s`: an entry still waiting for its cell gets that as its bound.
  void Finish(double t_s);

  const std::vector<CellEntry>& entries() const { return entries_; }
  MarginSummary Summary() const;
  // CSV: cell_id,i,j,entered_s,complete_s,margin_s,stalled (a header line, then one per entry).
  std::string Csv() const;

 private:
  std::map<uint32_t, double> complete_since_;  // cells complete now, since when
  std::vector<CellEntry> entries_;
  bool waiting_ = false;  // the last entry's cell has not been complete since it was entered
  std::optional<uint32_t> current_;
};

}  // namespace vistream::client
