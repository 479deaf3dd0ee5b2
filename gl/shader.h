#pragma once
// GLSL programs, for every renderer in gl/ (and the client's): compile and link with errors
// that name the program and carry the driver's log. Needs a current context.

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>

#include <absl/status/statusor.h>

namespace vistream::gl {

// The linked program of `vertex` and `fragment` sources. Errors (INTERNAL) name `what` and
// give the compiler's or linker's log.
absl::StatusOr<GLuint> LinkProgram(const char* vertex, const char* fragment, const char* what);

}  // namespace vistream::gl
