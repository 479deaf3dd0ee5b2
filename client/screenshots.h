#pragma once
// The walkthrough's screenshots: the frame just drawn as a PNG, named for its frame number and
// the walk's clock (--screenshots every --every seconds, F12 in the window, SIGUSR1).

#include <cstdint>
#include <string>

#include <absl/status/status.h>
#include <absl/status/statusor.h>

#include "client/renderer.h"

namespace vistream::client {

// Makes `dir` (and its parents) for --screenshots before the walk starts. Errors: UNAVAILABLE
// naming the folder and --screenshots.
absl::Status CreateScreenshotDir(const std::string& dir);

// Writes the frame `renderer` drew last (resolved by ReadRgb) as
// `<dir>/frame-<frame>-t<t_s>s.png`, where `dir` is `screenshots_dir`, or, when that is empty
// (F12 and SIGUSR1 without --screenshots), ./vistream-screenshots in the working folder, made
// here. `frame`: the frames drawn before it; `t_s`: the walk's clock, seconds. Returns the
// file's path. Errors: reading the pixels back (GL), UNAVAILABLE when the folder cannot be made,
// WritePng's (client/png_image.h).
absl::StatusOr<std::string> WriteScreenshot(Renderer& renderer, const std::string& screenshots_dir, uint64_t frame,
                                            double t_s);

}  // namespace vistream::client
