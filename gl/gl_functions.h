#pragma once
// OpenGL entry points as a table, loaded from the context that will call them. A process that
// draws both off-screen (OSMesa) and into a window (GLX through GLFW) links two GL libraries
// that export the same names; calls through this table reach the current context's own driver
// whichever library the linker bound the plain names to. The client's renderer calls GL only
// through it; the server-side users (planar raster, id renderer) are OSMesa-only and call the
// plain names.

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>

#include <absl/status/statusor.h>

namespace vistream::gl {

// Every entry point the table holds (OpenGL 3.3 core, plus texture buffers for the id
// renderer's masks): the renderer's, the overlay's (blending, scissors, its font texture, the
// texture its panels are kept in) and
// multisampling's (renderbuffers, the resolving blit).
#define VISTREAM_GL_FUNCTIONS(X)                                                                         \
  X(ActiveTexture) X(AttachShader) X(BindBuffer) X(BindFramebuffer) X(BindRenderbuffer) X(BindTexture)     \
  X(BindVertexArray) X(BufferData) X(BufferSubData) X(CheckFramebufferStatus) X(Clear) X(ClearColor)       \
  X(CompileShader) X(CreateProgram) X(CreateShader) X(CullFace) X(DeleteBuffers) X(DeleteFramebuffers)     \
  X(DeleteProgram) X(DeleteRenderbuffers) X(DeleteShader) X(DeleteTextures) X(DeleteVertexArrays)          \
  X(DepthFunc) X(Disable) X(DrawArrays) X(DrawElements) X(Enable) X(EnableVertexAttribArray) X(Finish)     \
  X(FramebufferRenderbuffer) X(GenBuffers) X(GenFramebuffers) X(GenRenderbuffers) X(GenTextures)           \
  X(GenVertexArrays) X(GetError) X(GetProgramInfoLog) X(GetProgramiv) X(GetShaderInfoLog) X(GetShaderiv)  \
  X(GetString) X(GetUniformLocation) X(LinkProgram) X(PixelStorei) X(ReadPixels) X(RenderbufferStorage)    \
  X(ShaderSource) X(TexBuffer) X(Uniform1f) X(Uniform1i) X(Uniform3f) X(UniformMatrix4fv) X(UseProgram)    \
  X(VertexAttribPointer) X(Viewport)                                                                      \
  X(BlendEquation) X(BlendFuncSeparate) X(Scissor) X(TexImage2D) X(TexParameteri) X(BlitFramebuffer)      \
  X(RenderbufferStorageMultisample) X(GetIntegerv) X(Uniform2f) X(FramebufferTexture2D)

struct GlFunctions {
#define VISTREAM_GL_MEMBER(name) decltype(&::gl##name) name = nullptr;
  VISTREAM_GL_FUNCTIONS(VISTREAM_GL_MEMBER)
#undef VISTREAM_GL_MEMBER

  // Looks every entry point up with `loader` ("glDrawElements" -> address). Errors
  // (UNAVAILABLE): the first name the loader does not know.
  static absl::StatusOr<GlFunctions> Load(void* (*loader)(const char*));
  // The names as the linker bound them (the off-screen OSMesa context's).
  static const GlFunctions& Linked();
};

}  // namespace vistream::gl
