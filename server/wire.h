#pragma once
// Conversions between domain types and protocol messages, at the server's edge.

#include <glm/vec3.hpp>

#include "proto/walkthrough.pb.h"

namespace vistream::server {

inline void SetVec(const glm::dvec3& v, vistream::v1::Vec3* out) {
  out->set_x(v.x);
  out->set_y(v.y);
  out->set_z(v.z);
}

inline glm::dvec3 ToVec(const vistream::v1::Vec3& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace vistream::server
