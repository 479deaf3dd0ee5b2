#pragma once
// GLSL programs, for every renderer in gl/ (and the client's): compile and link with errors
// that name the program and carry the driver's log. Needs a current context.

#include <absl/status/statusor.h>

#include "gl/gl_functions.h"

namespace vistream::gl {

// The linked program of `vertex` and `fragment` sources. Errors (INTERNAL) name `what` and
// give the compiler's or linker's log.
// `gl`: the current context's entry points (default: the linked names, OSMesa's).
absl::StatusOr<GLuint> LinkProgram(const GlFunctions& gl, const char* vertex, const char* fragment, const char* what);
inline absl::StatusOr<GLuint> LinkProgram(const char* vertex, const char* fragment, const char* what) {
  return LinkProgram(GlFunctions::Linked(), vertex, fragment, what);
}

}  // namespace vistream::gl
