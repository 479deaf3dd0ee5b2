#pragma once
// Boolean difference of footprints (CGAL's 2D regularized Boolean set operations, exact
// kernel), for the Simple 3D Buildings rule that an outline is drawn only where no part
// covers it.

#include <absl/status/statusor.h>

#include <vector>

#include "scenes/polygon.h"

namespace vistream::scenes {

// `from` less the union of `cut`, as polygons with holes (outer counter-clockwise, holes
// clockwise; metres, any frame). Every ring of `from` and `cut` must be simple, outer rings
// counter-clockwise and holes clockwise (as Triangulate takes them). Points where edges cross
// are rounded to double; callers snap and check the result again. An empty vector when `cut`
// covers `from`; an error if CGAL refuses the input.
absl::StatusOr<std::vector<PolygonWithHoles>> Difference(const PolygonWithHoles& from,
                                                         const std::vector<PolygonWithHoles>& cut);

// The union of `pieces` (each as Difference takes its rings), as polygons with holes: outer
// counter-clockwise, holes clockwise, in no particular order. Points where edges cross are
// rounded to double. An empty vector for no pieces; an error if CGAL refuses the input.
absl::StatusOr<std::vector<PolygonWithHoles>> Union(const std::vector<PolygonWithHoles>& pieces);

}  // namespace vistream::scenes
