#pragma once
// The thin client's main loop (DESIGN.md "Server and client"), shared by its two front ends:
// a GLFW window (WASD and mouse, or following a walk) and a headless OSMesa run that follows a
// walk from the scene catalog. Each frame takes what the network thread decoded, uploads within
// a budget, and draws, never waiting for the server: the ε-mask of a neighbourhood the eye is
// in once every object it lists is uploaded (a masked frame: those objects, only their masked
// triangles; of several, the one with the fewest triangles); else the current viewcell's PVS
// once it is complete; else what is held (a hole frame). A stall is a frame drawn inside a
// viewcell whose PVS geometry has not fully arrived (list, objects, and their upload), masked
// or not.
// The loop's parts (start-up, walk following, the frame loop, the window's keys) are named in
// client/walkthrough_loop.h; the summary in client/walkthrough_summary.h.

#include <absl/status/status.h>
#include <absl/status/statusor.h>

#include "client/walkthrough_options.h"
#include "client/walkthrough_summary.h"

namespace vistream::client {

// Runs one walkthrough against the server at options.server. Errors name what failed: an
// unreachable server or another protocol version (UNAVAILABLE, FAILED_PRECONDITION), a walk
// neither the catalog nor the server has (NOT_FOUND, listing every walk of both), no window (UNAVAILABLE), the server
// ending the session for good (its status), the first viewcell not arriving in time.
absl::StatusOr<WalkthroughSummary> RunWalkthrough(const WalkthroughOptions& options);
// The same, filling *summary with what was done even when it fails (a walk that gave up on a
// lost server has walked, drawn and received until then; the summary says how much).
absl::Status RunWalkthrough(const WalkthroughOptions& options, WalkthroughSummary* summary);

// The summary's JSON and lines: client/walkthrough_summary.h.

}  // namespace vistream::client
