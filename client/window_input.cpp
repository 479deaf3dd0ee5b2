#include "client/window_input.h"

#include <algorithm>
#include <cmath>
#include <utility>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "client/window_keys.h"

namespace vistream::client {

namespace {
GLFWwindow* W(void* w) { return static_cast<GLFWwindow*>(w); }
}  // namespace

WindowInput::WindowInput(void* window) : window_(window) {
  glfwSetWindowUserPointer(W(window), this);
  glfwSetKeyCallback(W(window), [](GLFWwindow* w, int key, int scancode, int action, int mods) {
    OnKey(w, key, scancode, action, mods);
  });
  glfwSetCharCallback(W(window), [](GLFWwindow* w, unsigned c) { OnChar(w, c); });
  glfwSetMouseButtonCallback(W(window), [](GLFWwindow* w, int button, int action, int mods) {
    OnMouseButton(w, button, action, mods);
  });
}

void WindowInput::OnMouseButton(void* window, int button, int action, int /*mods*/) {
  auto* self = static_cast<WindowInput*>(glfwGetWindowUserPointer(W(window)));
  if (self != nullptr && button == GLFW_MOUSE_BUTTON_LEFT && action == GLFW_PRESS) self->clicked_ = true;
}

void WindowInput::OnKey(void* window, int key, int /*scancode*/, int action, int mods) {
  auto* self = static_cast<WindowInput*>(glfwGetWindowUserPointer(W(window)));
  if (self != nullptr && action == GLFW_PRESS) self->keys_.push_back({key, mods});
}

void WindowInput::OnChar(void* window, unsigned codepoint) {
  auto* self = static_cast<WindowInput*>(glfwGetWindowUserPointer(W(window)));
  if (self != nullptr) self->chars_.push_back(codepoint);
}

std::vector<WindowInput::KeyPress> WindowInput::TakeKeys() { return std::exchange(keys_, {}); }

std::vector<unsigned> WindowInput::TakeChars() { return std::exchange(chars_, {}); }

void WindowInput::Escape() {
  if (captured_) {
    captured_ = false;
    glfwSetInputMode(W(window_), GLFW_CURSOR, GLFW_CURSOR_NORMAL);
  } else {
    Close();
  }
}

void WindowInput::Close() { glfwSetWindowShouldClose(W(window_), GLFW_TRUE); }

void WindowInput::ToggleFullScreen() {
  GLFWwindow* w = W(window_);
  if (!full_screen_) {
    GLFWmonitor* monitor = glfwGetPrimaryMonitor();
    const GLFWvidmode* mode = monitor != nullptr ? glfwGetVideoMode(monitor) : nullptr;
    if (mode == nullptr) return;
    glfwGetWindowPos(w, &windowed_x_, &windowed_y_);
    glfwGetWindowSize(w, &windowed_w_, &windowed_h_);
    glfwSetWindowMonitor(w, monitor, 0, 0, mode->width, mode->height, mode->refreshRate);
    full_screen_ = true;
  } else {
    glfwSetWindowMonitor(w, nullptr, windowed_x_, windowed_y_, windowed_w_, windowed_h_, GLFW_DONT_CARE);
    full_screen_ = false;
  }
}

void WindowInput::Poll() { glfwPollEvents(); }

bool WindowInput::ShouldClose() const { return glfwWindowShouldClose(W(window_)) != 0; }

void WindowInput::SetTitle(const std::string& title) { glfwSetWindowTitle(W(window_), title.c_str()); }

bool WindowInput::Update(double dt, double speed_mps, glm::dvec3* eye, double* yaw_rad, double* pitch_rad,
                         bool ui_has_mouse) {
  GLFWwindow* w = W(window_);
  // Whether a key of `action` (client/window_keys.h) is held.
  auto down = [&](WindowAction action) {
    const std::vector<int>& keys = BindingOf(action).keys;
    return std::any_of(keys.begin(), keys.end(), [&](int key) { return glfwGetKey(w, key) == GLFW_PRESS; });
  };
  bool moved = false;
  // A click (pressed and released between two frames) or the button held.
  const bool clicked = std::exchange(clicked_, false);
  if (!captured_ && !ui_has_mouse && (clicked || glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS)) {
    captured_ = true;
    glfwSetInputMode(w, GLFW_CURSOR, GLFW_CURSOR_DISABLED);
    glfwGetCursorPos(w, &last_x_, &last_y_);
  }
  if (captured_) {
    double x = 0.0, y = 0.0;
    glfwGetCursorPos(w, &x, &y);
    constexpr double kRadPerPixel = 0.0025;
    if (x != last_x_ || y != last_y_) {
      *yaw_rad -= (x - last_x_) * kRadPerPixel;
      *pitch_rad = std::clamp(*pitch_rad - (y - last_y_) * kRadPerPixel, -1.5, 1.5);
      moved = true;
    }
    last_x_ = x;
    last_y_ = y;
  }
  constexpr double kTurnRadPerS = 1.5;
  if (down(WindowAction::kTurnLeft)) *yaw_rad += kTurnRadPerS * dt, moved = true;
  if (down(WindowAction::kTurnRight)) *yaw_rad -= kTurnRadPerS * dt, moved = true;
  const double speed = speed_mps * (down(WindowAction::kRun) ? 5.0 : 1.0);
  const glm::dvec3 forward(std::cos(*yaw_rad), std::sin(*yaw_rad), 0.0), right(forward.y, -forward.x, 0.0);
  glm::dvec3 step(0.0);
  if (down(WindowAction::kForward)) step += forward;
  if (down(WindowAction::kBack)) step -= forward;
  if (down(WindowAction::kStrafeRight)) step += right;
  if (down(WindowAction::kStrafeLeft)) step -= right;
  if (step != glm::dvec3(0.0)) {
    *eye += step / std::sqrt(step.x * step.x + step.y * step.y) * speed * dt;
    moved = true;
  }
  return moved;
}

}  // namespace vistream::client
