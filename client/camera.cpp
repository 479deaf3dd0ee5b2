#include "client/camera.h"

#include <cmath>

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>


namespace vistream::client {

glm::dvec3 Camera::Forward() const {
  return {std::cos(pitch_rad) * std::cos(yaw_rad), std::cos(pitch_rad) * std::sin(yaw_rad), std::sin(pitch_rad)};
}

glm::dvec3 Camera::Up() const {
  return {-std::sin(pitch_rad) * std::cos(yaw_rad), -std::sin(pitch_rad) * std::sin(yaw_rad), std::cos(pitch_rad)};
}

glm::dmat4 Camera::ViewProjection() const {
  const glm::dmat4 view = glm::lookAt(eye, eye + Forward(), Up());
  const glm::dmat4 projection =
      glm::perspective(fov_y_rad, static_cast<double>(width) / static_cast<double>(height), near_m, far_m);
  return projection * view;
}

scenes::ViewFrustum Camera::Frustum() const {
  return scenes::ViewFrustum(eye, Forward(), Up(), fov_y_rad, static_cast<double>(width) / static_cast<double>(height));
}

}  // namespace vistream::client
