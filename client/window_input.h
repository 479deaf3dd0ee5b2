#pragma once
// Keyboard and mouse of the windowed front end (GLFW): the keys held to walk, strafe, turn and
// run are those of the window's key table (client/window_keys.h: W/S or Up/Down walk, A/D
// strafe, Left/Right turn, Shift runs); the mouse looks once the window is clicked (Esc frees
// it; Esc again or Q closes the window). The other keys (the overlay's, the walk's,
// screenshots) come as presses from TakeKeys/TakeChars, so that a key pressed and released
// within one frame (as xdotool types) is not lost; the walkthrough looks them up in the same
// table. Install before the overlay: ImGui's callbacks chain to these.

#include <string>
#include <vector>

#include <glm/vec3.hpp>

namespace vistream::client {

class WindowInput {
 public:
  // `window`: the GLFWwindow of gl::GlContext::window().
  explicit WindowInput(void* window);

  // Reads the keys and the mouse and moves the eye by `dt` seconds at `speed_mps` (xy only:
  // the eye keeps its height). Returns whether any key or the mouse moved the camera.
  // `ui_has_mouse`: the overlay's panels want the mouse (a click on them does not start mouse look).
  bool Update(double dt, double speed_mps, glm::dvec3* eye, double* yaw_rad, double* pitch_rad,
              bool ui_has_mouse = false);
  // Processes window events (call once a frame).
  void Poll();
  bool ShouldClose() const;
  void SetTitle(const std::string& title);

  // A key pressed since the last TakeKeys (GLFW key code and modifier bits), and characters
  // typed (Unicode code points: '+', '-' and '?' whatever the keyboard layout).
  struct KeyPress {
    int key = 0;
    int mods = 0;
  };
  std::vector<KeyPress> TakeKeys();
  std::vector<unsigned> TakeChars();
  // Esc: frees the mouse if it looks around, else closes the window.
  void Escape();
  // Q: closes the window.
  void Close();
  // Full screen on the window's monitor, or back to the window it was.
  void ToggleFullScreen();
  bool full_screen() const { return full_screen_; }

 private:
  static void OnKey(void* window, int key, int scancode, int action, int mods);
  static void OnChar(void* window, unsigned codepoint);
  static void OnMouseButton(void* window, int button, int action, int mods);

  void* window_;
  std::vector<KeyPress> keys_;
  std::vector<unsigned> chars_;
  bool full_screen_ = false;
  int windowed_x_ = 0, windowed_y_ = 0, windowed_w_ = 0, windowed_h_ = 0;
  bool captured_ = false;
  bool clicked_ = false;  // the left button pressed since the last Update (a click within a frame)
  double last_x_ = 0.0, last_y_ = 0.0;
};

}  // namespace vistream::client
