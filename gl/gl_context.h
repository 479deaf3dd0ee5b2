#pragma once
// The one place where OpenGL contexts are made. Off-screen contexts come from OSMesa (only
// gl_context.cpp knows, so EGL surfaceless, as upstream Mesa dropped OSMesa in 25.1, can
// replace it here alone); window contexts from GLFW. Code that may run on either calls GL
// through functions(); off-screen-only code may call the linked names directly.

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "gl/gl_functions.h"

namespace vistream::gl {

class GlContext {
 public:
  // An off-screen OpenGL 4.5 core context; draw into framebuffer objects. A context is current
  // on one thread at a time.
  static absl::StatusOr<std::unique_ptr<GlContext>> CreateOffscreen();
  // A resizable window of `width` x `height` screen pixels with an OpenGL 3.3 core context,
  // current on the calling thread; one at a time per process. Its framebuffer is single-sample
  // (a renderer multisamples into its own and resolves into it); `vsync`: swaps wait for the
  // display's refresh.
  // Errors (UNAVAILABLE): no display (the message says how to run without one), no GL 3.3.
  static absl::StatusOr<std::unique_ptr<GlContext>> CreateWindowed(int width, int height, const std::string& title,
                                                                   bool vsync = true);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  // Makes this context current on the calling thread.
  absl::Status MakeCurrent();
  // A GL entry point the library does not export directly (e.g. glClipControl); null if none.
  static void* ProcAddress(const char* name);
  // This context's entry points.
  const GlFunctions& functions() const;

  // Window contexts only (null / no-ops off-screen): the GLFWwindow, for input.
  void* window() const;
  void SwapBuffers();
  // The framebuffer's size in pixels (differs from the window's on high-DPI screens).
  void FramebufferSize(int* width, int* height) const;

 private:
  struct Impl;
  explicit GlContext(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vistream::gl
