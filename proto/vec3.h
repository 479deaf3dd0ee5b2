#pragma once
// The protocol's Vec3 (proto/walkthrough.proto: scene-local metres, or metres per second) to and
// from glm, for the server's edge, the client model and SceneInfo alike.

#include <glm/vec3.hpp>

#include "proto/walkthrough.pb.h"

namespace vistream {

inline void SetVec(const glm::dvec3& v, v1::Vec3* out) {
  out->set_x(v.x);
  out->set_y(v.y);
  out->set_z(v.z);
}

inline glm::dvec3 ToVec(const v1::Vec3& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace vistream
