#pragma once
// The overlay's drawing (client/overlay.h): ImGui's draw lists through the GL context's
// function table (gl/gl_functions.h), so that an OSMesa frame gets the panels as the window
// does (Debian's ImGui OpenGL 3 back end cannot draw into an OSMesa context); and the panels'
// cache: a texture holding them as last built, whose rectangles each frame copies. Inside the
// client library only.

#include <utility>
#include <vector>

#include <absl/status/status.h>
#include <imgui.h>

#include "gl/gl_functions.h"

namespace vistream::client {

class OverlayPainter {
 public:
  // A panel's rectangle: framebuffer pixels, top-left origin, [x0, x1) x [y0, y1).
  struct Rect {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  };

  // Draws through `functions`, the GL context's table (gl::GlContext::functions()).
  explicit OverlayPainter(const gl::GlFunctions& functions) : gl(functions) {}

  // Makes the program, buffers and font texture (ImGui's font atlas of `io`, whose texture id
  // it sets); the context current. Errors (INTERNAL): GL failing.
  absl::Status Init(ImGuiIO& io);
  // Deletes the GL objects; their context current.
  void Release();
  // The framebuffer's size and the panels' rectangles of a new build.
  void Measure(const ImDrawData* d);
  // The panels over the framebuffer bound: copied from the cache (drawn into it first when
  // `rebuilt`), or, into a multisample framebuffer, drawn. Errors (INTERNAL): GL failing.
  absl::Status Draw(const ImDrawData* d, bool rebuilt);

  // As measured at the last build.
  int fb_w() const { return fb_w_; }
  int fb_h() const { return fb_h_; }
  const std::vector<Rect>& rects() const { return rects_; }

 private:
  // Drawing state for ImGui's lists over a framebuffer of `width` x `height` pixels: the
  // overlay's program, no depth, ImGui's blending.
  void Begin2D(int width, int height);
  void End2D();
  // ImGui's draw lists (its OpenGL 3 back end's drawing: scissored commands) into the
  // framebuffer bound (fb_h_ pixels high), through the context's function table.
  void DrawLists(const ImDrawData* d);
  // The panels into the cache (made or remade at the size measured).
  absl::Status DrawIntoCache(const ImDrawData* d);

  gl::GlFunctions gl;
  unsigned program = 0, vao = 0, vbo = 0, ibo = 0, font_texture = 0;
  int loc_projection = -1, loc_atlas = -1;
  // The panels as last built: a texture the framebuffer's size holding them, and their
  // rectangles (in drawing order), opaque. Frames between builds copy these rectangles.
  unsigned cache_fbo = 0, cache_texture = 0;
  int cache_w = 0, cache_h = 0;  // the texture's size
  int fb_w_ = 0, fb_h_ = 0;        // the framebuffer's at the last build
  std::vector<Rect> rects_;
};

}  // namespace vistream::client
