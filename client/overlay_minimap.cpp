// The overlay's minimap panel (declared in client/overlay_panels.h): the viewcells around the
// eye in the states client/minimap.h keeps, the walk, the eye, a scale bar, north and a legend.
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <imgui.h>

#include "client/minimap.h"
#include "client/overlay.h"
#include "client/overlay_panels.h"
#include "client/window_keys.h"

namespace vistream::client {

namespace {

// The minimap's ground where there are no viewcells (and the lines between cells).
constexpr std::array<uint8_t, 3> kBeyondGrid{30, 32, 36};

double NiceLength(double target_m) {
  const double p = std::pow(10.0, std::floor(std::log10(std::max(target_m, 1e-3))));
  for (double m : {5.0, 2.0, 1.0}) {
    if (m * p <= target_m) return m * p;
  }
  return p;
}

}  // namespace

void MinimapPanel(const OverlayStatus& s, const MinimapView& map, int width, bool beside_stats, bool window_keys) {
  constexpr int kMargin = Overlay::kMargin, kStatsWidth = Overlay::kStatsWidth;
  constexpr int kMinimapPx = Overlay::kMinimapPx, kMinimapMinPx = Overlay::kMinimapMinPx;
  // Beside the statistics panel: what the frame's width leaves (its padding 2 x 8 px), at least
  // kMinimapMinPx (a frame narrower than both panels gets them overlapping).
  const int room = beside_stats ? width - (kMargin + kStatsWidth) - 2 * kMargin - 16 : kMinimapPx;
  const float px = static_cast<float>(std::clamp(room, kMinimapMinPx, kMinimapPx));
  ImGui::SetNextWindowPos(ImVec2(static_cast<float>(width - kMargin), kMargin), ImGuiCond_Always, ImVec2(1.0f, 0.0f));
  if (ImGui::Begin("minimap", nullptr, kOverlayPanel | ImGuiWindowFlags_NoTitleBar)) {
    // Wrapped at the map's width, so that the window keeps it.
    ImGui::PushTextWrapPos(ImGui::GetCursorPosX() + px);
    const std::string title =
        window_keys ? absl::StrCat("Viewcells around the eye (", BindingOf(WindowAction::kMinimap).name, "), north up")
                    : std::string("Viewcells around the eye, north up");
    ImGui::TextWrapped("%s", title.c_str());
    ImGui::PopTextWrapPos();
    const ImVec2 origin = ImGui::GetCursorScreenPos();
    ImGui::Dummy(ImVec2(px, px));
    ImDrawList* dl = ImGui::GetWindowDrawList();
    const ImVec2 lo = origin, hi(origin.x + px, origin.y + px);
    dl->AddRectFilled(lo, hi, OverlayRgb(kBeyondGrid));
    dl->PushClipRect(lo, hi, true);
    const double scale = px / (2.0 * map.radius_m);  // pixels a metre
    const ImVec2 centre(origin.x + 0.5f * px, origin.y + 0.5f * px);
    auto to_map = [&](double x, double y) {
      return ImVec2(centre.x + static_cast<float>((x - s.eye.x) * scale), centre.y - static_cast<float>((y - s.eye.y) * scale));
    };
    bool beyond_grid = true;  // the map shows ground without viewcells
    if (map.grid != nullptr && map.grid->CellCount() > 0) {
      const visibility::ViewcellGrid& g = *map.grid;
      const double x0 = g.corner().x, y0 = g.corner().y, size = g.cell_size();
      const int nx = g.nx(), ny = g.ny();
      beyond_grid = s.eye.x - map.radius_m < x0 || s.eye.x + map.radius_m > x0 + nx * size ||
                    s.eye.y - map.radius_m < y0 || s.eye.y + map.radius_m > y0 + ny * size;
      const int i0 = std::max(0, static_cast<int>(std::floor((s.eye.x - map.radius_m - x0) / size)));
      const int i1 = std::min(nx - 1, static_cast<int>(std::floor((s.eye.x + map.radius_m - x0) / size)));
      const int j0 = std::max(0, static_cast<int>(std::floor((s.eye.y - map.radius_m - y0) / size)));
      const int j1 = std::min(ny - 1, static_cast<int>(std::floor((s.eye.y + map.radius_m - y0) / size)));
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const size_t id = static_cast<size_t>(j) * static_cast<size_t>(nx) + static_cast<size_t>(i);
          const CellState state =
              map.cells != nullptr && id < map.cells->size() ? (*map.cells)[id] : CellState::kNotListed;
          const ImVec2 a = to_map(x0 + i * size, y0 + (j + 1) * size);
          const ImVec2 b = to_map(x0 + (i + 1) * size, y0 + j * size);
          const bool current = s.cell.has_value() && *s.cell == id;
          // A pixel short of its neighbours: the map's background between them draws the grid.
          dl->AddRectFilled(ImVec2(a.x + 1.0f, a.y + 1.0f), b,
                            OverlayRgb(current ? MinimapCurrentCellColour() : MinimapColour(state)));
        }
      }
    }
    if (map.walk.size() >= 2) {
      std::vector<ImVec2> pts;
      pts.reserve(map.walk.size());
      for (const glm::dvec2& q : map.walk) pts.push_back(to_map(q.x, q.y));
      dl->AddPolyline(pts.data(), static_cast<int>(pts.size()), IM_COL32(240, 80, 200, 255), ImDrawFlags_None, 2.0f);
    }
    // The eye: a triangle pointing along its heading (yaw counter-clockwise from east; the
    // map's y grows downwards).
    const float c = static_cast<float>(std::cos(s.yaw_rad)), sn = static_cast<float>(-std::sin(s.yaw_rad));
    auto rot = [&](float fx, float fy) { return ImVec2(centre.x + fx * c - fy * sn, centre.y + fx * sn + fy * c); };
    dl->AddTriangleFilled(rot(11.0f, 0.0f), rot(-6.0f, 6.0f), rot(-6.0f, -6.0f), IM_COL32(255, 255, 255, 255));
    dl->AddTriangle(rot(11.0f, 0.0f), rot(-6.0f, 6.0f), rot(-6.0f, -6.0f), IM_COL32(0, 0, 0, 255), 1.5f);
    // The scale bar, bottom left.
    const double bar_m = NiceLength(map.radius_m * 0.5);
    const float bar_px = static_cast<float>(bar_m * scale);
    const ImVec2 b0(lo.x + 10.0f, hi.y - 12.0f), b1(lo.x + 10.0f + bar_px, hi.y - 12.0f);
    dl->AddRectFilled(ImVec2(b0.x - 4.0f, b0.y - 20.0f), ImVec2(b1.x + 4.0f, b0.y + 6.0f), IM_COL32(0, 0, 0, 150));
    dl->AddLine(b0, b1, IM_COL32(255, 255, 255, 255), 2.0f);
    dl->AddLine(ImVec2(b0.x, b0.y - 4.0f), ImVec2(b0.x, b0.y + 4.0f), IM_COL32(255, 255, 255, 255), 2.0f);
    dl->AddLine(ImVec2(b1.x, b1.y - 4.0f), ImVec2(b1.x, b1.y + 4.0f), IM_COL32(255, 255, 255, 255), 2.0f);
    dl->AddText(ImVec2(b0.x, b0.y - 19.0f), IM_COL32(255, 255, 255, 255), absl::StrFormat("%.0f m", bar_m).c_str());
    // North, on a backing like the scale bar's.
    dl->AddRectFilled(ImVec2(hi.x - 20.0f, lo.y + 2.0f), ImVec2(hi.x - 4.0f, lo.y + 33.0f), IM_COL32(0, 0, 0, 150));
    dl->AddText(ImVec2(hi.x - 16.0f, lo.y + 4.0f), IM_COL32(255, 255, 255, 255), "N");
    dl->AddTriangleFilled(ImVec2(hi.x - 12.0f, lo.y + 22.0f), ImVec2(hi.x - 16.0f, lo.y + 30.0f),
                          ImVec2(hi.x - 8.0f, lo.y + 30.0f), IM_COL32(255, 255, 255, 255));
    dl->PopClipRect();
    // The legend.
    auto legend = [&](const std::array<uint8_t, 3>& colour, const char* text) {
      const ImVec2 p = ImGui::GetCursorScreenPos();
      const float h = ImGui::GetTextLineHeight();
      ImGui::GetWindowDrawList()->AddRectFilled(ImVec2(p.x, p.y + 2.0f), ImVec2(p.x + h - 4.0f, p.y + h - 2.0f),
                                                OverlayRgb(colour));
      ImGui::Dummy(ImVec2(h, h));
      ImGui::SameLine();
      ImGui::TextUnformatted(text);
    };
    // Two columns where they fit the map's width (the window keeps it), else one.
    const float column = 0.5f * px;
    const bool two = column >= ImGui::CalcTextSize("not asked for").x + 2.0f * ImGui::GetTextLineHeight();
    auto second = [&] {
      if (two) ImGui::SameLine(ImGui::GetCursorStartPos().x + column);
    };
    legend(MinimapCurrentCellColour(), "current");
    second();
    legend(MinimapColour(CellState::kComplete), "PVS complete");
    legend(MinimapColour(CellState::kPending), "pending");
    second();
    legend(MinimapColour(CellState::kNotListed), "not asked for");
    if (!map.walk.empty()) legend({240, 80, 200}, "walk followed");
    if (beyond_grid) legend(kBeyondGrid, "outside the grid");
  }
  ImGui::End();
}

}  // namespace vistream::client
