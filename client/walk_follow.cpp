#include "client/walk_follow.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_join.h>
#include <glm/geometric.hpp>

#include "client/walkthrough_loop.h"

namespace vistream::client {

namespace {

// The walk's point nearest the eye is searched this far apart along it (metres).
constexpr double kNearestStepM = 1.0;

}  // namespace

absl::StatusOr<scenes::Walk> MakeWalk(const scenes::WalkPath& path, double speed_mps, const scenes::Scene* scene) {
  return scene != nullptr && !scene->terrain.empty()
             ? scenes::Walk::Create(path, speed_mps, std::make_shared<const scenes::TerrainHeight>(*scene))
             : scenes::Walk::Create(path, speed_mps);
}

double NearestWalkTime(const scenes::Walk& walk, const glm::dvec2& eye) {
  double best = std::numeric_limits<double>::infinity(), from_s = 0.0;
  for (double along = 0.0; along <= walk.length_m() + 0.5; along += kNearestStepM) {
    const glm::dvec2 q = walk.PointAt(along);
    const double d = glm::length(q - eye);
    if (d < best) best = d, from_s = std::min(along, walk.length_m()) / walk.speed_mps();
  }
  return from_s;
}

void AddServerWalks(const v1::SceneInfo& info, std::vector<scenes::WalkPath>* walks,
                    const std::function<void(const std::string&)>& log) {
  // The server's walks at the speed and eye height of the catalog's first walk, else the defaults.
  const scenes::WalkPath defaults = walks->empty() ? scenes::WalkPath{} : walks->front();
  for (int k = 0; k < info.paths_size(); ++k) {
    const v1::ScenePathInfo& p = info.paths(k);
    const bool taken =
        std::any_of(walks->begin(), walks->end(), [&](const scenes::WalkPath& w) { return w.name == p.name(); });
    bool finite = true;
    for (double v : p.xy()) finite = finite && std::isfinite(v);
    if (taken || p.name().empty() || p.xy_size() < 4 || p.xy_size() % 2 != 0 || !finite) {
      if (!taken && log) {
        log(absl::StrCat("the server's walk ", k, " ('", p.name(), "') is not a named polyline: ignored"));
      }
      continue;
    }
    scenes::WalkPath w;
    w.name = p.name();
    w.speed_mps = defaults.speed_mps;
    w.eye_height_m = defaults.eye_height_m;
    for (int i = 0; i + 1 < p.xy_size(); i += 2) w.waypoints.emplace_back(p.xy(i), p.xy(i + 1));
    walks->push_back(std::move(w));
  }
}

// The walkthrough loop's walks (client/walkthrough_loop.h).

absl::Status WalkthroughLoop::ChooseWalk() {
  const scenes::WalkPath* path = nullptr;
  std::vector<std::string> names;
  for (const scenes::WalkPath& w : walks_) {
    names.push_back(w.name);
    if (path == nullptr && (w.name == opt_.path || opt_.path.empty())) path = &w;
  }
  if (path == nullptr) {
    if (walks_.empty() && !entry_.has_value()) {
      return absl::NotFoundError(absl::StrCat("the server's scene '", sum_->scene,
                                              "' has no entry in the scene catalog (", catalog_status_.message(),
                                              ") and the server sends no walks (a glTF file holds those its scene "
                                              "was saved with): there is no walk to follow; give --pose instead"));
    }
    return absl::NotFoundError(
        opt_.path.empty()
            ? absl::StrCat("scene '", sum_->scene, "'", entry_.has_value() ? absl::StrCat(" (", entry_->file, ")") : "",
                           " has no walks")
            : absl::StrCat("scene '", sum_->scene, "' has no walk '", opt_.path, "'; its walks: ",
                           absl::StrJoin(names, ", ")));
  }
  return FollowWalk(*path, false);
}

absl::Status WalkthroughLoop::FollowWalk(const scenes::WalkPath& path, bool from_here) {
  const double speed = opt_.speed_kmh > 0.0 ? opt_.speed_kmh / 3.6 : path.speed_mps;
  // With the scene here, terrain and all, the eye keeps its height above the ground.
  absl::StatusOr<scenes::Walk> walk = MakeWalk(path, speed, full_scene_);
  if (!walk.ok()) return walk.status();
  const double from_s = from_here ? NearestWalkTime(*walk, glm::dvec2(camera_.eye)) : 0.0;
  walk_ = std::move(*walk);
  walk_path_ = path;
  walk_pending_ = false;
  walk_limit_s_ = opt_.seconds > 0.0 ? std::min(opt_.seconds, walk_->duration_s()) : walk_->duration_s();
  walk_t_ = from_s;
  paused_ = false;
  sum_->path = path.name;
  sum_->speed_kmh = speed * 3.6;
  const scenes::WalkPose start = walk_->At(from_s);
  camera_.eye = start.eye;
  camera_.yaw_rad = start.yaw_rad;
  camera_.pitch_rad = 0.0;
  have_start_ = true;
  return absl::OkStatus();
}

void WalkthroughLoop::StartAtFirstWalk() {
  if (have_start_ || walks_.empty()) return;
  absl::StatusOr<scenes::Walk> walk = scenes::Walk::Create(walks_.front(), walks_.front().speed_mps);
  if (walk.ok()) {
    camera_.eye = walk->At(0.0).eye;
    camera_.yaw_rad = walk->At(0.0).yaw_rad;
    have_start_ = true;
  }
}

absl::Status WalkthroughLoop::OnSceneInfo(const v1::SceneInfo& info) {
  AddServerWalks(info, &walks_, opt_.log);
  if (walk_pending_) return ChooseWalk();
  if (!opt_.pose.has_value()) StartAtFirstWalk();
  return absl::OkStatus();
}

}  // namespace vistream::client
