#include "gl/shader.h"

#include <array>
#include <string>

#include <absl/strings/str_cat.h>

namespace vistream::gl {

namespace {

absl::StatusOr<GLuint> Compile(GLenum type, const char* source, const char* what) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    std::array<char, 4096> log{};
    glGetShaderInfoLog(shader, log.size(), nullptr, log.data());
    glDeleteShader(shader);
    return absl::InternalError(absl::StrCat(what, " ", type == GL_VERTEX_SHADER ? "vertex" : "fragment",
                                            " shader does not compile: ", log.data()));
  }
  return shader;
}

}  // namespace

absl::StatusOr<GLuint> LinkProgram(const char* vertex, const char* fragment, const char* what) {
  absl::StatusOr<GLuint> vs = Compile(GL_VERTEX_SHADER, vertex, what);
  if (!vs.ok()) return vs.status();
  absl::StatusOr<GLuint> fs = Compile(GL_FRAGMENT_SHADER, fragment, what);
  if (!fs.ok()) {
    glDeleteShader(*vs);
    return fs.status();
  }
  const GLuint program = glCreateProgram();
  glAttachShader(program, *vs);
  glAttachShader(program, *fs);
  glLinkProgram(program);
  glDeleteShader(*vs);
  glDeleteShader(*fs);
  GLint ok = 0;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    std::array<char, 4096> log{};
    glGetProgramInfoLog(program, log.size(), nullptr, log.data());
    glDeleteProgram(program);
    return absl::InternalError(absl::StrCat(what, " program does not link: ", log.data()));
  }
  return program;
}

}  // namespace vistream::gl
