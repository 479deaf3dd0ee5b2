#pragma once
// --verify: what a frame drew against the full scene, in the object-id buffer (gl/id_renderer.h).
// Conservative visibility draws every object (and, masked, every triangle) that the full scene
// shows at a pixel, so no pixel may differ.

#include <cstdint>
#include <vector>

#include <absl/status/statusor.h>

#include "client/object_store.h"
#include "client/renderer.h"
#include "gl/id_renderer.h"
#include "scenes/scene.h"

namespace vistream::client {

struct PixelComparison {
  uint64_t differ = 0;  // pixels whose object differs between the full scene and the drawn set
  uint64_t pixels = 0;  // pixels compared (camera.width x camera.height)
};

// Renders the full scene and the drawn set (`drawn`: objects whole, or those marked masked only
// with their triangles of `mask`, when given) from `camera` (scene-local metres) into `ids`,
// made from `scene`, and counts the pixels that differ. Ids outside the scene are left out.
// Leaves the id renderer's context current: the caller makes its own current again. Errors:
// the id renderer's (GL, sizes).
absl::StatusOr<PixelComparison> CompareWithFullScene(gl::IdRenderer& ids, const scenes::Scene& scene,
                                                     const Camera& camera, const std::vector<DrawnObject>& drawn,
                                                     const EpsilonMaskSet* mask);

}  // namespace vistream::client
