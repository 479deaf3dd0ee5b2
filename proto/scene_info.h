#pragma once
// The SceneInfo message (proto/walkthrough.proto) a session starts with, made from the scene
// and its viewcell grid: by the server for every session, and by the client that holds the
// whole scene itself (--draw-everything's preload), so that both describe a scene alike.

#include <string>

#include <absl/status/statusor.h>

#include "proto/walkthrough.pb.h"
#include "scenes/scene.h"
#include "visibility/viewcell_grid.h"

namespace vistream {

// SceneInfo for `scene` served as `name` over `grid`: origin (the scene's frame in its CRS),
// bounds, object and triangle counts (scene-local metres), the grid (corner, cell size, cell
// counts, band; per-cell bands where cells follow terrain, as band_z pairs in cell order) and
// the scene's own walks (Scene::paths, xy pairs); `levels` is the session's to set. Infallible.
v1::SceneInfo MakeSceneInfo(const scenes::Scene& scene, const visibility::ViewcellGrid& grid, const std::string& name);

// The client's viewcell grid from what SceneInfo says (the inverse of MakeSceneInfo's grid): the
// same cells, bands and cell ids as the server's. A grid without cells (sizes or counts not
// positive) is an empty grid. Errors (INVALID_ARGUMENT, naming what is wrong): a band list of
// the wrong length ("the viewcell grid lists 3 band values for 2 cells (4 expected)"), a band
// empty or not finite ("viewcell 1's band [6, 6] is empty or not finite"), too many cells.
absl::StatusOr<visibility::ViewcellGrid> GridFromSceneInfo(const v1::ViewcellGrid& grid);

}  // namespace vistream
