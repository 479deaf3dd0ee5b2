#include "client/verification.h"

#include "visibility/mask_codec.h"

namespace vistream::client {

absl::StatusOr<PixelComparison> CompareWithFullScene(gl::IdRenderer& ids, const scenes::Scene& scene,
                                                     const Camera& camera, const std::vector<DrawnObject>& drawn,
                                                     const EpsilonMaskSet* mask) {
  std::vector<uint8_t> flags(ids.triangle_count(), 0);
  for (const DrawnObject& d : drawn) {
    if (d.id >= scene.objects.size()) continue;
    const uint64_t first = ids.FirstTriangle(d.id);
    const size_t n = scene.objects[d.id].mesh.TriangleCount();
    const std::vector<uint8_t>* bits = nullptr;
    if (d.masked && mask != nullptr) bits = mask->Bits(d.id);
    for (size_t t = 0; t < n; ++t) {
      flags[first + t] = bits == nullptr || visibility::MaskBit(*bits, t) ? 1 : 0;
    }
  }
  const glm::dvec3 forward = camera.Forward(), up = camera.Up();
  absl::StatusOr<std::vector<uint32_t>> full =
      ids.RenderView(camera.eye, forward, up, camera.fov_y_rad, camera.width, camera.height, nullptr);
  if (!full.ok()) return full.status();
  absl::StatusOr<std::vector<uint32_t>> part =
      ids.RenderView(camera.eye, forward, up, camera.fov_y_rad, camera.width, camera.height, &flags);
  if (!part.ok()) return part.status();
  PixelComparison c;
  for (size_t k = 0; k < full->size(); ++k) c.differ += (*full)[k] != (*part)[k] ? 1 : 0;
  c.pixels = full->size();
  return c;
}

}  // namespace vistream::client
