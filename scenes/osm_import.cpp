#include "scenes/osm_import.h"

#include <CGAL/box_intersection_d.h>
#include <absl/strings/str_cat.h>

#include <GeographicLib/UTMUPS.hpp>
#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <glm/geometric.hpp>
#include <vector>

#include "scenes/derived_walks.h"
#include "scenes/osm_read.h"
#include "scenes/polygon.h"
#include "scenes/polygon_set.h"
#include "scenes/progress.h"

namespace vistream::scenes {

namespace fs = std::filesystem;

namespace {

// Scene-local coordinates snap to 1/256 m, as the generators' do (scenes/building.cpp).
double Snap(double x) { return std::round(x * 256.0) / 256.0; }

// " (reason: n, reason: n)" for an error that ends an import, so that what was left out is
// named even when nothing is left.
std::string Reasons(const OsmImportSummary& s) {
  std::string out;
  for (const auto& [reason, n] : s.skipped) {
    absl::StrAppend(&out, out.empty() ? " (" : ", ", reason, ": ", n);
  }
  return out.empty() ? out : out + ")";
}

// UTM in one zone and hemisphere for a whole import: GeographicLib's forward projection forced
// to the centre's zone, with northings of points across the equator moved to the centre's
// hemisphere (they differ by the false northing, UTMShift, 10,000 km).
class Projection {
 public:
  // Fails (a message) when the centre has no UTM/UPS projection.
  std::string Init(double lat, double lon) {
    try {
      GeographicLib::UTMUPS::Forward(lat, lon, zone_, north_, ox_, oy_);
    } catch (const std::exception& e) {
      return e.what();
    }
    ox_ = std::round(ox_);
    oy_ = std::round(oy_);
    return {};
  }
  std::string Zone() const { return GeographicLib::UTMUPS::EncodeZone(zone_, north_); }
  glm::dvec3 Origin() const { return {ox_, oy_, 0.0}; }

  // Scene-local metres, snapped; none where GeographicLib refuses the point (far outside the
  // zone) or it lies farther than kMaxOffsetM from the centre, where 1/256 m no longer fits in
  // a float.
  std::optional<Ring> Local(const std::vector<osmium::Location>& ring) const {
    constexpr double kMaxOffsetM = 65536.0;
    Ring out;
    out.reserve(ring.size());
    for (const osmium::Location& l : ring) {
      int z;
      bool n;
      double x, y;
      try {
        GeographicLib::UTMUPS::Forward(l.lat(), l.lon(), z, n, x, y, zone_);
      } catch (const std::exception&) {
        return std::nullopt;
      }
      if (zone_ != GeographicLib::UTMUPS::UPS && n != north_) {
        y += north_ ? -GeographicLib::UTMUPS::UTMShift() : GeographicLib::UTMUPS::UTMShift();
      }
      x -= ox_;
      y -= oy_;
      if (!(std::abs(x) < kMaxOffsetM && std::abs(y) < kMaxOffsetM)) return std::nullopt;
      out.emplace_back(Snap(x), Snap(y));
    }
    return out;
  }

 private:
  int zone_ = 0;
  bool north_ = true;
  double ox_ = 0.0, oy_ = 0.0;
};

// The scene's walks from its highway ways, over the buildings' xy bounds (the viewcell grid's).
void AddStreetWalks(const std::vector<RawHighway>& highways, const Projection& proj, size_t walks, Scene* scene,
                    OsmImportSummary* s) {
  std::vector<StreetPolyline> streets;
  streets.reserve(highways.size());
  for (const RawHighway& h : highways) {
    std::optional<Ring> local = proj.Local(h.nodes);
    if (!local) continue;
    streets.push_back({*std::move(local), h.street});
  }
  DeriveWalkOptions o;
  o.max_walks = walks;
  o.bounds.emplace(glm::dvec2(scene->bounds.min), glm::dvec2(scene->bounds.max));
  DerivedWalks derived = DeriveStreetWalks(streets, o);
  s->street_edges = derived.graph_edges;
  s->walk_notes = std::move(derived.notes);
  for (size_t k = 0; k < derived.paths.size(); ++k) {
    s->walks.push_back({derived.paths[k].name, derived.lengths_m[k]});
  }
  scene->paths = std::move(derived.paths);
}

// A building or part in scene-local metres: valid footprints and heights.
struct Footprint {
  const RawBuilding* raw = nullptr;
  std::vector<PolygonWithHoles> polygons;
  std::vector<std::vector<Triangle2>> triangles;  // Triangulate's, one per polygon
  HeightReading heights;
  bool hidden = false;  // an outline wholly covered by its parts
};

// Projects, repairs and checks one raw polygon. Invalid inner rings are dropped (counted);
// none and a reason when the outer ring is unusable.
std::optional<PolygonWithHoles> LocalPolygon(const RawPolygon& rp, const Projection& proj,
                                             OsmImportSummary* s, std::string* failure) {
  PolygonWithHoles poly;
  std::optional<Ring> outer = proj.Local(rp.outer);
  if (!outer) {
    *failure = "farther than 65 km from the data's centre";
    return std::nullopt;
  }
  poly.outer = *std::move(outer);
  const RingRepairs fix = CleanRing(&poly.outer);
  s->repaired_duplicate_points += fix.duplicate_points;
  s->repaired_spikes += fix.spikes;
  if (poly.outer.size() < 3) {
    *failure = "ring with fewer than 3 points";
    return std::nullopt;
  }
  if (!IsSimpleRing(poly.outer)) {
    *failure = "ring not simple after snapping to 4 mm";
    return std::nullopt;
  }
  if (SignedArea(poly.outer) < 0.0) std::reverse(poly.outer.begin(), poly.outer.end());
  for (const std::vector<osmium::Location>& rh : rp.holes) {
    std::optional<Ring> projected = proj.Local(rh);
    if (!projected) {
      ++s->dropped_inner_rings;
      continue;
    }
    Ring hole = *std::move(projected);
    const RingRepairs hf = CleanRing(&hole);
    s->repaired_duplicate_points += hf.duplicate_points;
    s->repaired_spikes += hf.spikes;
    // OSM's rules let inner rings touch the outer ring and each other at single nodes; they
    // must not cross, overlap or nest.
    bool ok = IsSimpleRing(hole) && RingInsideRing(hole, poly.outer);
    for (size_t g = 0; ok && g < poly.holes.size(); ++g) ok = RingsApart(hole, poly.holes[g]);
    if (!ok) {
      ++s->dropped_inner_rings;
      continue;
    }
    if (SignedArea(hole) > 0.0) std::reverse(hole.begin(), hole.end());
    poly.holes.push_back(std::move(hole));
  }
  return poly;
}

// Simple 3D Buildings: an outline is drawn only where none of its parts covers it. Parts are
// matched to outlines by overlapping boxes (CGAL's box intersection), then cut out exactly.
void CutOutlinesByParts(std::vector<Footprint>* footprints, OsmImportSummary* s) {
  using Box = CGAL::Box_intersection_d::Box_with_handle_d<double, 2, const Footprint*>;
  std::vector<Box> outlines, parts;
  for (const Footprint& f : *footprints) {
    CGAL::Bbox_2 bb;
    for (const PolygonWithHoles& p : f.polygons) {
      for (const glm::dvec2& v : p.outer) bb += CGAL::Bbox_2(v.x, v.y, v.x, v.y);
    }
    (f.raw->part ? parts : outlines).emplace_back(bb, &f);
  }
  if (parts.empty() || outlines.empty()) return;
  std::vector<std::pair<const Footprint*, const Footprint*>> pairs;  // (outline, part)
  CGAL::box_intersection_d(outlines.begin(), outlines.end(), parts.begin(), parts.end(),
                           [&](const Box& o, const Box& p) { pairs.emplace_back(o.handle(), p.handle()); });
  std::sort(pairs.begin(), pairs.end());
  for (size_t i = 0; i < pairs.size();) {
    // The boxes hold const handles; the outlines are this function's to change.
    Footprint& outline = const_cast<Footprint&>(*pairs[i].first);
    std::vector<PolygonWithHoles> cut;
    for (; i < pairs.size() && pairs[i].first == &outline; ++i) {
      for (const PolygonWithHoles& p : pairs[i].second->polygons) cut.push_back(p);
    }
    std::vector<PolygonWithHoles> rest;
    std::vector<std::vector<Triangle2>> rest_triangles;
    bool changed = false;
    for (size_t k = 0; k < outline.polygons.size(); ++k) {
      const PolygonWithHoles& p = outline.polygons[k];
      absl::StatusOr<std::vector<PolygonWithHoles>> pieces = Difference(p, cut);
      if (!pieces.ok()) {
        ++s->skipped[std::string(pieces.status().message())];
        changed = true;
        continue;
      }
      double before = SignedArea(p.outer), after = 0.0;
      for (const Ring& h : p.holes) before += SignedArea(h);
      for (const PolygonWithHoles& q : *pieces) {
        after += SignedArea(q.outer);
        for (const Ring& h : q.holes) after += SignedArea(h);
      }
      if (std::abs(after - before) <= 1e-9 * before) {
        rest.push_back(p);  // parts beside the outline, not on it: keep its rings as they were
        rest_triangles.push_back(outline.triangles[k]);
        continue;
      }
      changed = true;
      for (PolygonWithHoles& piece : *pieces) {
        // Crossing points were rounded: snap like every coordinate, and check again.
        for (glm::dvec2& v : piece.outer) v = {Snap(v.x), Snap(v.y)};
        CleanRing(&piece.outer);
        if (SignedArea(piece.outer) < 0.0) std::reverse(piece.outer.begin(), piece.outer.end());
        for (Ring& h : piece.holes) {
          for (glm::dvec2& v : h) v = {Snap(v.x), Snap(v.y)};
          CleanRing(&h);
          if (SignedArea(h) > 0.0) std::reverse(h.begin(), h.end());
        }
        // Part nodes on an outline's edge are off its line by up to the grid after projection
        // and snapping: the difference leaves slivers there. Pieces thinner than kSliverM
        // (twice the area over the perimeter) are such slivers, not building.
        constexpr double kSliverM = 0.05;
        double area = SignedArea(piece.outer), perimeter = 0.0;
        for (size_t e = 0; e < piece.outer.size(); ++e) {
          perimeter += glm::length(piece.outer[(e + 1) % piece.outer.size()] - piece.outer[e]);
        }
        for (const Ring& h : piece.holes) area += SignedArea(h);
        if (!(2.0 * area > kSliverM * perimeter)) continue;
        absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(piece);
        if (!tris.ok()) {
          // Slivers between a part and the outline's edge, thinner than the 4 mm grid.
          ++s->skipped["outline piece beside its parts not simple after snapping"];
          continue;
        }
        rest.push_back(std::move(piece));
        rest_triangles.push_back(*std::move(tris));
      }
    }
    if (!changed) continue;
    outline.polygons = std::move(rest);
    outline.triangles = std::move(rest_triangles);
    if (outline.polygons.empty()) {
      outline.hidden = true;
      ++s->outlines_hidden_by_parts;
    } else {
      ++s->outlines_cut_by_parts;
    }
  }
}

}  // namespace

absl::StatusOr<Scene> ImportOsm(const std::string& path, const OsmImportOptions& options,
                                OsmImportSummary* summary, const RunControl& run) {
  const auto start = std::chrono::steady_clock::now();
  OsmImportSummary local_summary;
  OsmImportSummary& s = summary != nullptr ? *summary : local_summary;
  s = OsmImportSummary{};
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": is a directory, not an OpenStreetMap file"));
  }
  if (!fs::is_regular_file(path, ec)) {
    return absl::NotFoundError(absl::StrCat(path, ": no such file"));
  }
  if (fs::file_size(path, ec) == 0) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": the file is empty"));
  }
  if (!(options.storey_m > 0.0) || !std::isfinite(options.storey_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat("storey height must be positive (", options.storey_m, ")"));
  }
  if (!(options.max_height_m > 0.0) || !std::isfinite(options.max_height_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat("the plausible height limit must be positive (", options.max_height_m, ")"));
  }

  std::vector<RawBuilding> raw;
  std::vector<RawHighway> highways;
  if (absl::Status read = ReadOsmBuildings(path, options.bbox, &raw, &s, run, options.walks > 0 ? &highways : nullptr);
      !read.ok()) {
    return read;
  }
  if (raw.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": no buildings (building=* or building:part=*) to import",
        s.Skipped() > 0 ? absl::StrCat("; ", s.Skipped(), " skipped", Reasons(s)) : ""));
  }

  // The projection: UTM in the zone of the data's centre, the median longitude and latitude of
  // the buildings' nodes (a stray node far away does not move it).
  std::vector<double> lons, lats;
  for (const RawBuilding& b : raw) {
    for (const RawPolygon& p : b.polygons) {
      for (const osmium::Location& l : p.outer) {
        lons.push_back(l.lon());
        lats.push_back(l.lat());
      }
    }
  }
  auto median = [](std::vector<double>& v) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  const double clat = median(lats), clon = median(lons);
  Projection proj;
  if (const std::string why = proj.Init(clat, clon); !why.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": the data's centre (", clat, ", ", clon,
                                                   ") has no UTM/UPS projection: ", why));
  }
  s.utm_zone = proj.Zone();

  // Footprints and heights of every building and part.
  std::vector<Footprint> footprints;
  footprints.reserve(raw.size());
  for (const RawBuilding& b : raw) {
    if (run.Cancelled()) return absl::CancelledError("OSM import cancelled");
    s.repaired_duplicate_points += b.duplicate_nodes;
    Footprint f;
    f.raw = &b;
    std::string failure;
    for (const RawPolygon& rp : b.polygons) {
      std::optional<PolygonWithHoles> poly = LocalPolygon(rp, proj, &s, &failure);
      if (!poly) continue;
      absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(*poly);
      if (!tris.ok() && !poly->holes.empty()) {
        // Holes the checks let through but the triangles show wrong: keep the building whole,
        // without its courtyards.
        s.dropped_inner_rings += poly->holes.size();
        poly->holes.clear();
        tris = Triangulate(*poly);
      }
      if (!tris.ok()) {
        failure = std::string(tris.status().message());
        continue;
      }
      f.polygons.push_back(*std::move(poly));
      f.triangles.push_back(*std::move(tris));
    }
    if (f.polygons.empty()) {
      ++s.skipped[failure.empty() ? std::string("no polygon left") : failure];
      continue;
    }
    f.heights = ReadHeights(b.tags, options.storey_m, options.max_height_m);
    footprints.push_back(std::move(f));
  }
  CutOutlinesByParts(&footprints, &s);

  Scene scene;
  scene.name = !options.name.empty() ? options.name : fs::path(path).filename().string();
  if (options.name.empty()) scene.name = scene.name.substr(0, scene.name.find('.'));
  scene.origin = proj.Origin();
  Progress progress(run, "building meshes", footprints.size());
  for (const Footprint& f : footprints) {
    if (run.Cancelled()) return absl::CancelledError("OSM import cancelled");
    progress.Advance();
    if (f.hidden) continue;
    const HeightReading& h = f.heights;
    const double base = Snap(h.base), top = Snap(h.top);
    // Only a solid standing on the ground, with heights that do not contradict each other,
    // may occlude (visibility/occluder_set.h).
    const bool occludes = base == 0.0 && !h.base_above_top;
    if (!(top > base)) {
      ++s.skipped["thinner than 4 mm"];
      continue;
    }
    Mesh mesh;
    std::vector<Occluder25D> occluders;
    for (size_t k = 0; k < f.polygons.size(); ++k) {
      const PolygonWithHoles& poly = f.polygons[k];
      const std::vector<Triangle2>& tris = f.triangles[k];
      AppendPrism(poly, tris, base, top, &mesh);
      ++s.outer_rings;
      s.inner_rings += poly.holes.size();
      if (!occludes) continue;
      if (poly.holes.empty()) {
        occluders.push_back({poly.outer, top, 0});
      } else {
        for (const Triangle2& t : tris) occluders.push_back({{t[0], t[1], t[2]}, top, 0});
      }
    }
    if (mesh.indices.empty()) continue;
    const ObjectId id = scene.AddObject(f.raw->name, std::move(mesh));
    for (Occluder25D& o : occluders) {
      o.object = id;
      scene.occluders.push_back(std::move(o));
    }
    s.occluders += occluders.size();
    ++s.buildings;
    ++(f.raw->from_relation ? s.from_relations : s.from_ways);
    s.parts += f.raw->part;
    s.raised += base > 0.0;
    s.bad_height_tags += static_cast<uint64_t>(h.unreadable);
    s.implausible_heights += static_cast<uint64_t>(h.implausible);
    s.min_height_above_height += h.base_above_top;
    switch (h.source) {
      case HeightReading::Source::kHeightTag: ++s.height_tagged; break;
      case HeightReading::Source::kLevels: ++s.levels_tagged; break;
      case HeightReading::Source::kRule: ++s.height_by_rule; break;
    }
  }
  progress.Finish();
  if (scene.objects.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": no building could be imported; ",
                                                   s.Skipped(), " skipped", Reasons(s)));
  }
  if (options.walks > 0) AddStreetWalks(highways, proj, options.walks, &scene, &s);
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return scene;
}

}  // namespace vistream::scenes
