#pragma once
// --verify: what a frame drew against the full scene, in the object-id buffer (gl/id_renderer.h).
// Conservative visibility draws every object (and, masked, every triangle) that the full scene
// shows at a pixel, so without levels of detail no pixel may differ. With levels (issue 45) an
// object drawn at a level may differ from its full mesh by the level's error, which the server
// keeps within the client's screen error tau: a differing pixel then lies within about tau
// pixels of a full-detail silhouette (in the full frame, an edge between two objects, or
// between two surfaces of one object where one passes behind the other), which
// CompareWithFullScene measures.

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
  // The largest Euclidean distance, in pixels, from a differing pixel to the nearest pixel on a
  // full-detail silhouette (in the full frame, a pixel whose object differs from a 4-neighbour's,
  // or whose triangle does not join the neighbour's: they share no edge, or one faces the eye
  // and the other away, as where a building's lower block hides the foot of its upper one);
  // 0 when no pixel differs. With no silhouette in the frame at all, the frame's diagonal.
  double max_silhouette_px = 0.0;
};

// Renders the full scene and the drawn set (`drawn`: objects whole, or those marked masked only
// with their triangles of `mask`, when given; each at its level, which needs an id renderer made
// with levels; an object drawn as its piece of a cluster level, DrawnObject::cluster) from
// `camera` (scene-local metres) into `ids`, made from `scene`, and counts the pixels that differ
// (a piece's pixel over any object its cluster stands for does not). Ids outside the scene are
// left out. Leaves the id renderer's context current: the caller makes its own current again. Errors: the id renderer's (GL, sizes);
// FAILED_PRECONDITION for a drawn level the id renderer does not hold.
absl::StatusOr<PixelComparison> CompareWithFullScene(gl::IdRenderer& ids, const scenes::Scene& scene,
                                                     const Camera& camera, const std::vector<DrawnObject>& drawn,
                                                     const EpsilonMaskSet* mask);

// For each of the `width` x `height` pixels (row by row), the squared Euclidean distance in
// pixels to the nearest pixel where `source` is set (exact: Felzenszwalb & Huttenlocher 2012,
// "Distance Transforms of Sampled Functions", two passes of the 1-D lower envelope of
// parabolas); 1e20 everywhere when no pixel is set.
std::vector<double> SquaredDistanceTransform(const std::vector<uint8_t>& source, int width, int height);

}  // namespace vistream::client
