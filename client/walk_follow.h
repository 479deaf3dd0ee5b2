#pragma once
// Following a walk (client/walkthrough.h): the walks a run may follow (the scene catalog's,
// then the server's own from SceneInfo.paths), the walk made from one of them at a speed, and
// the place on it to start from when the window's walk list asks to follow it "from here".
// The walkthrough loop's part (choosing, following, the start pose) is in
// client/walk_follow.cpp with these.

#include <functional>
#include <string>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>

#include "proto/walkthrough.pb.h"
#include "scenes/scene.h"
#include "scenes/walk.h"

namespace vistream::client {

// The walk along `path` at `speed_mps` (m/s). With `scene` (may be null) holding terrain, the
// eye keeps its height above the ground; otherwise above z = 0 (scene-local metres). Errors:
// scenes::Walk::Create's (a path of fewer than two distinct points, a speed not above 0).
absl::StatusOr<scenes::Walk> MakeWalk(const scenes::WalkPath& path, double speed_mps, const scenes::Scene* scene);

// Seconds along `walk` (from its start, at its speed) of its point nearest `eye` (scene-local
// xy, metres), searched a metre apart.
double NearestWalkTime(const scenes::Walk& walk, const glm::dvec2& eye);

// Adds the server's walks (`info.paths`) to `walks` at the speed and eye height of its first
// walk (else the defaults), in the server's order. A walk whose name is taken keeps the earlier
// one; one that is no named polyline (no name, fewer than two points, an odd or non-finite
// coordinate list) is left out and said through `log` (may be empty).
void AddServerWalks(const v1::SceneInfo& info, std::vector<scenes::WalkPath>* walks,
                    const std::function<void(const std::string&)>& log);

}  // namespace vistream::client
