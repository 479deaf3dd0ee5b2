#pragma once
// Keyboard and mouse of the windowed front end (GLFW): W/S or Up/Down walk, A/D strafe,
// Left/Right turn, the mouse looks once the window is clicked (Esc frees it; Esc again or Q
// closes the window), Shift runs.

#include <string>

#include <glm/vec3.hpp>

namespace vistream::client {

class WindowInput {
 public:
  // `window`: the GLFWwindow of gl::GlContext::window().
  explicit WindowInput(void* window);

  // Reads the keys and the mouse and moves the eye by `dt` seconds at `speed_mps` (xy only:
  // the eye keeps its height). Returns whether any key or the mouse moved the camera.
  bool Update(double dt, double speed_mps, glm::dvec3* eye, double* yaw_rad, double* pitch_rad);
  // Processes window events (call once a frame).
  void Poll();
  bool ShouldClose() const;
  void SetTitle(const std::string& title);

 private:
  void* window_;
  bool captured_ = false;
  bool escape_was_down_ = false;
  double last_x_ = 0.0, last_y_ = 0.0;
};

}  // namespace vistream::client
