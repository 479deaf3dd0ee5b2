#pragma once
// The view frustum of a pinhole camera as a conservative box test: the client's renderer culls
// with it, and the simulator counts the triangles that renderer would draw with the same one.

#include <cmath>

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

namespace vistream::scenes {

class ViewFrustum {
 public:
  // `eye` in scene-local metres; `forward` and `up` unit vectors, orthogonal; `fov_y_rad` the
  // vertical field of view (radians, in (0, pi)); `aspect` width over height (> 0). The planes
  // are the four sides through the eye and the eye plane facing forward; the far plane is left
  // out (beyond the scene), as glm::perspective's near plane is a hair in front of the eye.
  ViewFrustum(const glm::dvec3& eye, const glm::dvec3& forward, const glm::dvec3& up, double fov_y_rad, double aspect)
      : eye_(eye) {
    const glm::dvec3 right = glm::normalize(glm::cross(forward, up));
    const double ty = std::tan(0.5 * fov_y_rad), tx = ty * aspect;
    normals_[0] = forward * tx + right;  // inward normals
    normals_[1] = forward * tx - right;
    normals_[2] = forward * ty + up;
    normals_[3] = forward * ty - up;
    normals_[4] = forward;
  }

  // Whether any part of the box [box_min, box_max] (scene-local metres) may be inside.
  // Conservative: false only when the box lies wholly outside one plane.
  bool MayOverlap(const glm::dvec3& box_min, const glm::dvec3& box_max) const {
    for (const glm::dvec3& n : normals_) {
      // The box corner farthest along n, relative to the eye.
      const glm::dvec3 p(n.x >= 0 ? box_max.x : box_min.x, n.y >= 0 ? box_max.y : box_min.y,
                         n.z >= 0 ? box_max.z : box_min.z);
      if (glm::dot(n, p - eye_) < 0.0) return false;
    }
    return true;
  }

 private:
  glm::dvec3 eye_;
  glm::dvec3 normals_[5];
};

}  // namespace vistream::scenes
