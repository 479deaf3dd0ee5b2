// The window's key table (client/window_keys.h): the one place its keys are stated, which window
// input, the walkthrough's key handling and the overlay's key list (H or ?) all read.

#include <set>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "client/window_keys.h"

namespace vistream::client {
namespace {

TEST(WindowKeys, TheKeyListShowsOneRowAKeyOrGroupInTheTablesOrder) {
  const std::vector<std::pair<std::string, std::string>> expected = {
      {"W A S D, arrows", "walk, strafe, turn (Shift: 5x faster); leave a walk followed"},
      {"click, then mouse", "look around (Esc frees the mouse)"},
      {"P", "the scene's walks: Up/Down choose, Enter from its start, F from here"},
      {"space", "pause or resume the walk followed"},
      {"+ / -", "faster / slower (walk or free)"},
      {"R", "back to the start pose (a walk: its start)"},
      {"F1", "statistics panel"},
      {"M", "minimap of the viewcells"},
      {"F11", "full screen"},
      {"F12", "screenshot (PNG into --screenshots, else ./vistream-screenshots)"},
      {"H or ?", "this list"},
      {"Esc (mouse free), Q", "quit"},
  };
  EXPECT_EQ(KeyListRows(), expected);
}

TEST(WindowKeys, NoKeyOrCharacterIsBoundTwiceAndEveryActionHasItsBinding) {
  std::set<int> keys;
  std::set<unsigned> chars;
  for (const KeyBinding& b : WindowKeys()) {
    for (int k : b.keys) EXPECT_TRUE(keys.insert(k).second) << "key " << k << " bound twice";
    for (unsigned c : b.chars) EXPECT_TRUE(chars.insert(c).second) << "character " << c << " bound twice";
    EXPECT_EQ(&BindingOf(b.action), &b);
  }
  std::set<int> list_keys;
  for (const WalkListBinding& b : WalkListKeys()) {
    for (int k : b.keys) EXPECT_TRUE(list_keys.insert(k).second) << "walk list key " << k << " bound twice";
  }
}

TEST(WindowKeys, PressesAndTypedCharactersFindTheirActions) {
  EXPECT_EQ(BindingOfKey(GLFW_KEY_F1)->action, WindowAction::kStats);
  EXPECT_EQ(BindingOfKey(GLFW_KEY_H)->action, WindowAction::kHelp);
  EXPECT_EQ(BindingOfChar('?')->action, WindowAction::kHelp);
  EXPECT_EQ(BindingOfChar('+')->action, WindowAction::kFaster);
  EXPECT_EQ(BindingOfKey(GLFW_KEY_Q)->action, WindowAction::kQuit);
  EXPECT_EQ(BindingOfKey(GLFW_KEY_F), nullptr);  // only the walk list's
  EXPECT_EQ(WalkListBindingOfKey(GLFW_KEY_F)->action, WalkListAction::kFollowFromHere);
  EXPECT_EQ(WalkListBindingOfKey(GLFW_KEY_KP_ENTER)->action, WalkListAction::kFollowFromStart);
  EXPECT_EQ(WalkListBindingOfKey(GLFW_KEY_P), nullptr);
}

TEST(WindowKeys, WalkingAndTurningKeysLeaveAWalkButShiftDoesNot) {
  for (int k : {GLFW_KEY_W, GLFW_KEY_A, GLFW_KEY_S, GLFW_KEY_D, GLFW_KEY_UP, GLFW_KEY_DOWN, GLFW_KEY_LEFT,
                GLFW_KEY_RIGHT}) {
    ASSERT_NE(BindingOfKey(k), nullptr) << k;
    EXPECT_TRUE(IsMovement(BindingOfKey(k)->action)) << k;
  }
  EXPECT_FALSE(IsMovement(BindingOfKey(GLFW_KEY_LEFT_SHIFT)->action));
  EXPECT_FALSE(IsMovement(BindingOfKey(GLFW_KEY_SPACE)->action));
}

}  // namespace
}  // namespace vistream::client
