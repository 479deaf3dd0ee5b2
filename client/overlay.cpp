#include "client/overlay.h"

#include <algorithm>
#include <cfloat>
#include <deque>
#include <cmath>
#include <cstdint>
#include <filesystem>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>

#include "client/overlay_painter.h"
#include "client/overlay_panels.h"
#include "client/window_keys.h"

namespace vistream::client {

namespace {

// A TrueType font from Debian's fonts-dejavu-core reads better than ImGui's 13-pixel bitmap
// font; without it, the bitmap font.
constexpr const char* kFontPath = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
constexpr float kFontPx = 15.0f;

// A window in the middle of a `width` x `height` frame (the key list, the walk list).
bool BeginCentred(const char* title, int width, int height) {
  ImGui::SetNextWindowPos(ImVec2(0.5f * static_cast<float>(width), 0.5f * static_cast<float>(height)), ImGuiCond_Always,
                          ImVec2(0.5f, 0.5f));
  return ImGui::Begin(title, nullptr, kOverlayFixed);
}

std::string Megabytes(uint64_t bytes) { return absl::StrFormat("%.1f MB", static_cast<double>(bytes) / 1e6); }

}  // namespace

std::vector<std::string> OverlayLines(const OverlayStatus& s, double fps, double frame_ms, double bytes_per_s) {
  std::vector<std::string> out;
  out.push_back(absl::StrCat("scene ", s.scene, " on ", s.server));
  switch (s.link) {
    case OverlayStatus::Link::kConnected:
      out.push_back(absl::StrCat("connection: connected", s.reconnects > 0 ? absl::StrCat(" (", s.reconnects,
                                                                                          " reconnects)")
                                                                           : ""));
      break;
    case OverlayStatus::Link::kReconnecting:
      out.push_back(absl::StrFormat("connection: reconnecting for %.1f s, back-off %.2f s%s", s.lost_for_s, s.backoff_s,
                                    s.give_up_s > 0.0 ? absl::StrFormat(", gives up after %.0f s", s.give_up_s) : ""));
      break;
    case OverlayStatus::Link::kGivenUp:
      out.push_back(absl::StrFormat("connection: given up after %.0f s", s.give_up_s));
      break;
    case OverlayStatus::Link::kLocal:
      out.push_back("connection: none (the whole scene drawn locally)");
      break;
  }
  if (s.starting_s >= 0.0) {
    out.push_back(absl::StrFormat("starting: waiting %.0f s for the first viewcell's PVS and geometry (%.0f s at most)",
                                  s.starting_s, s.startup_timeout_s));
  }
  out.push_back(absl::StrFormat("fps %.1f, frame %.1f ms", fps, frame_ms));
  if (s.cell.has_value()) {
    out.push_back(absl::StrCat("viewcell ", s.cell_i, ",", s.cell_j, " (id ", *s.cell, "): ",
                               !s.pvs_listed     ? std::string("PVS list not here")
                               : s.pvs_complete ? absl::StrCat("PVS ", s.pvs_objects, " objects, complete")
                                                : absl::StrCat("PVS ", s.pvs_objects, " objects, ", s.pvs_missing,
                                                               " missing")));
  } else {
    out.push_back("viewcell: none (outside the grid, or no scene yet)");
  }
  out.push_back(s.masked ? absl::StrFormat("frame: masked (eps-mask %d, neighbourhood %.0f x %.0f m)", s.mask_id,
                                           s.mask_box_max.x - s.mask_box_min.x, s.mask_box_max.y - s.mask_box_min.y)
                : s.hole ? std::string("frame: HOLE (no usable mask, PVS incomplete)")
                         : std::string("frame: viewcell PVS"));
  out.push_back(absl::StrFormat("drawn %d triangles (PVS alone %d; scene %d)", s.triangles_drawn,
                                s.triangles_without_masks, s.scene_triangles));
  out.push_back(absl::StrCat("held ", s.held_objects, " objects, ", Megabytes(s.held_bytes),
                             s.memory_budget_bytes > 0 ? absl::StrCat(" of ", Megabytes(s.memory_budget_bytes))
                                                       : std::string(" (no budget)")));
  out.push_back(absl::StrFormat("received %s, %.2f MB/s", Megabytes(s.bytes_received), bytes_per_s / 1e6));
  out.push_back(absl::StrFormat("frames %d, stalls %d (%.2f s), holes %d", s.frames, s.stalls, s.stall_s,
                                s.hole_frames));
  out.push_back(s.lod_tau_px > 0.0 && s.server_without_levels
                    ? absl::StrFormat("levels: tau %.2g px asked, the server has none (full detail)", s.lod_tau_px)
                : s.lod_tau_px > 0.0
                    ? absl::StrFormat("levels: tau %.2g px, %d coarse frames, %d at a level (%s saved)", s.lod_tau_px,
                                      s.coarse_frames, s.level_objects, Megabytes(s.level_bytes_saved))
                    : std::string("levels: off (full detail)"));
  // Rounded down: 100.0% only when every frame was.
  const double masked_percent =
      s.frames > 0 ? std::floor(1000.0 * static_cast<double>(s.frames_masked) / s.frames) / 10.0 : 0.0;
  out.push_back(absl::StrFormat("masked frames %d (%.1f%%), masks %d", s.frames_masked, masked_percent,
                                s.masks_received));
  if (!s.walk.empty()) {
    out.push_back(absl::StrFormat("walk '%s' %.0f of %.0f s at %.1f km/h%s", s.walk, s.walk_t_s, s.walk_duration_s,
                                  s.speed_kmh, s.walk_paused ? ", PAUSED" : ""));
  } else {
    out.push_back(absl::StrFormat("free walking at %.1f km/h", s.speed_kmh));
  }
  double heading = std::fmod(90.0 - s.yaw_rad * 180.0 / M_PI, 360.0);  // compass: 0 north, clockwise
  if (heading < 0.0) heading += 360.0;
  out.push_back(absl::StrFormat("eye %.1f, %.1f, %.1f m, heading %.0f deg", s.eye.x, s.eye.y, s.eye.z, heading));
  return out;
}

struct Overlay::Impl {
  explicit Impl(const gl::GlFunctions& functions) : painter(functions) {}

  gl::GlContext* context = nullptr;
  void* window = nullptr;
  ImGuiContext* imgui = nullptr;
  bool glfw_backend = false;
  OverlayPainter painter;  // the panels drawn, and their cache (client/overlay_painter.h)
  double since_rebuild_s = 0.0;
  bool invalid = true;
  std::array<bool, 4> shown{};  // show_stats, show_minimap, show_help, show_walks at the last rebuild
  struct Sample {
    double t = 0.0;  // steady clock, s
    float frame_ms = 0.0f;
    uint64_t bytes = 0;  // received since the start
  };
  std::deque<Sample> samples;  // the last kHistoryS seconds' frames
  size_t walk_selected = 0;
  std::vector<std::string> lines;  // the statistics panel's, this frame

  absl::Status Init();
  // Whether the window's mouse cursor is over a panel as last built.
  bool MouseOverPanel() const;
  // The samples of the last second (or what there is): the first one's index, and the span.
  std::pair<size_t, double> LastSecond() const;
  double Fps() const;
  double BytesPerSecond() const;
  void StatsPanel(const OverlayStatus& s);
  // The key list, from the window's key table (client/window_keys.h).
  void Help(int width, int height);
  OverlayRequest Walks(const std::vector<std::string>& walks, int width, int height, bool* open);
};

absl::Status Overlay::Impl::Init() {
  imgui = ImGui::CreateContext();
  ImGui::SetCurrentContext(imgui);
  ImGuiIO& io = ImGui::GetIO();
  io.IniFilename = nullptr;  // no imgui.ini in the working folder
  io.LogFilename = nullptr;
  ImGui::StyleColorsDark();
  ImGuiStyle& style = ImGui::GetStyle();
  // Opaque, square panels: a frame copies them from the texture they were drawn into
  // (Overlay::Frame); blending them over each frame cost a CPU rasteriser ~2 ms at 1280x720.
  style.WindowRounding = 0.0f;
  style.Colors[ImGuiCol_WindowBg] = ImVec4(0.09f, 0.09f, 0.10f, 1.0f);
  // Which panel ImGui calls focused says nothing here: titles look the same either way.
  style.Colors[ImGuiCol_TitleBgActive] = style.Colors[ImGuiCol_TitleBg];
  style.WindowBorderSize = 0.0f;
  // No anti-aliased fringes on shapes (rectangles and lines are axis-aligned or thin): fewer
  // triangles and pixels for a CPU rasteriser; text is unchanged.
  style.AntiAliasedLines = false;
  style.AntiAliasedLinesUseTex = false;
  style.AntiAliasedFill = false;
  if (std::error_code ec; std::filesystem::exists(kFontPath, ec)) {
    io.Fonts->AddFontFromFileTTF(kFontPath, kFontPx);
  } else {
    io.Fonts->AddFontDefault();
  }
  if (window != nullptr) {
    // Keyboard and mouse for the panels (the walk list's buttons); the loop reads the keys it
    // needs itself, and ImGui's callbacks chain to those installed before them.
    glfw_backend = ImGui_ImplGlfw_InitForOpenGL(static_cast<GLFWwindow*>(window), true);
    if (!glfw_backend) return absl::InternalError("overlay: ImGui's GLFW back end did not start");
  }
  io.BackendRendererName = "vistream_gl_functions";
  return painter.Init(io);
}

bool Overlay::Impl::MouseOverPanel() const {
  const std::vector<OverlayPainter::Rect>& rects = painter.rects();
  if (window == nullptr || rects.empty()) return false;
  auto* w = static_cast<GLFWwindow*>(window);
  // Looking around (the cursor captured), the cursor is nowhere on the window.
  if (glfwGetInputMode(w, GLFW_CURSOR) == GLFW_CURSOR_DISABLED) return false;
  double x = 0.0, y = 0.0;
  int ww = 0, wh = 0;
  glfwGetCursorPos(w, &x, &y);
  glfwGetWindowSize(w, &ww, &wh);
  if (ww <= 0 || wh <= 0) return false;
  // Window coordinates onto the framebuffer's pixels (a HiDPI window has more).
  x *= static_cast<double>(painter.fb_w()) / ww;
  y *= static_cast<double>(painter.fb_h()) / wh;
  return std::any_of(rects.begin(), rects.end(),
                     [&](const OverlayPainter::Rect& r) { return x >= r.x0 && x < r.x1 && y >= r.y0 && y < r.y1; });
}

std::pair<size_t, double> Overlay::Impl::LastSecond() const {
  if (samples.size() < 2) return {0, 0.0};
  const double now = samples.back().t;
  size_t k = samples.size() - 1;
  while (k > 0 && now - samples[k - 1].t <= 1.0) --k;
  return {k, now - samples[k].t};
}

double Overlay::Impl::Fps() const {
  const auto [k, span] = LastSecond();
  return span > 0.0 ? static_cast<double>(samples.size() - 1 - k) / span : 0.0;
}

double Overlay::Impl::BytesPerSecond() const {
  const auto [k, span] = LastSecond();
  return span > 0.0 ? static_cast<double>(samples.back().bytes - samples[k].bytes) / span : 0.0;
}

void Overlay::Impl::StatsPanel(const OverlayStatus& s) {
  ImGui::SetNextWindowPos(ImVec2(kMargin, kMargin));
  ImGui::SetNextWindowSize(ImVec2(kStatsWidth, 0.0f));
  // The keys' hints only where keys reach (the window, not headless frames).
  const bool keys = window != nullptr;
  const std::string title = keys ? absl::StrCat("vistream (", BindingOf(WindowAction::kStats).name, ")") : "vistream";
  if (ImGui::Begin(title.c_str(), nullptr, kOverlayPanel)) {
    // Warnings in colour: a hole, stalls, a lost server.
    const ImVec4 warn(1.0f, 0.55f, 0.35f, 1.0f);
    for (const std::string& line : lines) {
      const bool bad = (line.rfind("frame: HOLE", 0) == 0) ||
                       (line.rfind("connection: reconnecting", 0) == 0) || (line.rfind("connection: given up", 0) == 0);
      if (bad) {
        ImGui::PushStyleColor(ImGuiCol_Text, warn);
        ImGui::TextWrapped("%s", line.c_str());
        ImGui::PopStyleColor();
      } else {
        ImGui::TextWrapped("%s", line.c_str());
      }
      if (line.rfind("fps ", 0) == 0 && !samples.empty()) {
        // The frame-time graph of the last seconds, 0 to at least 50 ms.
        std::vector<float> ms;
        ms.reserve(samples.size());
        float top = 50.0f;
        for (const Sample& f : samples) {
          ms.push_back(f.frame_ms);
          top = std::max(top, f.frame_ms);
        }
        // Its label above it, clear of the line.
        ImGui::TextDisabled("frame time, last %.0f s (0 to %.0f ms)", kHistoryS, top);
        ImGui::PlotLines("##frame_ms", ms.data(), static_cast<int>(ms.size()), 0, nullptr, 0.0f, top,
                         ImVec2(static_cast<float>(kStatsWidth) - 20.0f, 40.0f));
      }
      if (line.rfind("held ", 0) == 0 && s.memory_budget_bytes > 0) {
        const float f = static_cast<float>(static_cast<double>(s.held_bytes) / static_cast<double>(s.memory_budget_bytes));
        ImGui::ProgressBar(std::min(f, 1.0f), ImVec2(-FLT_MIN, 0.0f),
                           absl::StrFormat("%.0f%% of the memory budget", 100.0 * f).c_str());
      }
    }
    if (keys) {
      const std::string hint = absl::StrCat(
          BindingOf(WindowAction::kStats).name, " panel  ", BindingOf(WindowAction::kMinimap).name, " map  ",
          BindingOf(WindowAction::kHelp).name, " keys  ", BindingOf(WindowAction::kWalkList).name, " walks");
      ImGui::TextDisabled("%s", hint.c_str());
    }
  }
  ImGui::End();
}

void Overlay::Impl::Help(int width, int height) {
  const std::string title = absl::StrCat("Keys (", BindingOf(WindowAction::kHelp).label, " closes)");
  if (BeginCentred(title.c_str(), width, height)) {
    if (ImGui::BeginTable("keys", 2, ImGuiTableFlags_RowBg)) {
      for (const auto& [keys, what] : KeyListRows()) {
        ImGui::TableNextRow();
        ImGui::TableSetColumnIndex(0);
        ImGui::TextUnformatted(keys.c_str());
        ImGui::TableSetColumnIndex(1);
        ImGui::TextUnformatted(what.c_str());
      }
      ImGui::EndTable();
    }
  }
  ImGui::End();
}

OverlayRequest Overlay::Impl::Walks(const std::vector<std::string>& walks, int width, int height, bool* open) {
  OverlayRequest req;
  const std::string title = absl::StrCat("Walks (", BindingOf(WindowAction::kWalkList).name, " closes)");
  if (BeginCentred(title.c_str(), width, height)) {
    if (walks.empty()) {
      ImGui::TextUnformatted("this scene has no walks");
    } else {
      walk_selected = std::min(walk_selected, walks.size() - 1);
      ImGui::TextDisabled("%s", WalkListHint().c_str());
      for (size_t k = 0; k < walks.size(); ++k) {
        ImGui::PushID(static_cast<int>(k));
        if (ImGui::Selectable(walks[k].c_str(), k == walk_selected, 0, ImVec2(220.0f, 0.0f))) walk_selected = k;
        ImGui::SameLine();
        if (ImGui::SmallButton("from start")) req.follow_walk = k, req.from_start = true;
        ImGui::SameLine();
        if (ImGui::SmallButton("from here")) req.follow_walk = k, req.from_start = false;
        ImGui::PopID();
      }
    }
  }
  ImGui::End();
  if (req.follow_walk.has_value()) *open = false;
  return req;
}

Overlay::Overlay(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

absl::StatusOr<std::unique_ptr<Overlay>> Overlay::Create(gl::GlContext* context, void* window) {
  auto impl = std::make_unique<Impl>(context->functions());
  impl->context = context;
  impl->window = window;
  auto overlay = std::unique_ptr<Overlay>(new Overlay(std::move(impl)));
  if (absl::Status s = overlay->impl_->Init(); !s.ok()) return s;
  return overlay;
}

Overlay::~Overlay() {
  if (impl_ == nullptr || impl_->imgui == nullptr) return;
  ImGui::SetCurrentContext(impl_->imgui);
  if (impl_->glfw_backend) ImGui_ImplGlfw_Shutdown();
  if (impl_->context != nullptr && impl_->context->MakeCurrent().ok()) impl_->painter.Release();
  ImGui::DestroyContext(impl_->imgui);
}

void Overlay::AddFrame(double frame_ms, double now_s, uint64_t bytes_received) {
  impl_->samples.push_back({now_s, static_cast<float>(frame_ms), bytes_received});
  while (now_s - impl_->samples.front().t > kHistoryS) impl_->samples.pop_front();
}

bool Overlay::WantsMouse() const {
  ImGui::SetCurrentContext(impl_->imgui);
  return ImGui::GetIO().WantCaptureMouse || impl_->MouseOverPanel();
}

void Overlay::Invalidate() { impl_->invalid = true; }

size_t& Overlay::walk_selected() { return impl_->walk_selected; }

const std::vector<std::string>& Overlay::last_lines() const { return impl_->lines; }

absl::StatusOr<OverlayRequest> Overlay::Frame(const OverlayStatus& status, const MinimapView& map,
                                              const std::vector<std::string>& walks, int width, int height,
                                              double dt_s) {
  ImGui::SetCurrentContext(impl_->imgui);
  ImGuiIO& io = ImGui::GetIO();
  impl_->lines = OverlayLines(status, impl_->Fps(), impl_->samples.empty() ? 0.0 : impl_->samples.back().frame_ms,
                              impl_->BytesPerSecond());
  if (dt_s > 0.0) impl_->since_rebuild_s += dt_s;
  const std::array<bool, 4> shown{show_stats, show_minimap, show_help, show_walks};
  const bool rebuild = impl_->invalid || impl_->since_rebuild_s >= kRebuildS || shown != impl_->shown ||
                       width != impl_->painter.fb_w() || height != impl_->painter.fb_h() || io.WantCaptureMouse ||
                       impl_->MouseOverPanel();
  OverlayRequest req;
  if (rebuild) {
    // A panel that appears (or a new size) takes ImGui two frames: the first measures the
    // auto-sized windows without drawing them.
    const bool resized = width != impl_->painter.fb_w() || height != impl_->painter.fb_h();
    const int passes = shown != impl_->shown || resized ? 2 : 1;
    for (int pass = 0; pass < passes; ++pass) {
      if (impl_->glfw_backend) {
        ImGui_ImplGlfw_NewFrame();  // display size, scale, time and input from the window
      } else {
        io.DisplaySize = ImVec2(static_cast<float>(width), static_cast<float>(height));
        io.DisplayFramebufferScale = ImVec2(1.0f, 1.0f);
        io.DeltaTime = impl_->since_rebuild_s > 0.0 ? static_cast<float>(impl_->since_rebuild_s) : 1.0f / 60.0f;
      }
      ImGui::NewFrame();
      const int w = static_cast<int>(io.DisplaySize.x), h = static_cast<int>(io.DisplaySize.y);
      if (show_stats) impl_->StatsPanel(status);
      if (show_minimap) MinimapPanel(status, map, w, show_stats, impl_->window != nullptr);
      if (show_walks) {
        const OverlayRequest asked = impl_->Walks(walks, w, h, &show_walks);
        if (asked.follow_walk.has_value()) req = asked;
      }
      if (show_help) impl_->Help(w, h);
      ImGui::Render();
      impl_->since_rebuild_s = 0.0;
    }
    impl_->painter.Measure(ImGui::GetDrawData());
    impl_->invalid = false;
    impl_->shown = shown;
  }
  // ImGui's draw data stays as built until its next frame.
  if (absl::Status st = impl_->painter.Draw(ImGui::GetDrawData(), rebuild); !st.ok()) return st;
  return req;
}

}  // namespace vistream::client
