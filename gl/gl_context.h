#pragma once
// The one place where OpenGL contexts are made. Everything that draws takes a current context
// and calls GL directly; only gl_context.cpp knows the context comes from OSMesa, so EGL
// surfaceless (upstream Mesa dropped OSMesa in 25.1) can replace it there alone.

#include <memory>

#include "absl/status/statusor.h"

namespace vistream::gl {

class GlContext {
 public:
  // An off-screen OpenGL 4.5 core context; draw into framebuffer objects. A context is current
  // on one thread at a time.
  static absl::StatusOr<std::unique_ptr<GlContext>> CreateOffscreen();
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  // Makes this context current on the calling thread.
  absl::Status MakeCurrent();
  // A GL entry point the library does not export directly (e.g. glClipControl); null if none.
  static void* ProcAddress(const char* name);

 private:
  struct Impl;
  explicit GlContext(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vistream::gl
