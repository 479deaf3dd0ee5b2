#include "client/window_keys.h"

#include <algorithm>

#include <absl/strings/str_cat.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

namespace vistream::client {

namespace {

template <typename T>
bool Holds(const std::vector<T>& v, T x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

}  // namespace

const std::string& WalkListHint() {
  static const std::string hint = "Up/Down choose, Enter from its start, F from here";
  return hint;
}

const std::vector<KeyBinding>& WindowKeys() {
  using A = WindowAction;
  static const std::vector<KeyBinding> table = {
      {A::kForward, {GLFW_KEY_W, GLFW_KEY_UP}, {}, "W", "W A S D, arrows",
       "walk, strafe, turn (Shift: 5x faster); leave a walk followed"},
      {A::kBack, {GLFW_KEY_S, GLFW_KEY_DOWN}, {}, "S", "", ""},
      {A::kStrafeLeft, {GLFW_KEY_A}, {}, "A", "", ""},
      {A::kStrafeRight, {GLFW_KEY_D}, {}, "D", "", ""},
      {A::kTurnLeft, {GLFW_KEY_LEFT}, {}, "Left", "", ""},
      {A::kTurnRight, {GLFW_KEY_RIGHT}, {}, "Right", "", ""},
      {A::kRun, {GLFW_KEY_LEFT_SHIFT, GLFW_KEY_RIGHT_SHIFT}, {}, "Shift", "", ""},
      {A::kLook, {}, {}, "", "click, then mouse", "look around (Esc frees the mouse)"},
      {A::kWalkList, {GLFW_KEY_P}, {}, "P", "P", absl::StrCat("the scene's walks: ", WalkListHint())},
      {A::kPause, {GLFW_KEY_SPACE}, {}, "space", "space", "pause or resume the walk followed"},
      {A::kFaster, {}, {'+'}, "+", "+ / -", "faster / slower (walk or free)"},
      {A::kSlower, {}, {'-'}, "-", "", ""},
      {A::kRestart, {GLFW_KEY_R}, {}, "R", "R", "back to the start pose (a walk: its start)"},
      {A::kStats, {GLFW_KEY_F1}, {}, "F1", "F1", "statistics panel"},
      {A::kMinimap, {GLFW_KEY_M}, {}, "M", "M", "minimap of the viewcells"},
      {A::kFullScreen, {GLFW_KEY_F11}, {}, "F11", "F11", "full screen"},
      {A::kScreenshot, {GLFW_KEY_F12}, {}, "F12", "F12",
       "screenshot (PNG into --screenshots, else ./vistream-screenshots)"},
      {A::kHelp, {GLFW_KEY_H}, {'?'}, "H", "H or ?", "this list"},
      {A::kEscape, {GLFW_KEY_ESCAPE}, {}, "Esc", "Esc (mouse free), Q", "quit"},
      {A::kQuit, {GLFW_KEY_Q}, {}, "Q", "", ""},
  };
  return table;
}

const std::vector<WalkListBinding>& WalkListKeys() {
  using A = WalkListAction;
  static const std::vector<WalkListBinding> table = {
      {A::kUp, {GLFW_KEY_UP}},
      {A::kDown, {GLFW_KEY_DOWN}},
      {A::kFollowFromStart, {GLFW_KEY_ENTER, GLFW_KEY_KP_ENTER}},
      {A::kFollowFromHere, {GLFW_KEY_F}},
      {A::kClose, {GLFW_KEY_ESCAPE}},
  };
  return table;
}

const KeyBinding& BindingOf(WindowAction action) {
  const std::vector<KeyBinding>& table = WindowKeys();
  return *std::find_if(table.begin(), table.end(), [&](const KeyBinding& b) { return b.action == action; });
}

const KeyBinding* BindingOfKey(int glfw_key) {
  for (const KeyBinding& b : WindowKeys()) {
    if (Holds(b.keys, glfw_key)) return &b;
  }
  return nullptr;
}

const KeyBinding* BindingOfChar(unsigned codepoint) {
  for (const KeyBinding& b : WindowKeys()) {
    if (Holds(b.chars, codepoint)) return &b;
  }
  return nullptr;
}

const WalkListBinding* WalkListBindingOfKey(int glfw_key) {
  for (const WalkListBinding& b : WalkListKeys()) {
    if (Holds(b.keys, glfw_key)) return &b;
  }
  return nullptr;
}

bool IsMovement(WindowAction action) {
  switch (action) {
    case WindowAction::kForward:
    case WindowAction::kBack:
    case WindowAction::kStrafeLeft:
    case WindowAction::kStrafeRight:
    case WindowAction::kTurnLeft:
    case WindowAction::kTurnRight:
      return true;
    default:
      return false;
  }
}

std::vector<std::pair<std::string, std::string>> KeyListRows() {
  std::vector<std::pair<std::string, std::string>> rows;
  for (const KeyBinding& b : WindowKeys()) {
    if (!b.label.empty()) rows.emplace_back(b.label, b.help);
  }
  return rows;
}

}  // namespace vistream::client
