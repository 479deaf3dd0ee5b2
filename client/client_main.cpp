// vistream-client: the thin walkthrough client (DESIGN.md, "Server and client"). Connects to a
// vistream-server, reports its pose, draws only what the server streamed. A window (GLFW) by
// default; --headless follows a walk of the scene catalog off-screen (OSMesa) and prints a
// summary. Exit codes: 0 done, 1 a run-time error (named on stderr), 2 bad options, 130
// stopped by ^C (the summary of what was walked is still printed).
#include <signal.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <grpc/support/log.h>

#include <CLI/CLI.hpp>
#include <absl/strings/numbers.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_split.h>

#include "cli/number_options.h"
#include "cli/unexpected_arguments.h"
#include "client/walkthrough.h"

namespace {

std::atomic<bool> g_stop{false};
std::atomic<bool> g_screenshot{false};
extern "C" void OnSignal(int) { g_stop.store(true); }
extern "C" void OnScreenshotSignal(int) { g_screenshot.store(true); }

// A finite number in [lo, hi], shared with the vistream tool (CLI11's own checks let NaN through).
using vistream::cli::FiniteRange;

bool ParseSize(const std::string& text, int* width, int* height) {
  const std::vector<std::string> parts = absl::StrSplit(text, 'x');
  return parts.size() == 2 && absl::SimpleAtoi(parts[0], width) && absl::SimpleAtoi(parts[1], height) &&
         *width >= 16 && *height >= 16 && *width <= 8192 && *height <= 8192;
}

// HOST:PORT (IPv6 hosts in brackets) with a port from 1 to 65535.
bool ValidAddress(const std::string& address) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon == 0) return false;
  const std::string port = address.substr(colon + 1);
  int p = 0;
  return !port.empty() && port.find_first_not_of("0123456789") == std::string::npos && absl::SimpleAtoi(port, &p) &&
         p >= 1 && p <= 65535;
}

bool ParsePose(const std::string& text, vistream::client::FixedPose* pose) {
  const std::vector<std::string> parts = absl::StrSplit(text, ',');
  double v[5];
  if (parts.size() != 5) return false;
  for (int k = 0; k < 5; ++k) {
    if (!absl::SimpleAtod(parts[k], &v[k]) || !std::isfinite(v[k])) return false;
  }
  pose->eye = {v[0], v[1], v[2]};
  pose->yaw_rad = v[3] * M_PI / 180.0;
  pose->pitch_rad = v[4] * M_PI / 180.0;
  return std::abs(v[4]) < 89.0;
}

}  // namespace

int main(int argc, char** argv) {
  using vistream::client::WalkthroughOptions;
  WalkthroughOptions o;
  std::string size = "1280x720", pose;
  bool json = false, no_masks = false;
  double memory_mb = -1.0, triangle_budget = -1.0, upload_mb = 4.0;
  CLI::App app("vistream-client: walk through a city streamed by vistream-server");
  app.add_option("--server", o.server, "host:port of vistream-server")->capture_default_str();
  app.add_flag("--headless", o.headless, "draw off-screen (OSMesa) along a walk instead of opening a window");
  app.add_option("--scene", o.scene, "the scene to walk, when the server serves several (its only one otherwise)");
  app.add_option("--path", o.path, "walk to follow: one of the scene's catalog entry, or one the server sends from the scene's "
                 "data (\"street 1\"); headless: default the first; a name neither has lists them all");
  app.add_option("--speed", o.speed_kmh, "walking speed in km/h (default: the walk's)")->check(FiniteRange(0.01, 10000));
  app.add_option("--seconds", o.seconds, "stop after this many seconds of the walk (default: all of it)")
      ->check(FiniteRange(0.01, 1e7));
  app.add_option("--size", size, "frame size in pixels, WIDTHxHEIGHT")->capture_default_str();
  app.add_option("--screenshots", o.screenshots_dir, "write PNG screenshots into this folder");
  app.add_option("--every", o.every_s, "seconds of the walk between screenshots and between --verify checks")
      ->check(FiniteRange(0.01, 1e7))
      ->capture_default_str();
  app.add_flag("--verify", o.verify,
               "load the full scene locally and count pixels where the drawn set differs from it (tests)");
  app.add_flag("--json", json, "print the summary as JSON");
  app.add_flag("--overlay", o.overlay,
               "headless: draw the statistics panel and the minimap into the frames and screenshots (the window "
               "always has them: F1, M)");
  app.add_option("--overlay-dump", o.overlay_dump, "at the end, write the statistics panel's lines of the last frame "
                 "to this file (the window's, or with --overlay)");
  app.add_option("--msaa", o.msaa_samples, "multisample antialiasing samples, 0 for none (default: 4 in the window, "
                 "none headless)")
      ->check(CLI::Range(0, 16));
  bool no_overlay = false;
  app.add_flag("--no-overlay", no_overlay, "the window starts without its panels (F1 and M show them)");
  bool no_vsync = false;
  app.add_flag("--no-vsync", no_vsync, "the window does not wait for the display's refresh (vsync is on by default)");
  app.add_option("--frame-log", o.frame_log, "write one CSV line per frame to this file");
  app.add_option("--cell-log", o.cell_log,
                 "write one CSV line per viewcell entered (cell_id,i,j,entered_s,complete_s,margin_s,stalled)");
  app.add_option("--connect-timeout", o.connect_timeout_s, "seconds to wait for the server to answer")
      ->check(FiniteRange(0.1, 3600))
      ->capture_default_str();
  app.add_option("--give-up", o.give_up_s, "seconds without the server before the run ends with an error; 0 never")
      ->check(FiniteRange(0.0, 1e7))
      ->capture_default_str();
  app.add_option("--catalog", o.catalog_dir, "scene catalog folder (walks and client budgets)");
  app.add_option("--memory-mb", memory_mb, "memory budget for held geometry, MiB (default: the catalog's)")
      ->check(FiniteRange(0.0, 1e9));
  app.add_option("--triangle-budget", triangle_budget, "triangles a frame may draw (default: the catalog's)")
      ->check(FiniteRange(0.0, 1e12));
  app.add_option("--upload-mb", upload_mb, "GPU uploads a frame, MiB")->check(FiniteRange(0.01, 1e6))->capture_default_str();
  app.add_option("--max-fps", o.max_fps, "frame-rate cap; 0 draws as fast as it can")
      ->check(FiniteRange(0.0, 1e4))
      ->capture_default_str();
  app.add_flag("--no-masks", no_masks,
               "ask the server for no ε-masks (Hello.epsilon_masks false) and draw the viewcell PVS whole (a baseline)");
  std::string lod = "1";
  app.add_option("--lod", lod,
                 "levels of detail: the screen error in pixels the client accepts (tau, in (0, 1000]), or off for "
                 "full detail; a server without levels sends full detail")
      ->capture_default_str();
  std::string lod_clusters = "off";
  app.add_option("--lod-clusters", lod_clusters,
                 "with --lod: on, far groups of objects may come as one cluster level (drawn as each object's piece); "
                 "off (the default), objects' own levels only")
      ->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option("--pose", pose, "stand at X,Y,Z (scene-local m) looking YAW,PITCH (degrees) instead of walking");
  app.add_option("--frames", o.frames, "with --pose: frames to draw before exiting (headless default 1)")
      ->check(CLI::Range(uint64_t{1}, uint64_t{1} << 40));
  std::string tls_ca, tls_cert, tls_key, token_file;
  app.add_option("--tls-ca", tls_ca, "PEM CA bundle that signed the server's certificate: connect with TLS");
  app.add_option("--tls-cert", tls_cert, "PEM client certificate for a server that requires one (mutual TLS)");
  app.add_option("--tls-key", tls_key, "PEM private key of --tls-cert");
  app.add_option("--token-file", token_file,
                 "file holding the server's bearer token (never on the command line, where ps shows it)");
  // Bad options exit 2, in the vistream tool's form: "<option>: <what is wrong>", then the hint.
  auto bad_option = [](const std::string& message) {
    std::fprintf(stderr, "vistream-client: error: %s\nRun 'vistream-client --help' for the options.\n", message.c_str());
    return 2;
  };
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // Unknown options first: a misspelt option often hides another complaint.
    const std::string unexpected = vistream::cli::UnexpectedArguments(app.remaining(), "vistream-client");
    return bad_option(unexpected.empty() ? e.what() : unexpected);
  }
  if (std::error_code ec; !o.catalog_dir.empty() && !std::filesystem::is_directory(o.catalog_dir, ec)) {
    return bad_option("--catalog: '" + o.catalog_dir + "': no such folder");
  }
  if (!ValidAddress(o.server)) {
    return bad_option("--server: '" + o.server + "': expected HOST:PORT with a port from 1 to 65535");
  }
  if (!ParseSize(size, &o.width, &o.height)) {
    return bad_option("--size: '" + size + "': expected WIDTHxHEIGHT from 16x16 to 8192x8192, e.g. 1280x720");
  }
  if (!pose.empty()) {
    vistream::client::FixedPose p;
    if (!ParsePose(pose, &p)) {
      return bad_option("--pose: '" + pose + "': expected X,Y,Z,YAW,PITCH (metres, degrees; pitch within +-89)");
    }
    o.pose = p;
  }
  o.lod_clusters = lod_clusters == "on";
  if (!vistream::cli::ParseScreenError(lod, &o.lod_tau_px)) {
    return bad_option("--lod: '" + lod + "': expected off or a screen error in pixels in (0, 1000]");
  }
  if (o.frames > 0 && !o.pose.has_value()) return bad_option("--frames: needs --pose");
  if (!o.overlay_dump.empty() && o.headless && !o.overlay) return bad_option("--overlay-dump: headless, needs --overlay");
  o.vsync = !no_vsync;
  o.window_panels = !no_overlay;
  if (o.overlay && no_overlay) return bad_option("--overlay: cannot be given with --no-overlay");
  if (!o.path.empty() && o.pose.has_value()) return bad_option("--path: cannot be given with --pose");
  if (absl::StatusOr<vistream::client::ChannelSecurity> security =
          vistream::client::LoadChannelSecurity(tls_ca, tls_cert, tls_key, token_file);
      security.ok()) {
    o.security = *std::move(security);
  } else {
    return bad_option(std::string(security.status().message()));
  }
  if (memory_mb >= 0.0) o.memory_budget_bytes = static_cast<uint64_t>(memory_mb * 1048576.0);
  if (triangle_budget >= 0.0) o.triangle_budget = static_cast<uint64_t>(triangle_budget);
  o.upload_budget_bytes = static_cast<uint64_t>(upload_mb * 1048576.0);
  o.use_masks = !no_masks;
  // gRPC's own log lines (a failed TLS handshake, once per retry) say less than the error this
  // client prints; GRPC_VERBOSITY in the environment brings them back.
  if (std::getenv("GRPC_VERBOSITY") == nullptr) gpr_set_log_function([](gpr_log_func_args*) {});
  o.cancel = &g_stop;
  o.screenshot_request = &g_screenshot;
  o.log = [](const std::string& line) { std::fprintf(stderr, "vistream-client: %s\n", line.c_str()); };
  struct sigaction sa {};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // SIGUSR1: a screenshot of the next frame (headless too), into --screenshots or ./vistream-screenshots.
  struct sigaction shot {};
  shot.sa_handler = OnScreenshotSignal;
  sigemptyset(&shot.sa_mask);
  shot.sa_flags = SA_RESTART;
  sigaction(SIGUSR1, &shot, nullptr);

  vistream::client::WalkthroughSummary summary;
  const absl::Status status = vistream::client::RunWalkthrough(o, &summary);
  // A walk that ran and then failed (the server lost for good) still says what it did; one
  // that never started (no server, a bad option found late) has nothing to say.
  if (status.ok() || summary.frames > 0) {
    if (json) {
      std::printf("%s\n", vistream::client::SummaryJson(summary).c_str());
    } else {
      std::printf("%s", vistream::client::SummaryText(summary).c_str());
    }
  }
  if (!status.ok()) {
    std::fprintf(stderr, "vistream-client: error: %s\n", std::string(status.message()).c_str());
    return 1;
  }
  return summary.cancelled ? 130 : 0;
}
