#pragma once
// The window's keys, stated once: which key (GLFW key code) or typed character does what, and
// the line the overlay's key list (H or ?) shows for it. Window input (client/window_input.h:
// the keys held to walk and turn), the walkthrough's handling of key presses
// (client/walkthrough_window.cpp) and the overlay's help and panel titles (client/overlay.cpp)
// all read this table; a key is added or changed here only.

#include <string>
#include <utility>
#include <vector>

namespace vistream::client {

// What a key does in the window.
enum class WindowAction {
  // Held (WindowInput::Update reads them every frame); pressed, each leaves a walk followed.
  kForward,
  kBack,
  kStrafeLeft,
  kStrafeRight,
  kTurnLeft,
  kTurnRight,
  kRun,   // held with the above: 5 times faster
  kLook,  // the mouse after a click (no key)
  // Pressed (the walkthrough acts on them once a press).
  kWalkList,
  kPause,
  kFaster,
  kSlower,
  kRestart,
  kStats,
  kMinimap,
  kFullScreen,
  kScreenshot,
  kHelp,
  kEscape,  // frees the mouse, else closes the key list, else closes the window
  kQuit,
};

// The keys of the walk list (P) while it is shown: they act on the list and nothing else.
enum class WalkListAction {
  kUp,
  kDown,
  kFollowFromStart,
  kFollowFromHere,
  kClose,
};

struct KeyBinding {
  WindowAction action;
  std::vector<int> keys;        // GLFW key codes (GLFW_KEY_*); may be empty
  std::vector<unsigned> chars;  // typed characters (Unicode code points, whatever the layout)
  std::string name;             // the key as panel titles and hints name it ("F1"); may be empty
  // The key list's row: its keys and what they do. An empty `label` puts the binding on the row
  // above (W, A, S and D share one row, so do + and -).
  std::string label;
  std::string help;
};

struct WalkListBinding {
  WalkListAction action;
  std::vector<int> keys;  // GLFW key codes
};

// The table, in the key list's order.
const std::vector<KeyBinding>& WindowKeys();
// The walk list's keys, and their hint as the list and the key list show it.
const std::vector<WalkListBinding>& WalkListKeys();
const std::string& WalkListHint();

// The binding of `action` (every action has one).
const KeyBinding& BindingOf(WindowAction action);
// The action of a pressed key (GLFW key code) or a typed character; none for other keys.
const KeyBinding* BindingOfKey(int glfw_key);
const KeyBinding* BindingOfChar(unsigned codepoint);
// The walk list's action of a pressed key; none for keys the list does not take.
const WalkListBinding* WalkListBindingOfKey(int glfw_key);
// Whether `action` walks or turns (a press leaves a walk followed).
bool IsMovement(WindowAction action);

// The key list's rows as the overlay shows them: (keys, what they do), in the table's order.
std::vector<std::pair<std::string, std::string>> KeyListRows();

}  // namespace vistream::client
