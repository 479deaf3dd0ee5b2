#pragma once
// What the overlay's panel files (client/overlay.cpp, client/overlay_minimap.cpp) share: ImGui
// window flags, colours, and the minimap's panel. Inside the client library only; called between
// ImGui::NewFrame and ImGui::Render of the overlay's context.

#include <array>
#include <cstdint>

#include <imgui.h>

#include "client/minimap.h"

namespace vistream::client {

struct OverlayStatus;  // client/overlay.h (not included: overlay.cpp includes this file)

// Windows in fixed places, sized to what they hold; the panels also never take the focus.
constexpr ImGuiWindowFlags kOverlayFixed = ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize |
                                           ImGuiWindowFlags_NoCollapse | ImGuiWindowFlags_NoSavedSettings |
                                           ImGuiWindowFlags_AlwaysAutoResize | ImGuiWindowFlags_NoNav;
constexpr ImGuiWindowFlags kOverlayPanel =
    kOverlayFixed | ImGuiWindowFlags_NoFocusOnAppearing | ImGuiWindowFlags_NoScrollbar;

inline ImU32 OverlayRgb(const std::array<uint8_t, 3>& c, uint8_t alpha = 255) {
  return IM_COL32(c[0], c[1], c[2], alpha);
}

// The minimap panel at the top right of a frame `width` pixels wide (Overlay::kMinimapPx
// square; `beside_stats`: the statistics panel is shown, and the map shrinks to stay clear of
// it in a narrow frame, down to Overlay::kMinimapMinPx), centred on `s.eye` (scene-local
// metres), north up. `window_keys`: its title names its key (the window; not headless frames).
void MinimapPanel(const OverlayStatus& s, const MinimapView& map, int width, bool beside_stats, bool window_keys);

}  // namespace vistream::client
