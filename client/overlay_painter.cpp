#include "client/overlay_painter.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <glm/gtc/type_ptr.hpp>
#include <glm/mat4x4.hpp>

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

}  // namespace

absl::Status OverlayPainter::Init(ImGuiIO& io) {
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

void OverlayPainter::Release() {
  gl.DeleteProgram(program);
  gl.DeleteVertexArrays(1, &vao);
  gl.DeleteBuffers(1, &vbo);
  gl.DeleteBuffers(1, &ibo);
  gl.DeleteTextures(1, &font_texture);
  if (cache_fbo != 0) gl.DeleteFramebuffers(1, &cache_fbo);
  if (cache_texture != 0) gl.DeleteTextures(1, &cache_texture);
}

void OverlayPainter::Begin2D(int width, int height) {
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

void OverlayPainter::End2D() {
  gl.BindVertexArray(0);
  gl.BindTexture(GL_TEXTURE_2D, 0);
  gl.Disable(GL_SCISSOR_TEST);
  gl.Disable(GL_BLEND);
  gl.Enable(GL_DEPTH_TEST);
}

void OverlayPainter::DrawLists(const ImDrawData* d) {
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
      gl.Scissor(static_cast<int>(x0), static_cast<int>(static_cast<float>(fb_h_) - y1), static_cast<int>(x1 - x0),
                 static_cast<int>(y1 - y0));
      gl.BindTexture(GL_TEXTURE_2D, static_cast<unsigned>(reinterpret_cast<intptr_t>(cmd.GetTexID())));
      gl.DrawElements(GL_TRIANGLES, static_cast<GLsizei>(cmd.ElemCount),
                      sizeof(ImDrawIdx) == 2 ? GL_UNSIGNED_SHORT : GL_UNSIGNED_INT,
                      reinterpret_cast<void*>(static_cast<intptr_t>(cmd.IdxOffset * sizeof(ImDrawIdx))));
    }
  }
}

void OverlayPainter::Measure(const ImDrawData* d) {
  const ImVec2 off = d->DisplayPos, scale = d->FramebufferScale;
  fb_w_ = static_cast<int>(d->DisplaySize.x * scale.x);
  fb_h_ = static_cast<int>(d->DisplaySize.y * scale.y);
  rects_.clear();
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
                 std::min(fb_w_, static_cast<int>(std::ceil((hi_x - off.x) * scale.x))),
                 std::min(fb_h_, static_cast<int>(std::ceil((hi_y - off.y) * scale.y)))};
    if (r.x1 > r.x0 && r.y1 > r.y0) rects_.push_back(r);
  }
}

absl::Status OverlayPainter::DrawIntoCache(const ImDrawData* d) {
  GLint bound = 0;
  gl.GetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &bound);
  if (cache_texture == 0 || fb_w_ != cache_w || fb_h_ != cache_h) {
    if (cache_fbo != 0) gl.DeleteFramebuffers(1, &cache_fbo);
    if (cache_texture != 0) gl.DeleteTextures(1, &cache_texture);
    gl.GenTextures(1, &cache_texture);
    gl.BindTexture(GL_TEXTURE_2D, cache_texture);
    gl.TexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, fb_w_, fb_h_, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
    gl.BindTexture(GL_TEXTURE_2D, 0);
    gl.GenFramebuffers(1, &cache_fbo);
    gl.BindFramebuffer(GL_FRAMEBUFFER, cache_fbo);
    gl.FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, cache_texture, 0);
    const bool complete = gl.CheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    gl.BindFramebuffer(GL_FRAMEBUFFER, static_cast<unsigned>(bound));
    if (!complete) {
      return absl::InternalError(absl::StrFormat("overlay: the %dx%d panel framebuffer is incomplete", fb_w_, fb_h_));
    }
    cache_w = fb_w_;
    cache_h = fb_h_;
  }
  gl.BindFramebuffer(GL_FRAMEBUFFER, cache_fbo);
  // Only the panels' rectangles are ever copied out: those are cleared, then drawn whole.
  gl.Enable(GL_SCISSOR_TEST);
  gl.ClearColor(0.0f, 0.0f, 0.0f, 1.0f);
  for (const Rect& r : rects_) {
    gl.Scissor(r.x0, fb_h_ - r.y1, r.x1 - r.x0, r.y1 - r.y0);
    gl.Clear(GL_COLOR_BUFFER_BIT);
  }
  Begin2D(fb_w_, fb_h_);
  DrawLists(d);
  End2D();
  gl.BindFramebuffer(GL_FRAMEBUFFER, static_cast<unsigned>(bound));
  if (const GLenum err = gl.GetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("overlay: GL error ", err, " while drawing the panels"));
  }
  return absl::OkStatus();
}

absl::Status OverlayPainter::Draw(const ImDrawData* d, bool rebuilt) {
  if (rects_.empty() || fb_w_ <= 0 || fb_h_ <= 0) return absl::OkStatus();
  GLint sample_buffers = 0;
  gl.GetIntegerv(GL_SAMPLE_BUFFERS, &sample_buffers);
  if (sample_buffers > 0) {
    // A multisample target cannot take a copy: the panels are drawn into it.
    Begin2D(fb_w_, fb_h_);
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
  for (const Rect& r : rects_) {
    gl.BlitFramebuffer(r.x0, fb_h_ - r.y1, r.x1, fb_h_ - r.y0, r.x0, fb_h_ - r.y1, r.x1, fb_h_ - r.y0, GL_COLOR_BUFFER_BIT,
                       GL_NEAREST);
  }
  gl.BindFramebuffer(GL_FRAMEBUFFER, static_cast<unsigned>(bound));
  if (const GLenum err = gl.GetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("overlay: GL error ", err, " while copying the panels"));
  }
  return absl::OkStatus();
}

}  // namespace vistream::client
