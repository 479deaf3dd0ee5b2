#pragma once
// The client's camera (part of the client model, client/client_model.h): a pinhole camera with
// the renderer's field of view and frame size, culling as the renderer culls. The renderer
// (client/renderer.h) draws through it and the simulator (simulation/simulator.h) counts the
// triangles the renderer would draw with it.

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "scenes/view_frustum.h"

namespace vistream::client {

// A pinhole camera in scene-local metres, z up. yaw: counter-clockwise from +x; pitch: up
// from the horizontal (radians).
struct Camera {
  glm::dvec3 eye{0.0};
  double yaw_rad = 0.0, pitch_rad = 0.0;
  double fov_y_rad = 1.0471975511965976;  // 60 degrees
  int width = 1280, height = 720;
  double near_m = 0.25;
  double far_m = 20000.0;

  // The unit view direction, and the unit up direction orthogonal to it in the vertical plane
  // through it (exactly +z for a level camera).
  glm::dvec3 Forward() const;
  glm::dvec3 Up() const;
  // World to clip, OpenGL conventions (depth -1..1).
  glm::dmat4 ViewProjection() const;
  // The view frustum (its side planes and the near plane; the far plane is beyond the scene),
  // for culling many boxes.
  scenes::ViewFrustum Frustum() const;
};

}  // namespace vistream::client
