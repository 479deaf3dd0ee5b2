#include "scenes/osm_import.h"

#include <absl/strings/str_cat.h>

#include <GeographicLib/UTMUPS.hpp>
#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <osmium/area/assembler.hpp>
#include <osmium/area/multipolygon_manager.hpp>
#include <osmium/area/problem_reporter.hpp>
#include <osmium/handler.hpp>
#include <osmium/handler/node_locations_for_ways.hpp>
#include <osmium/index/map/flex_mem.hpp>
#include <osmium/io/pbf_input.hpp>
#include <osmium/io/xml_input.hpp>
#include <osmium/osm/area.hpp>
#include <osmium/relations/manager_util.hpp>
#include <osmium/visitor.hpp>
#include <unordered_map>
#include <vector>

#include "scenes/polygon.h"
#include "scenes/progress.h"

namespace vistream::scenes {

namespace fs = std::filesystem;

namespace {

std::string_view Strip(std::string_view t) {
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
  return t;
}

// The whole of `t` (stripped) as a finite number.
std::optional<double> Number(std::string_view t) {
  t = Strip(t);
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  double v;
  const auto [end, err] = std::from_chars(t.data(), t.data() + t.size(), v);
  if (t.empty() || err != std::errc() || end != t.data() + t.size() || !std::isfinite(v)) {
    return std::nullopt;
  }
  return v;
}

// Scene-local coordinates snap to 1/256 m, as the generators' do (scenes/building.cpp).
double Snap(double x) { return std::round(x * 256.0) / 256.0; }

constexpr double kRoofM = 1.0;  // the roof on top of counted storeys, when no tag says

bool IsBuilding(const osmium::TagList& tags) {
  const char* v = tags.get_value_by_key("building");
  return v != nullptr && std::string_view(v) != "no";
}

// Why osmium's assembler gave up on an object, by the id of the area it would have made
// (a way's id x 2, a relation's x 2 + 1, as osmium numbers areas).
class Reasons : public osmium::area::ProblemReporter {
 public:
  std::unordered_map<int64_t, std::string> why;
  std::unordered_map<int64_t, uint64_t> duplicate_nodes;

  void report_duplicate_node(osmium::object_id_type, osmium::object_id_type,
                             osmium::Location) override {
    ++duplicate_nodes[AreaId()];
  }
  void report_intersection(osmium::object_id_type, osmium::Location, osmium::Location,
                           osmium::object_id_type, osmium::Location, osmium::Location,
                           osmium::Location) override {
    Note("self-intersecting ring");
  }
  void report_duplicate_segment(const osmium::NodeRef&, const osmium::NodeRef&) override {
    Note("duplicate segment");
  }
  void report_overlapping_segment(const osmium::NodeRef&, const osmium::NodeRef&) override {
    Note("overlapping segments");
  }
  void report_ring_not_closed(const osmium::NodeRef&, const osmium::Way*) override {
    Note("ring not closed");
  }
  void report_way_in_multiple_rings(const osmium::Way&) override { Note("way in several rings"); }
  void report_invalid_location(osmium::object_id_type, osmium::object_id_type) override {
    Note("missing node locations");
  }

 private:
  int64_t AreaId() const {
    return m_object_type == osmium::item_type::way ? 2 * m_object_id : 2 * m_object_id + 1;
  }
  void Note(const char* reason) { why.emplace(AreaId(), reason); }  // the first reason counts
};

// Building ways that osmium's manager passes over in silence, counted by reason.
class WayCensus : public osmium::handler::Handler {
 public:
  explicit WayCensus(std::map<std::string, uint64_t>* skipped) : skipped_(skipped) {}
  void way(const osmium::Way& way) {
    if (!IsBuilding(way.tags())) return;
    const auto& nodes = way.nodes();
    if (nodes.size() < 4) {
      ++(*skipped_)["way with fewer than 4 nodes"];
      return;
    }
    for (const osmium::NodeRef& n : nodes) {
      if (!n.location().valid()) {
        ++(*skipped_)["way with missing nodes"];
        return;
      }
    }
    if (!way.ends_have_same_location()) ++(*skipped_)["way not closed"];
  }

 private:
  std::map<std::string, uint64_t>* skipped_;
};

// A building as read: rings in degrees, the tags that matter.
struct RawPolygon {
  std::vector<osmium::Location> outer;
  std::vector<std::vector<osmium::Location>> holes;
};
struct RawBuilding {
  std::string name;
  bool from_relation = false;
  std::vector<RawPolygon> polygons;
  std::string building, height, building_height, levels, roof_height, roof_levels, min_height,
      min_level;
  uint64_t duplicate_nodes = 0;
};

std::string Tag(const osmium::TagList& tags, const char* key) {
  const char* v = tags.get_value_by_key(key);
  return v == nullptr ? std::string() : std::string(v);
}

std::vector<osmium::Location> RingLocations(const osmium::NodeRefList& ring) {
  std::vector<osmium::Location> out;
  out.reserve(ring.size());
  for (const osmium::NodeRef& n : ring) out.push_back(n.location());
  // Assembled rings are closed (the first node again at the end): keep it open.
  if (out.size() > 1 && out.front() == out.back()) out.pop_back();
  return out;
}

// A count: "3", "3.5", "3;4" (the first), "2.0 "; none if not a non-negative number.
std::optional<double> ParseCount(std::string_view text) {
  const std::optional<double> v = Number(text.substr(0, text.find(';')));
  if (!v || *v < 0.0) return std::nullopt;
  return v;
}

struct Heights {
  double base = 0.0, top = 0.0;
};

Heights BuildingHeights(const RawBuilding& b, double storey, OsmImportSummary* s) {
  Heights h;
  std::optional<double> top;
  for (const std::string* tag : {&b.height, &b.building_height}) {
    if (top || tag->empty()) continue;
    top = ParseLength(*tag);
    if (!top) ++s->bad_height_tags;
  }
  if (top) {
    ++s->height_tagged;
  } else if (!b.levels.empty()) {
    if (const std::optional<double> levels = ParseCount(b.levels)) {
      double roof = kRoofM;
      if (const std::optional<double> r =
              b.roof_height.empty() ? std::nullopt : ParseLength(b.roof_height)) {
        roof = *r;
      } else if (const std::optional<double> rl =
                     b.roof_levels.empty() ? std::nullopt : ParseCount(b.roof_levels)) {
        roof = *rl * storey;
      }
      top = *levels * storey + roof;
      ++s->levels_tagged;
    } else {
      ++s->bad_height_tags;
    }
  }
  if (!top) {
    top = DefaultLevels(b.building) * storey + kRoofM;
    ++s->height_by_rule;
  }
  if (!b.min_height.empty()) {
    if (const std::optional<double> m = ParseLength(b.min_height)) {
      h.base = *m;
    } else {
      ++s->bad_height_tags;
    }
  } else if (!b.min_level.empty()) {
    if (const std::optional<double> m = ParseCount(b.min_level)) {
      h.base = *m * storey;
    } else {
      ++s->bad_height_tags;
    }
  }
  h.top = *top;
  if (!(h.top > h.base + 0.1)) {
    // A base at or above the top: tags that contradict each other; keep one storey.
    ++s->bad_height_tags;
    h.top = h.base + storey;
  }
  h.base = Snap(h.base);
  h.top = Snap(h.top);
  return h;
}

}  // namespace

uint64_t OsmImportSummary::Skipped() const {
  uint64_t n = 0;
  for (const auto& [reason, count] : skipped) n += count;
  return n;
}

absl::StatusOr<GeoBox> ParseGeoBox(std::string_view text) {
  const std::string where = absl::StrCat("bbox '", std::string(text), "'");
  std::vector<std::string_view> parts;
  for (size_t from = 0;;) {
    const size_t comma = text.find(',', from);
    parts.push_back(
        text.substr(from, comma == std::string_view::npos ? std::string_view::npos : comma - from));
    if (comma == std::string_view::npos) break;
    from = comma + 1;
  }
  if (parts.size() != 4) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": needs four numbers min_lon,min_lat,max_lon,max_lat"));
  }
  double v[4];
  for (int i = 0; i < 4; ++i) {
    const std::optional<double> x = Number(parts[i]);
    if (!x) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": '", std::string(parts[i]), "' is not a number"));
    }
    v[i] = *x;
  }
  const GeoBox b{v[0], v[1], v[2], v[3]};
  if (b.min_lon < -180 || b.max_lon > 180 || b.min_lat < -90 || b.max_lat > 90 ||
      b.min_lon >= b.max_lon || b.min_lat >= b.max_lat) {
    return absl::InvalidArgumentError(absl::StrCat(
        where, ": needs -180 <= min_lon < max_lon <= 180 and -90 <= min_lat < max_lat <= 90"));
  }
  return b;
}

int DefaultLevels(std::string_view building) {
  static const std::pair<std::string_view, int> kTable[] = {
      {"garage", 1},
      {"garages", 1},
      {"shed", 1},
      {"hut", 1},
      {"kiosk", 1},
      {"carport", 1},
      {"roof", 1},
      {"service", 1},
      {"toilets", 1},
      {"cabin", 1},
      {"container", 1},
      {"greenhouse", 1},
      {"bunker", 1},
      {"transformer_tower", 2},
      {"house", 2},
      {"detached", 2},
      {"semidetached_house", 2},
      {"terrace", 2},
      {"bungalow", 1},
      {"farm", 2},
      {"barn", 2},
      {"retail", 2},
      {"supermarket", 1},
      {"industrial", 2},
      {"warehouse", 2},
      {"church", 5},
      {"cathedral", 8},
      {"chapel", 3},
      {"apartments", 5},
      {"residential", 4},
      {"hotel", 6},
      {"office", 6},
      {"commercial", 4},
      {"hospital", 5},
      {"school", 3},
      {"university", 4},
      {"public", 3},
      {"civic", 3},
      {"government", 4},
      {"train_station", 3},
      {"stadium", 4},
  };
  for (const auto& [key, levels] : kTable) {
    if (key == building) return levels;
  }
  return 4;  // "yes" and everything else
}

std::optional<double> ParseLength(std::string_view text) {
  std::string t(Strip(text));
  for (char& c : t) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (t.empty()) return std::nullopt;
  // Feet and inches: 12'6" or 12'.
  if (const size_t q = t.find('\''); q != std::string::npos) {
    const std::optional<double> feet = Number(std::string_view(t).substr(0, q));
    if (!feet) return std::nullopt;
    double inches = 0.0;
    std::string_view rest = Strip(std::string_view(t).substr(q + 1));
    if (!rest.empty()) {
      if (rest.back() != '"') return std::nullopt;
      rest.remove_suffix(1);
      const std::optional<double> in = Number(rest);
      if (!in) return std::nullopt;
      inches = *in;
    }
    const double m = *feet * 0.3048 + inches * 0.0254;
    return std::isfinite(m) && m >= 0.0 && *feet >= 0.0 && inches >= 0.0 ? std::optional<double>(m)
                                                                         : std::nullopt;
  }
  // A number and an optional unit.
  size_t end = 0;
  while (end < t.size() &&
         (std::isdigit(static_cast<unsigned char>(t[end])) || t[end] == '.' || t[end] == '+')) {
    ++end;
  }
  const std::optional<double> v = Number(std::string_view(t).substr(0, end));
  if (!v || *v < 0.0) return std::nullopt;
  const std::string_view unit = Strip(std::string_view(t).substr(end));
  double scale;
  if (unit.empty() || unit == "m" || unit == "meter" || unit == "meters" || unit == "metre" ||
      unit == "metres") {
    scale = 1.0;
  } else if (unit == "ft" || unit == "feet" || unit == "foot") {
    scale = 0.3048;
  } else if (unit == "cm") {
    scale = 0.01;
  } else if (unit == "km") {
    scale = 1000.0;
  } else if (unit == "mi") {
    scale = 1609.344;
  } else {
    return std::nullopt;
  }
  return *v * scale;
}

absl::StatusOr<Scene> ImportOsm(const std::string& path, const OsmImportOptions& options,
                                OsmImportSummary* summary, const RunControl& run) {
  const auto start = std::chrono::steady_clock::now();
  OsmImportSummary local_summary;
  OsmImportSummary& s = summary != nullptr ? *summary : local_summary;
  s = OsmImportSummary{};
  std::error_code ec;
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

  // Read: relations first (for their member ways), then everything, assembling areas.
  std::vector<RawBuilding> raw;
  try {
    const osmium::io::File file(path);
    osmium::area::Assembler::config_type config;
    Reasons reasons;
    config.problem_reporter = &reasons;
    config.create_empty_areas = true;  // a failure leaves an empty area: counted below
    osmium::TagsFilter filter{false};
    filter.add_rule(true, osmium::TagMatcher{"building"});
    osmium::area::MultipolygonManager<osmium::area::Assembler> manager{config, filter};
    Progress progress(run, absl::StrCat("reading ", fs::path(path).filename().string()), fs::file_size(path, ec));
    uint64_t read_bytes = 0;
    osmium::relations::read_relations(file, manager);
    using Index = osmium::index::map::FlexMem<osmium::unsigned_object_id_type, osmium::Location>;
    Index index;
    osmium::handler::NodeLocationsForWays<Index> locations{index};
    locations.ignore_errors();  // an extract's ways lose nodes at its edge: counted, skipped
    WayCensus census(&s.skipped);
    auto on_area = [&](const osmium::Area& area) {
      if (!IsBuilding(area.tags())) return;
      const int64_t area_id = area.id();
      const std::string name = absl::StrCat(area.from_way() ? "way/" : "relation/", area.orig_id());
      if (area.num_rings().first == 0) {
        const auto it = reasons.why.find(area_id);
        ++s.skipped[it != reasons.why.end() ? it->second : std::string("not assembled")];
        return;
      }
      RawBuilding b;
      b.name = name;
      b.from_relation = !area.from_way();
      for (const osmium::OuterRing& outer : area.outer_rings()) {
        RawPolygon p;
        p.outer = RingLocations(outer);
        for (const osmium::InnerRing& inner : area.inner_rings(outer))
          p.holes.push_back(RingLocations(inner));
        b.polygons.push_back(std::move(p));
      }
      const osmium::TagList& t = area.tags();
      b.building = Tag(t, "building");
      b.height = Tag(t, "height");
      b.building_height = Tag(t, "building:height");
      b.levels = Tag(t, "building:levels");
      b.roof_height = Tag(t, "roof:height");
      b.roof_levels = Tag(t, "roof:levels");
      b.min_height = Tag(t, "min_height");
      b.min_level = Tag(t, "building:min_level");
      if (const auto it = reasons.duplicate_nodes.find(area_id);
          it != reasons.duplicate_nodes.end()) {
        b.duplicate_nodes = it->second;
      }
      if (options.bbox) {
        const GeoBox& g = *options.bbox;
        for (const RawPolygon& p : b.polygons) {
          for (const osmium::Location& l : p.outer) {
            if (l.lon() < g.min_lon || l.lon() > g.max_lon || l.lat() < g.min_lat ||
                l.lat() > g.max_lat) {
              ++s.skipped["outside the bbox"];
              return;
            }
          }
        }
      }
      raw.push_back(std::move(b));
    };
    struct AreaHandler : osmium::handler::Handler {
      decltype(on_area)* f;
      void area(const osmium::Area& a) { (*f)(a); }
    } area_handler;
    area_handler.f = &on_area;
    osmium::io::Reader reader(file, osmium::osm_entity_bits::node | osmium::osm_entity_bits::way);
    while (osmium::memory::Buffer buffer = reader.read()) {
      if (run.Cancelled()) return absl::CancelledError("OSM import cancelled");
      osmium::apply(buffer, locations, census, manager.handler([&](osmium::memory::Buffer&& areas) {
        osmium::apply(areas, area_handler);
      }));
      progress.SetDetail(absl::StrCat(raw.size(), " buildings"));
      progress.Advance(reader.offset() - read_bytes);
      read_bytes = reader.offset();
    }
    reader.close();
    progress.Finish();
    manager.for_each_incomplete_relation([&](const osmium::relations::RelationHandle&) {
      ++s.skipped["relation with members missing"];
    });
  } catch (const std::exception& e) {
    return absl::DataLossError(
        absl::StrCat(path, ": not readable as OpenStreetMap data (", e.what(), ")"));
  }
  if (raw.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": no buildings (building=*) to import",
                     s.Skipped() > 0 ? absl::StrCat("; ", s.Skipped(), " skipped") : ""));
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
  int zone;
  bool north;
  double ox, oy;
  try {
    GeographicLib::UTMUPS::Forward(clat, clon, zone, north, ox, oy);
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": the data's centre (", clat, ", ", clon,
                                                   ") has no UTM/UPS projection: ", e.what()));
  }
  s.utm_zone = GeographicLib::UTMUPS::EncodeZone(zone, north);
  ox = std::round(ox);
  oy = std::round(oy);
  // None for a ring the centre's zone cannot take (GeographicLib refuses points far outside
  // it) or that lies farther than kMaxOffsetM from the centre, where 1/256 m no longer fits
  // in a float.
  constexpr double kMaxOffsetM = 65536.0;
  auto project = [&](const std::vector<osmium::Location>& ring) -> std::optional<Ring> {
    Ring out;
    out.reserve(ring.size());
    for (const osmium::Location& l : ring) {
      int z;
      bool n;
      double x, y;
      try {
        GeographicLib::UTMUPS::Forward(l.lat(), l.lon(), z, n, x, y, zone);
      } catch (const std::exception&) {
        return std::nullopt;
      }
      x -= ox;
      y -= oy;
      if (!(std::abs(x) < kMaxOffsetM && std::abs(y) < kMaxOffsetM)) return std::nullopt;
      out.emplace_back(Snap(x), Snap(y));
    }
    return out;
  };
  const std::string too_far = "farther than 65 km from the data's centre";

  Scene scene;
  scene.name = !options.name.empty() ? options.name : fs::path(path).filename().string();
  if (options.name.empty()) scene.name = scene.name.substr(0, scene.name.find('.'));
  scene.origin = glm::dvec3(ox, oy, 0.0);
  Progress progress(run, "building meshes", raw.size());
  for (size_t i = 0; i < raw.size(); ++i) {
    if (run.Cancelled()) return absl::CancelledError("OSM import cancelled");
    progress.Advance();
    const RawBuilding& b = raw[i];
    s.repaired_duplicate_points += b.duplicate_nodes;
    Mesh mesh;
    std::vector<Occluder25D> occluders;
    const Heights h = BuildingHeights(b, options.storey_m, &s);
    std::string failure;
    for (const RawPolygon& rp : b.polygons) {
      PolygonWithHoles poly;
      std::optional<Ring> outer = project(rp.outer);
      if (!outer) {
        failure = too_far;
        continue;
      }
      poly.outer = *std::move(outer);
      const RingRepairs fix = CleanRing(&poly.outer);
      s.repaired_duplicate_points += fix.duplicate_points;
      s.repaired_spikes += fix.spikes;
      if (poly.outer.size() < 3) {
        failure = "ring with fewer than 3 points";
        continue;
      }
      if (!IsSimpleRing(poly.outer)) {
        failure = "ring not simple after snapping to 4 mm";
        continue;
      }
      if (SignedArea(poly.outer) < 0.0) std::reverse(poly.outer.begin(), poly.outer.end());
      for (const std::vector<osmium::Location>& rh : rp.holes) {
        std::optional<Ring> projected = project(rh);
        if (!projected) {
          ++s.dropped_inner_rings;
          continue;
        }
        Ring hole = *std::move(projected);
        const RingRepairs hf = CleanRing(&hole);
        s.repaired_duplicate_points += hf.duplicate_points;
        s.repaired_spikes += hf.spikes;
        bool ok = IsSimpleRing(hole) && RingInsideRing(hole, poly.outer);
        for (size_t g = 0; ok && g < poly.holes.size(); ++g) {
          const Ring& other = poly.holes[g];
          ok = !RingInsideRing(hole, other) && !RingInsideRing(other, hole);
          // Touching or crossing holes: Triangulate refuses them; checked there.
        }
        if (!ok) {
          ++s.dropped_inner_rings;
          continue;
        }
        if (SignedArea(hole) > 0.0) std::reverse(hole.begin(), hole.end());
        poly.holes.push_back(std::move(hole));
      }
      absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(poly);
      if (!tris.ok() && !poly.holes.empty()) {
        // Holes that touch each other: keep the building whole, without its courtyards.
        s.dropped_inner_rings += poly.holes.size();
        poly.holes.clear();
        tris = Triangulate(poly);
      }
      if (!tris.ok()) {
        failure = std::string(tris.status().message());
        continue;
      }
      AppendPrism(poly, *tris, h.base, h.top, &mesh);
      ++s.outer_rings;
      s.inner_rings += poly.holes.size();
      if (h.base > 0.0) continue;
      if (poly.holes.empty()) {
        occluders.push_back({poly.outer, h.top, 0});
      } else {
        for (const Triangle2& t : *tris) occluders.push_back({{t[0], t[1], t[2]}, h.top, 0});
      }
    }
    if (mesh.indices.empty()) {
      ++s.skipped[failure.empty() ? std::string("no polygon left") : failure];
      continue;
    }
    const ObjectId id = scene.AddObject(b.name, std::move(mesh));
    for (Occluder25D& o : occluders) {
      o.object = id;
      scene.occluders.push_back(std::move(o));
    }
    s.occluders += occluders.size();
    ++s.buildings;
    ++(b.from_relation ? s.from_relations : s.from_ways);
    if (h.base > 0.0) ++s.raised;
  }
  progress.Finish();
  if (scene.objects.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": no building could be imported; ", s.Skipped(), " skipped"));
  }
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return scene;
}

}  // namespace vistream::scenes
