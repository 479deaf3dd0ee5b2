#include "client/overlay.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <filesystem>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <glm/gtc/type_ptr.hpp>
#include <glm/mat4x4.hpp>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>

#include "gl/shader.h"

namespace vistream::client {

namespace {

constexpr const char* kVertexShader = R"(#version 330 core
layout(location = 0) in vec2 position;
layout(location = 1) in vec2 uv;
layout(location = 2) in vec4 colour;
uniform mat4 projection;
out vec2 f_uv;
out vec4 f_colour;
void main() {
  f_uv = uv;
  f_colour = colour;
  gl_Position = projection * vec4(position, 0.0, 1.0);
}
)";

constexpr const char* kFragmentShader = R"(#version 330 core
in vec2 f_uv;
in vec4 f_colour;
uniform sampler2D atlas;
out vec4 fragment;
void main() { fragment = f_colour * texture(atlas, f_uv); }
)";

// A TrueType font from Debian's fonts-dejavu-core reads better than ImGui's 13-pixel bitmap
// font; without it, the bitmap font.
constexpr const char* kFontPath = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
constexpr float kFontPx = 15.0f;

ImU32 Rgb(const std::array<uint8_t, 3>& c, uint8_t alpha = 255) { return IM_COL32(c[0], c[1], c[2], alpha); }

// A round length for a scale bar about `target_m` long: 1, 2 or 5 times a power of ten.
double NiceLength(double target_m) {
  const double p = std::pow(10.0, std::floor(std::log10(std::max(target_m, 1e-3))));
  for (double m : {5.0, 2.0, 1.0}) {
    if (m * p <= target_m) return m * p;
  }
  return p;
}

// Windows in fixed places, sized to what they hold; the panels also never take the focus.
constexpr ImGuiWindowFlags kFixed = ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse |
                                    ImGuiWindowFlags_NoSavedSettings | ImGuiWindowFlags_AlwaysAutoResize |
                                    ImGuiWindowFlags_NoNav;
constexpr ImGuiWindowFlags kPanel = kFixed | ImGuiWindowFlags_NoFocusOnAppearing | ImGuiWindowFlags_NoScrollbar;

// The minimap's ground where there are no viewcells (and the lines between cells).
constexpr std::array<uint8_t, 3> kBeyondGrid{30, 32, 36};

// A window in the middle of a `width` x `height` frame (the key list, the walk list).
bool BeginCentred(const char* title, int width, int height) {
  ImGui::SetNextWindowPos(ImVec2(0.5f * static_cast<float>(width), 0.5f * static_cast<float>(height)), ImGuiCond_Always,
                          ImVec2(0.5f, 0.5f));
  return ImGui::Begin(title, nullptr, kFixed);
}

std::string Megabytes(uint64_t bytes) { return absl::StrFormat("%.1f MB", static_cast<double>(bytes) / 1e6); }

}  // namespace

std::array<uint8_t, 3> MinimapColour(CellState state) {
  switch (state) {
    case CellState::kComplete:
      return {64, 160, 90};
    case CellState::kPending:
      return {225, 170, 40};
    case CellState::kNotListed:
      break;
  }
  return {70, 74, 82};
}

std::array<uint8_t, 3> MinimapCurrentCellColour() { return {80, 170, 255}; }

double MinimapRadius(const GridInfo& grid) { return std::clamp(8.0 * grid.cell_size, 150.0, 600.0); }

void MinimapCells::Refresh(const ObjectStore& store, const std::function<bool(uint32_t)>& uploaded,
                           const glm::dvec3& eye, double radius_m, size_t max_lookups) {
  if (!store.has_scene_info()) return;
  const GridInfo& g = store.grid();
  const size_t n = static_cast<size_t>(g.nx) * static_cast<size_t>(g.ny);
  if (states_.size() != n) states_.assign(n, CellState::kNotListed);
  size_t lookups = 0;
  auto state = [&](uint32_t id) {
    const std::vector<uint32_t>* list = store.Pvs(id);
    if (list == nullptr) return CellState::kNotListed;
    for (uint32_t o : *list) {
      ++lookups;
      if (!uploaded(o)) return CellState::kPending;
    }
    return CellState::kComplete;
  };
  if (const std::optional<uint32_t> c = g.CellAt(eye.x, eye.y)) states_[*c] = state(*c);
  const double r = radius_m + g.cell_size;
  const int i0 = std::max(0, static_cast<int>(std::floor((eye.x - r - g.x0) / g.cell_size)));
  const int i1 = std::min(g.nx - 1, static_cast<int>(std::floor((eye.x + r - g.x0) / g.cell_size)));
  const int j0 = std::max(0, static_cast<int>(std::floor((eye.y - r - g.y0) / g.cell_size)));
  const int j1 = std::min(g.ny - 1, static_cast<int>(std::floor((eye.y + r - g.y0) / g.cell_size)));
  if (i1 < i0 || j1 < j0) return;
  const size_t w = static_cast<size_t>(i1 - i0 + 1), count = w * static_cast<size_t>(j1 - j0 + 1);
  for (size_t k = 0; k < count && lookups < max_lookups; ++k) {
    const size_t at = cursor_++ % count;
    const auto id = static_cast<uint32_t>((j0 + static_cast<int>(at / w)) * g.nx + i0 + static_cast<int>(at % w));
    states_[id] = state(id);
  }
}

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
  gl::GlContext* context = nullptr;
  gl::GlFunctions gl;
  void* window = nullptr;
  ImGuiContext* imgui = nullptr;
  bool glfw_backend = false;
  unsigned program = 0, vao = 0, vbo = 0, ibo = 0, font_texture = 0;
  int loc_projection = -1, loc_atlas = -1;
  // The panels as last built: a texture the framebuffer's size holding them, and their
  // rectangles (framebuffer pixels, top-left origin, in drawing order), opaque. Frames between
  // builds copy these rectangles.
  unsigned cache_fbo = 0, cache_texture = 0;
  int cache_w = 0, cache_h = 0;  // the texture's size
  int fb_w = 0, fb_h = 0;        // the framebuffer's at the last build
  struct Rect {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  };
  std::vector<Rect> rects;
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
  // Drawing state for ImGui's lists over a framebuffer of `width` x `height` pixels: the
  // overlay's program, no depth, ImGui's blending.
  void Begin2D(int width, int height);
  void End2D();
  // ImGui's draw lists (its OpenGL 3 back end's drawing: scissored commands) into the
  // framebuffer bound (fb_h pixels high), through the context's function table.
  void DrawLists(const ImDrawData* d);
  // The framebuffer's size and the panels' rectangles of a new build.
  void Measure(const ImDrawData* d);
  // The panels into the cache (made or remade at the size measured).
  absl::Status DrawIntoCache(const ImDrawData* d);
  // The panels over the framebuffer bound: copied from the cache (drawn into it first when
  // `rebuilt`), or, into a multisample framebuffer, drawn. Errors (INTERNAL): GL failing.
  absl::Status Draw(const ImDrawData* d, bool rebuilt);
  // Whether the window's mouse cursor is over a panel as last built.
  bool MouseOverPanel() const;
  // The samples of the last second (or what there is): the first one's index, and the span.
  std::pair<size_t, double> LastSecond() const;
  double Fps() const;
  double BytesPerSecond() const;
  void StatsPanel(const OverlayStatus& s);
  // `beside_stats`: the statistics panel is shown (the map shrinks to stay clear of it in a
  // narrow frame).
  void Minimap(const OverlayStatus& s, const MinimapView& map, int width, bool beside_stats);
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

  absl::StatusOr<unsigned> p = gl::LinkProgram(gl, kVertexShader, kFragmentShader, "overlay");
  if (!p.ok()) return p.status();
  program = *p;
  loc_projection = gl.GetUniformLocation(program, "projection");
  loc_atlas = gl.GetUniformLocation(program, "atlas");
  gl.GenVertexArrays(1, &vao);
  gl.GenBuffers(1, &vbo);
  gl.GenBuffers(1, &ibo);
  gl.BindVertexArray(vao);
  gl.BindBuffer(GL_ARRAY_BUFFER, vbo);
  gl.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, ibo);
  gl.EnableVertexAttribArray(0);
  gl.EnableVertexAttribArray(1);
  gl.EnableVertexAttribArray(2);
  gl.VertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, sizeof(ImDrawVert),
                         reinterpret_cast<void*>(offsetof(ImDrawVert, pos)));
  gl.VertexAttribPointer(1, 2, GL_FLOAT, GL_FALSE, sizeof(ImDrawVert), reinterpret_cast<void*>(offsetof(ImDrawVert, uv)));
  gl.VertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, sizeof(ImDrawVert),
                         reinterpret_cast<void*>(offsetof(ImDrawVert, col)));
  gl.BindVertexArray(0);

  unsigned char* pixels = nullptr;
  int w = 0, h = 0;
  io.Fonts->GetTexDataAsRGBA32(&pixels, &w, &h);
  gl.GenTextures(1, &font_texture);
  gl.BindTexture(GL_TEXTURE_2D, font_texture);
  gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  gl.PixelStorei(GL_UNPACK_ALIGNMENT, 1);
  gl.TexImage2D(GL_TEXTURE_2D, 0, GL_RGBA, w, h, 0, GL_RGBA, GL_UNSIGNED_BYTE, pixels);
  gl.BindTexture(GL_TEXTURE_2D, 0);
  io.Fonts->SetTexID(reinterpret_cast<ImTextureID>(static_cast<intptr_t>(font_texture)));
  if (const GLenum err = gl.GetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("overlay: GL error ", err, " while setting up"));
  }
  return absl::OkStatus();
}

void Overlay::Impl::Begin2D(int width, int height) {
  // ImGui's OpenGL 3 back end's blending.
  gl.Enable(GL_BLEND);
  gl.BlendEquation(GL_FUNC_ADD);
  gl.BlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
  gl.Disable(GL_CULL_FACE);
  gl.Disable(GL_DEPTH_TEST);
  gl.Viewport(0, 0, width, height);
  // Pixels, y down, onto clip space.
  const float r = static_cast<float>(width), b = static_cast<float>(height);
  const glm::mat4 projection(2.0f / r, 0.0f, 0.0f, 0.0f,   //
                             0.0f, -2.0f / b, 0.0f, 0.0f,  //
                             0.0f, 0.0f, -1.0f, 0.0f,      //
                             -1.0f, 1.0f, 0.0f, 1.0f);
  gl.UseProgram(program);
  gl.Uniform1i(loc_atlas, 0);
  gl.UniformMatrix4fv(loc_projection, 1, GL_FALSE, glm::value_ptr(projection));
  gl.ActiveTexture(GL_TEXTURE0);
  gl.BindVertexArray(vao);
  gl.BindBuffer(GL_ARRAY_BUFFER, vbo);
}

void Overlay::Impl::End2D() {
  gl.BindVertexArray(0);
  gl.BindTexture(GL_TEXTURE_2D, 0);
  gl.Disable(GL_SCISSOR_TEST);
  gl.Disable(GL_BLEND);
  gl.Enable(GL_DEPTH_TEST);
}

void Overlay::Impl::DrawLists(const ImDrawData* d) {
  const ImVec2 off = d->DisplayPos, scale = d->FramebufferScale;
  gl.Enable(GL_SCISSOR_TEST);
  for (int n = 0; n < d->CmdListsCount; ++n) {
    const ImDrawList* list = d->CmdLists[n];
    if (list->VtxBuffer.Size == 0) continue;
    gl.BufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(list->VtxBuffer.Size) * sizeof(ImDrawVert),
                  list->VtxBuffer.Data, GL_STREAM_DRAW);
    gl.BufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(list->IdxBuffer.Size) * sizeof(ImDrawIdx),
                  list->IdxBuffer.Data, GL_STREAM_DRAW);
    for (int c = 0; c < list->CmdBuffer.Size; ++c) {
      const ImDrawCmd& cmd = list->CmdBuffer[c];
      if (cmd.UserCallback != nullptr) continue;  // none are used
      const float x0 = (cmd.ClipRect.x - off.x) * scale.x, y0 = (cmd.ClipRect.y - off.y) * scale.y;
      const float x1 = (cmd.ClipRect.z - off.x) * scale.x, y1 = (cmd.ClipRect.w - off.y) * scale.y;
      if (x1 <= x0 || y1 <= y0) continue;
      gl.Scissor(static_cast<int>(x0), static_cast<int>(static_cast<float>(fb_h) - y1), static_cast<int>(x1 - x0),
                 static_cast<int>(y1 - y0));
      gl.BindTexture(GL_TEXTURE_2D, static_cast<unsigned>(reinterpret_cast<intptr_t>(cmd.GetTexID())));
      gl.DrawElements(GL_TRIANGLES, static_cast<GLsizei>(cmd.ElemCount),
                      sizeof(ImDrawIdx) == 2 ? GL_UNSIGNED_SHORT : GL_UNSIGNED_INT,
                      reinterpret_cast<void*>(static_cast<intptr_t>(cmd.IdxOffset * sizeof(ImDrawIdx))));
    }
  }
}

void Overlay::Impl::Measure(const ImDrawData* d) {
  const ImVec2 off = d->DisplayPos, scale = d->FramebufferScale;
  fb_w = static_cast<int>(d->DisplaySize.x * scale.x);
  fb_h = static_cast<int>(d->DisplaySize.y * scale.y);
  rects.clear();
  for (int n = 0; n < d->CmdListsCount; ++n) {
    const ImDrawList* list = d->CmdLists[n];
    if (list->VtxBuffer.Size == 0) continue;
    // What the list draws: each command's triangles' box within its clip rectangle (a walk's
    // line runs past the minimap, clipped), over the commands. A panel's list starts with its
    // opaque, square background, so the whole box is opaque.
    float lo_x = FLT_MAX, lo_y = FLT_MAX, hi_x = -FLT_MAX, hi_y = -FLT_MAX;
    for (const ImDrawCmd& cmd : list->CmdBuffer) {
      if (cmd.UserCallback != nullptr || cmd.ElemCount == 0) continue;
      float cx0 = FLT_MAX, cy0 = FLT_MAX, cx1 = -FLT_MAX, cy1 = -FLT_MAX;
      for (unsigned k = cmd.IdxOffset; k < cmd.IdxOffset + cmd.ElemCount; ++k) {
        const ImVec2& v = list->VtxBuffer[static_cast<int>(cmd.VtxOffset + list->IdxBuffer[static_cast<int>(k)])].pos;
        cx0 = std::min(cx0, v.x);
        cy0 = std::min(cy0, v.y);
        cx1 = std::max(cx1, v.x);
        cy1 = std::max(cy1, v.y);
      }
      cx0 = std::max(cx0, cmd.ClipRect.x);
      cy0 = std::max(cy0, cmd.ClipRect.y);
      cx1 = std::min(cx1, cmd.ClipRect.z);
      cy1 = std::min(cy1, cmd.ClipRect.w);
      if (cx1 <= cx0 || cy1 <= cy0) continue;
      lo_x = std::min(lo_x, cx0);
      lo_y = std::min(lo_y, cy0);
      hi_x = std::max(hi_x, cx1);
      hi_y = std::max(hi_y, cy1);
    }
    if (hi_x <= lo_x || hi_y <= lo_y) continue;
    const Rect r{std::max(0, static_cast<int>(std::floor((lo_x - off.x) * scale.x))),
                 std::max(0, static_cast<int>(std::floor((lo_y - off.y) * scale.y))),
                 std::min(fb_w, static_cast<int>(std::ceil((hi_x - off.x) * scale.x))),
                 std::min(fb_h, static_cast<int>(std::ceil((hi_y - off.y) * scale.y)))};
    if (r.x1 > r.x0 && r.y1 > r.y0) rects.push_back(r);
  }
}

absl::Status Overlay::Impl::DrawIntoCache(const ImDrawData* d) {
  GLint bound = 0;
  gl.GetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &bound);
  if (cache_texture == 0 || fb_w != cache_w || fb_h != cache_h) {
    if (cache_fbo != 0) gl.DeleteFramebuffers(1, &cache_fbo);
    if (cache_texture != 0) gl.DeleteTextures(1, &cache_texture);
    gl.GenTextures(1, &cache_texture);
    gl.BindTexture(GL_TEXTURE_2D, cache_texture);
    gl.TexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, fb_w, fb_h, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
    gl.BindTexture(GL_TEXTURE_2D, 0);
    gl.GenFramebuffers(1, &cache_fbo);
    gl.BindFramebuffer(GL_FRAMEBUFFER, cache_fbo);
    gl.FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, cache_texture, 0);
    const bool complete = gl.CheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    gl.BindFramebuffer(GL_FRAMEBUFFER, static_cast<unsigned>(bound));
    if (!complete) {
      return absl::InternalError(absl::StrFormat("overlay: the %dx%d panel framebuffer is incomplete", fb_w, fb_h));
    }
    cache_w = fb_w;
    cache_h = fb_h;
  }
  gl.BindFramebuffer(GL_FRAMEBUFFER, cache_fbo);
  // Only the panels' rectangles are ever copied out: those are cleared, then drawn whole.
  gl.Enable(GL_SCISSOR_TEST);
  gl.ClearColor(0.0f, 0.0f, 0.0f, 1.0f);
  for (const Rect& r : rects) {
    gl.Scissor(r.x0, fb_h - r.y1, r.x1 - r.x0, r.y1 - r.y0);
    gl.Clear(GL_COLOR_BUFFER_BIT);
  }
  Begin2D(fb_w, fb_h);
  DrawLists(d);
  End2D();
  gl.BindFramebuffer(GL_FRAMEBUFFER, static_cast<unsigned>(bound));
  if (const GLenum err = gl.GetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("overlay: GL error ", err, " while drawing the panels"));
  }
  return absl::OkStatus();
}

absl::Status Overlay::Impl::Draw(const ImDrawData* d, bool rebuilt) {
  if (rects.empty() || fb_w <= 0 || fb_h <= 0) return absl::OkStatus();
  GLint sample_buffers = 0;
  gl.GetIntegerv(GL_SAMPLE_BUFFERS, &sample_buffers);
  if (sample_buffers > 0) {
    // A multisample target cannot take a copy: the panels are drawn into it.
    Begin2D(fb_w, fb_h);
    DrawLists(d);
    End2D();
    return absl::OkStatus();
  }
  if (rebuilt || cache_texture == 0) {
    if (absl::Status st = DrawIntoCache(d); !st.ok()) return st;
  }
  // The panels are opaque: their rectangles are copied, in the order drawn (where they
  // overlap, the cache holds the upper one, copied twice).
  GLint bound = 0;
  gl.GetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &bound);
  gl.BindFramebuffer(GL_READ_FRAMEBUFFER, cache_fbo);
  for (const Rect& r : rects) {
    gl.BlitFramebuffer(r.x0, fb_h - r.y1, r.x1, fb_h - r.y0, r.x0, fb_h - r.y1, r.x1, fb_h - r.y0, GL_COLOR_BUFFER_BIT,
                       GL_NEAREST);
  }
  gl.BindFramebuffer(GL_FRAMEBUFFER, static_cast<unsigned>(bound));
  if (const GLenum err = gl.GetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("overlay: GL error ", err, " while copying the panels"));
  }
  return absl::OkStatus();
}

bool Overlay::Impl::MouseOverPanel() const {
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
  x *= static_cast<double>(fb_w) / ww;
  y *= static_cast<double>(fb_h) / wh;
  return std::any_of(rects.begin(), rects.end(),
                     [&](const Rect& r) { return x >= r.x0 && x < r.x1 && y >= r.y0 && y < r.y1; });
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
  if (ImGui::Begin(keys ? "vistream (F1)" : "vistream", nullptr, kPanel)) {
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
    if (keys) ImGui::TextDisabled("F1 panel  M map  H keys  P walks");
  }
  ImGui::End();
}

void Overlay::Impl::Minimap(const OverlayStatus& s, const MinimapView& map, int width, bool beside_stats) {
  // Beside the statistics panel: what the frame's width leaves (its padding 2 x 8 px), at least
  // kMinimapMinPx (a frame narrower than both panels gets them overlapping).
  const int room = beside_stats ? width - (kMargin + kStatsWidth) - 2 * kMargin - 16 : kMinimapPx;
  const float px = static_cast<float>(std::clamp(room, kMinimapMinPx, kMinimapPx));
  ImGui::SetNextWindowPos(ImVec2(static_cast<float>(width - kMargin), kMargin), ImGuiCond_Always, ImVec2(1.0f, 0.0f));
  if (ImGui::Begin("minimap", nullptr, kPanel | ImGuiWindowFlags_NoTitleBar)) {
    // Wrapped at the map's width, so that the window keeps it.
    ImGui::PushTextWrapPos(ImGui::GetCursorPosX() + px);
    ImGui::TextWrapped("%s", window != nullptr ? "Viewcells around the eye (M), north up"
                                               : "Viewcells around the eye, north up");
    ImGui::PopTextWrapPos();
    const ImVec2 origin = ImGui::GetCursorScreenPos();
    ImGui::Dummy(ImVec2(px, px));
    ImDrawList* dl = ImGui::GetWindowDrawList();
    const ImVec2 lo = origin, hi(origin.x + px, origin.y + px);
    dl->AddRectFilled(lo, hi, Rgb(kBeyondGrid));
    dl->PushClipRect(lo, hi, true);
    const double scale = px / (2.0 * map.radius_m);  // pixels a metre
    const ImVec2 centre(origin.x + 0.5f * px, origin.y + 0.5f * px);
    auto to_map = [&](double x, double y) {
      return ImVec2(centre.x + static_cast<float>((x - s.eye.x) * scale), centre.y - static_cast<float>((y - s.eye.y) * scale));
    };
    bool beyond_grid = true;  // the map shows ground without viewcells
    if (map.grid != nullptr && map.grid->nx > 0 && map.grid->ny > 0 && map.grid->cell_size > 0.0) {
      const GridInfo& g = *map.grid;
      beyond_grid = s.eye.x - map.radius_m < g.x0 || s.eye.x + map.radius_m > g.x0 + g.nx * g.cell_size ||
                    s.eye.y - map.radius_m < g.y0 || s.eye.y + map.radius_m > g.y0 + g.ny * g.cell_size;
      const int i0 = std::max(0, static_cast<int>(std::floor((s.eye.x - map.radius_m - g.x0) / g.cell_size)));
      const int i1 = std::min(g.nx - 1, static_cast<int>(std::floor((s.eye.x + map.radius_m - g.x0) / g.cell_size)));
      const int j0 = std::max(0, static_cast<int>(std::floor((s.eye.y - map.radius_m - g.y0) / g.cell_size)));
      const int j1 = std::min(g.ny - 1, static_cast<int>(std::floor((s.eye.y + map.radius_m - g.y0) / g.cell_size)));
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const size_t id = static_cast<size_t>(j) * static_cast<size_t>(g.nx) + static_cast<size_t>(i);
          const CellState state =
              map.cells != nullptr && id < map.cells->size() ? (*map.cells)[id] : CellState::kNotListed;
          const ImVec2 a = to_map(g.x0 + i * g.cell_size, g.y0 + (j + 1) * g.cell_size);
          const ImVec2 b = to_map(g.x0 + (i + 1) * g.cell_size, g.y0 + j * g.cell_size);
          const bool current = s.cell.has_value() && *s.cell == id;
          // A pixel short of its neighbours: the map's background between them draws the grid.
          dl->AddRectFilled(ImVec2(a.x + 1.0f, a.y + 1.0f), b,
                            Rgb(current ? MinimapCurrentCellColour() : MinimapColour(state)));
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
                                                Rgb(colour));
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

void Overlay::Impl::Help(int width, int height) {
  if (BeginCentred("Keys (H or ? closes)", width, height)) {
    static constexpr const char* kKeys[][2] = {
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
    if (ImGui::BeginTable("keys", 2, ImGuiTableFlags_RowBg)) {
      for (const auto& k : kKeys) {
        ImGui::TableNextRow();
        ImGui::TableSetColumnIndex(0);
        ImGui::TextUnformatted(k[0]);
        ImGui::TableSetColumnIndex(1);
        ImGui::TextUnformatted(k[1]);
      }
      ImGui::EndTable();
    }
  }
  ImGui::End();
}

OverlayRequest Overlay::Impl::Walks(const std::vector<std::string>& walks, int width, int height, bool* open) {
  OverlayRequest req;
  if (BeginCentred("Walks (P closes)", width, height)) {
    if (walks.empty()) {
      ImGui::TextUnformatted("this scene has no walks");
    } else {
      walk_selected = std::min(walk_selected, walks.size() - 1);
      ImGui::TextDisabled("Up/Down choose, Enter from its start, F from here");
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
  auto impl = std::make_unique<Impl>();
  impl->context = context;
  impl->gl = context->functions();
  impl->window = window;
  auto overlay = std::unique_ptr<Overlay>(new Overlay(std::move(impl)));
  if (absl::Status s = overlay->impl_->Init(); !s.ok()) return s;
  return overlay;
}

Overlay::~Overlay() {
  if (impl_ == nullptr || impl_->imgui == nullptr) return;
  ImGui::SetCurrentContext(impl_->imgui);
  if (impl_->glfw_backend) ImGui_ImplGlfw_Shutdown();
  if (impl_->context != nullptr && impl_->context->MakeCurrent().ok()) {
    impl_->gl.DeleteProgram(impl_->program);
    impl_->gl.DeleteVertexArrays(1, &impl_->vao);
    impl_->gl.DeleteBuffers(1, &impl_->vbo);
    impl_->gl.DeleteBuffers(1, &impl_->ibo);
    impl_->gl.DeleteTextures(1, &impl_->font_texture);
    if (impl_->cache_fbo != 0) impl_->gl.DeleteFramebuffers(1, &impl_->cache_fbo);
    if (impl_->cache_texture != 0) impl_->gl.DeleteTextures(1, &impl_->cache_texture);
  }
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
                       width != impl_->fb_w || height != impl_->fb_h || io.WantCaptureMouse ||
                       impl_->MouseOverPanel();
  OverlayRequest req;
  if (rebuild) {
    // A panel that appears (or a new size) takes ImGui two frames: the first measures the
    // auto-sized windows without drawing them.
    const int passes = shown != impl_->shown || width != impl_->fb_w || height != impl_->fb_h ? 2 : 1;
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
      if (show_minimap) impl_->Minimap(status, map, w, show_stats);
      if (show_walks) {
        const OverlayRequest asked = impl_->Walks(walks, w, h, &show_walks);
        if (asked.follow_walk.has_value()) req = asked;
      }
      if (show_help) impl_->Help(w, h);
      ImGui::Render();
      impl_->since_rebuild_s = 0.0;
    }
    impl_->Measure(ImGui::GetDrawData());
    impl_->invalid = false;
    impl_->shown = shown;
  }
  // ImGui's draw data stays as built until its next frame.
  if (absl::Status st = impl_->Draw(ImGui::GetDrawData(), rebuild); !st.ok()) return st;
  return req;
}

}  // namespace vistream::client
