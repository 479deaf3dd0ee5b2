#include "visibility/discovery_rays.h"

#include <glm/geometric.hpp>
#include <limits>

namespace vistream::visibility {

std::optional<double> DiscoveryLambda(const DiscoveryFan& fan, RTCScene object, uint64_t* rays, int depth) {
  if (!(glm::length(fan.to - fan.from) > 0.0) || !(fan.radius > 0.0)) return std::nullopt;
  auto meets = [&](double lambda) {
    const glm::dvec3 dir = fan.to + lambda * fan.radius * fan.d - fan.from;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRay ray;
    ray.org_x = static_cast<float>(fan.from.x);
    ray.org_y = static_cast<float>(fan.from.y);
    ray.org_z = static_cast<float>(fan.from.z);
    ray.dir_x = static_cast<float>(dir.x);
    ray.dir_y = static_cast<float>(dir.y);
    ray.dir_z = static_cast<float>(dir.z);
    // t in units of dir, which reaches to's plane at t = 1: from a millionth of the way on, as
    // the exact search counts meetings.
    ray.tnear = 1e-6f;
    ray.tfar = std::numeric_limits<float>::infinity();
    ray.mask = ~0u;
    ray.flags = 0;
    ray.time = 0.0f;
    ray.id = 0;
    rtcOccluded1(object, &ctx, &ray);
    ++*rays;
    return ray.tfar < 0.0f;  // Embree marks an occluded ray with tfar = -inf
  };
  double hit = 0.0, miss = 1.0;
  if (meets(0.0)) {
    if (meets(1.0)) return std::nullopt;
  } else {
    if (!meets(-1.0)) return std::nullopt;
    hit = -1.0;
    miss = 0.0;
  }
  for (int k = 0; k < depth; ++k) {
    const double mid = 0.5 * (hit + miss);
    (meets(mid) ? hit : miss) = mid;
  }
  return hit;
}

}  // namespace vistream::visibility
