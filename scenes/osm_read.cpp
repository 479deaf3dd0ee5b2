#include "scenes/osm_read.h"

#include <absl/strings/str_cat.h>

#include <algorithm>
#include <filesystem>
#include <osmium/area/assembler.hpp>
#include <osmium/area/multipolygon_manager.hpp>
#include <osmium/area/problem_reporter.hpp>
#include <osmium/handler.hpp>
#include <osmium/handler/node_locations_for_ways.hpp>
#include <osmium/index/map/flex_mem.hpp>
#include <osmium/io/any_compression.hpp>
#include <osmium/io/pbf_input.hpp>
#include <osmium/io/xml_input.hpp>
#include <osmium/osm/area.hpp>
#include <osmium/relations/manager_util.hpp>
#include <osmium/object_pointer_collection.hpp>
#include <osmium/osm/object_comparisons.hpp>
#include <osmium/visitor.hpp>
#include <unordered_map>

namespace vistream::scenes {

namespace fs = std::filesystem;

namespace {

bool IsYes(const osmium::TagList& tags, const char* key) {
  const char* v = tags.get_value_by_key(key);
  return v != nullptr && std::string_view(v) != "no";
}
bool IsPart(const osmium::TagList& tags) { return IsYes(tags, "building:part"); }
bool IsBuildingOrPart(const osmium::TagList& tags) {
  return IsYes(tags, "building") || IsPart(tags);
}

// Why osmium's assembler gave up on an object, by the id of the area it would have made
// (osmium::object_id_to_area_id: a way's id x 2, a relation's x 2 + 1, negative ids negative).
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
  int64_t AreaId() const { return osmium::object_id_to_area_id(m_object_id, m_object_type); }
  void Note(const char* reason) { why.emplace(AreaId(), reason); }  // the first reason counts
};

// Building ways that osmium's manager passes over in silence, counted by reason.
class WayCensus : public osmium::handler::Handler {
 public:
  explicit WayCensus(std::map<std::string, uint64_t>* skipped) : skipped_(skipped) {}
  void way(const osmium::Way& way) {
    if (!IsBuildingOrPart(way.tags())) return;
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

std::string Tag(const osmium::TagList& tags, const char* key) {
  const char* v = tags.get_value_by_key(key);
  return v == nullptr ? std::string() : std::string(v);
}

bool InBox(const osmium::Location& l, const std::optional<GeoBox>& bbox) {
  return !bbox || (l.lon() >= bbox->min_lon && l.lon() <= bbox->max_lon && l.lat() >= bbox->min_lat &&
                   l.lat() <= bbox->max_lat);
}

// Walkable highway ways, cut into runs of nodes with locations inside the bbox.
class HighwayCollector : public osmium::handler::Handler {
 public:
  HighwayCollector(const std::optional<GeoBox>& bbox, std::vector<RawHighway>* out, OsmImportSummary* s)
      : bbox_(bbox), out_(out), s_(s) {}
  void way(const osmium::Way& way) {
    if (out_ == nullptr) return;
    const osmium::TagList& t = way.tags();
    const char* highway = t.get_value_by_key("highway");
    if (highway == nullptr || !IsWalkableHighway(highway)) return;
    if (IsYes(t, "tunnel") || Tag(t, "indoor") == "yes") return;
    ++s_->highway_ways;
    RawHighway run;
    run.name = absl::StrCat("way/", way.id());
    run.street = Tag(t, "name");
    run.highway = highway;
    auto flush = [&] {
      if (run.nodes.size() >= 2) out_->push_back(run);
      run.nodes.clear();
    };
    for (const osmium::NodeRef& n : way.nodes()) {
      if (!n.location().valid() || !InBox(n.location(), bbox_)) {
        flush();
        continue;
      }
      run.nodes.push_back(n.location());
    }
    flush();
  }

 private:
  const std::optional<GeoBox>& bbox_;
  std::vector<RawHighway>* out_;
  OsmImportSummary* s_;
};

std::vector<osmium::Location> RingLocations(const osmium::NodeRefList& ring) {
  std::vector<osmium::Location> out;
  out.reserve(ring.size());
  for (const osmium::NodeRef& n : ring) out.push_back(n.location());
  // Assembled rings are closed (the first node again at the end): keep it open.
  if (out.size() > 1 && out.front() == out.back()) out.pop_back();
  return out;
}

// A ring's identity whatever its start and direction: the locations from the smallest one on,
// in the direction whose second location is the smaller.
std::vector<osmium::Location> RingKey(const std::vector<osmium::Location>& ring) {
  if (ring.empty()) return {};
  const size_t n = ring.size();
  const size_t first = static_cast<size_t>(std::min_element(ring.begin(), ring.end()) - ring.begin());
  const bool forward = ring[(first + 1) % n] < ring[(first + n - 1) % n];
  std::vector<osmium::Location> key;
  key.reserve(n);
  for (size_t k = 0; k < n; ++k) key.push_back(ring[forward ? (first + k) % n : (first + n - k) % n]);
  return key;
}

struct LocationsHash {
  size_t operator()(const std::vector<osmium::Location>& v) const {
    size_t h = v.size();
    for (const osmium::Location& l : v) {
      h = h * 1000003u ^ static_cast<size_t>(static_cast<uint32_t>(l.x()));
      h = h * 1000003u ^ static_cast<size_t>(static_cast<uint32_t>(l.y()));
    }
    return h;
  }
};

// A closed way tagged building that is also the outer ring of a building relation (the old
// habit of tagging both) would be a second, coincident object: merge it into the relation,
// whose empty height tags it fills.
void MergeWayOutlines(std::vector<RawBuilding>* raw, OsmImportSummary* s) {
  std::unordered_map<std::vector<osmium::Location>, size_t, LocationsHash> relation_rings;
  for (size_t i = 0; i < raw->size(); ++i) {
    const RawBuilding& b = (*raw)[i];
    if (!b.from_relation) continue;
    for (const RawPolygon& p : b.polygons) relation_rings.emplace(RingKey(p.outer), i);
  }
  if (relation_rings.empty()) return;
  std::vector<RawBuilding> kept;
  kept.reserve(raw->size());
  std::vector<std::pair<size_t, size_t>> merges;  // (way in raw, relation in raw)
  for (size_t i = 0; i < raw->size(); ++i) {
    RawBuilding& b = (*raw)[i];
    if (!b.from_relation && b.polygons.size() == 1 && b.polygons[0].holes.empty()) {
      const auto it = relation_rings.find(RingKey(b.polygons[0].outer));
      if (it != relation_rings.end() && (*raw)[it->second].part == b.part) {
        merges.emplace_back(i, it->second);
        continue;
      }
    }
  }
  for (const auto& [way, relation] : merges) {
    HeightTags& to = (*raw)[relation].tags;
    const HeightTags& from = (*raw)[way].tags;
    for (auto field : {&HeightTags::height, &HeightTags::building_height, &HeightTags::levels,
                       &HeightTags::roof_height, &HeightTags::roof_levels,
                       &HeightTags::min_height, &HeightTags::min_level}) {
      if ((to.*field).empty()) to.*field = from.*field;
    }
    (*raw)[way].polygons.clear();  // marks it for removal below
    ++s->merged_way_outlines;
  }
  for (RawBuilding& b : *raw) {
    if (!b.polygons.empty()) kept.push_back(std::move(b));
  }
  *raw = std::move(kept);
}

}  // namespace

namespace {

// A whole file in one buffer, objects in the order libosmium's stream handlers need (nodes,
// ways, relations, each by id): files from editors may have their ids in any order.
osmium::memory::Buffer SortedCopy(const osmium::io::File& file) {
  osmium::io::Reader reader(file);
  std::vector<osmium::memory::Buffer> buffers;
  osmium::ObjectPointerCollection objects;
  while (osmium::memory::Buffer buffer = reader.read()) {
    osmium::apply(buffer, objects);
    buffers.push_back(std::move(buffer));
  }
  reader.close();
  objects.sort(osmium::object_order_type_id_version());
  osmium::memory::Buffer out(1024 * 1024, osmium::memory::Buffer::auto_grow::yes);
  for (const osmium::OSMObject& o : objects) {
    out.add_item(o);
    out.commit();
  }
  return out;
}

// One pass over the input: `sorted` holds the whole file when its ids were out of order,
// else the file is streamed twice (relations, then everything).
absl::Status ReadPass(const std::string& path, const osmium::memory::Buffer* sorted,
                      const std::optional<GeoBox>& bbox, std::vector<RawBuilding>* out,
                      OsmImportSummary* summary, const RunControl& run, std::vector<RawHighway>* highways) {
  OsmImportSummary& s = *summary;
  std::vector<RawBuilding>& raw = *out;
  const osmium::io::File file(path);
  osmium::area::Assembler::config_type config;
  Reasons reasons;
  config.problem_reporter = &reasons;
  config.create_empty_areas = true;  // a failure leaves an empty area: counted below
  osmium::TagsFilter filter{false};
  filter.add_rule(true, osmium::TagMatcher{"building"});
  filter.add_rule(true, osmium::TagMatcher{"building:part"});
  osmium::area::MultipolygonManager<osmium::area::Assembler> manager{config, filter};
  std::error_code ec;
  Progress progress(run, absl::StrCat("reading ", fs::path(path).filename().string()),
                    fs::file_size(path, ec));
  if (sorted != nullptr) {
    for (const osmium::Relation& r : sorted->select<osmium::Relation>()) manager.relation(r);
    manager.prepare_for_lookup();
  } else {
    osmium::relations::read_relations(file, manager);
  }
  // Editors save objects not yet uploaded with negative ids: a second index keeps theirs.
  using Index = osmium::index::map::FlexMem<osmium::unsigned_object_id_type, osmium::Location>;
  Index positive, negative;
  osmium::handler::NodeLocationsForWays<Index, Index> locations{positive, negative};
  locations.ignore_errors();  // an extract's ways lose nodes at its edge: counted, skipped
  WayCensus census(&s.skipped);
  HighwayCollector roads(bbox, highways, &s);
  auto on_area = [&](const osmium::Area& area) {
    const osmium::TagList& t = area.tags();
    if (!IsBuildingOrPart(t)) return;
    const int64_t area_id = area.id();
    if (area.num_rings().first == 0) {
      const auto it = reasons.why.find(area_id);
      ++s.skipped[it != reasons.why.end() ? it->second : std::string("not assembled")];
      return;
    }
    RawBuilding b;
    b.name = absl::StrCat(area.from_way() ? "way/" : "relation/", area.orig_id());
    b.from_relation = !area.from_way();
    b.part = IsPart(t);
    for (const osmium::OuterRing& outer : area.outer_rings()) {
      RawPolygon p;
      p.outer = RingLocations(outer);
      for (const osmium::InnerRing& inner : area.inner_rings(outer))
        p.holes.push_back(RingLocations(inner));
      b.polygons.push_back(std::move(p));
    }
    // A part's own type names its rule ("building:part=roof"), a building's its tag.
    b.tags.building = Tag(t, b.part ? "building:part" : "building");
    b.tags.height = Tag(t, "height");
    b.tags.building_height = Tag(t, "building:height");
    b.tags.levels = Tag(t, "building:levels");
    b.tags.roof_height = Tag(t, "roof:height");
    b.tags.roof_levels = Tag(t, "roof:levels");
    b.tags.min_height = Tag(t, "min_height");
    b.tags.min_level = Tag(t, "building:min_level");
    if (const auto it = reasons.duplicate_nodes.find(area_id);
        it != reasons.duplicate_nodes.end()) {
      b.duplicate_nodes = it->second;
    }
    if (bbox) {
      for (const RawPolygon& p : b.polygons) {
        for (const osmium::Location& l : p.outer) {
          if (l.lon() < bbox->min_lon || l.lon() > bbox->max_lon || l.lat() < bbox->min_lat ||
              l.lat() > bbox->max_lat) {
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
  auto apply = [&](osmium::memory::Buffer& buffer) {
    osmium::apply(buffer, locations, census, roads, manager.handler([&](osmium::memory::Buffer&& areas) {
      osmium::apply(areas, area_handler);
    }));
  };
  if (sorted != nullptr) {
    // The sorted copy is read-only here; the handlers take const objects.
    apply(const_cast<osmium::memory::Buffer&>(*sorted));
  } else {
    osmium::io::Reader reader(file, osmium::osm_entity_bits::node | osmium::osm_entity_bits::way);
    uint64_t read_bytes = 0;
    while (osmium::memory::Buffer buffer = reader.read()) {
      if (run.Cancelled()) return absl::CancelledError("OSM import cancelled");
      apply(buffer);
      progress.SetDetail(absl::StrCat(raw.size(), " buildings"));
      progress.Advance(reader.offset() - read_bytes);
      read_bytes = reader.offset();
    }
    reader.close();
  }
  progress.Finish();
  manager.for_each_incomplete_relation([&](const osmium::relations::RelationHandle&) {
    ++s.skipped["relation with members missing"];
  });
  return absl::OkStatus();
}

}  // namespace

bool IsWalkableHighway(std::string_view value) {
  static constexpr std::string_view kWalkable[] = {
      "footway",   "path",        "pedestrian",   "steps",          "living_street", "residential",
      "service",   "unclassified", "road",        "track",          "cycleway",      "bridleway",
      "tertiary",  "tertiary_link", "secondary",  "secondary_link", "primary",       "primary_link",
      "trunk",     "trunk_link"};
  return std::find(std::begin(kWalkable), std::end(kWalkable), value) != std::end(kWalkable);
}

absl::Status ReadOsmBuildings(const std::string& path, const std::optional<GeoBox>& bbox,
                              std::vector<RawBuilding>* out, OsmImportSummary* summary,
                              const RunControl& run, std::vector<RawHighway>* highways) {
  try {
    absl::Status status;
    try {
      status = ReadPass(path, nullptr, bbox, out, summary, run, highways);
    } catch (const osmium::out_of_order_error&) {
      // Ids out of order (as editors save them): start again from a sorted copy in memory.
      out->clear();
      summary->skipped.clear();
      summary->highway_ways = 0;
      if (highways != nullptr) highways->clear();
      const osmium::memory::Buffer sorted = SortedCopy(osmium::io::File(path));
      status = ReadPass(path, &sorted, bbox, out, summary, run, highways);
    }
    if (!status.ok()) return status;
  } catch (const std::exception& e) {
    return absl::DataLossError(
        absl::StrCat(path, ": not readable as OpenStreetMap data (", e.what(), ")"));
  }
  MergeWayOutlines(out, summary);
  return absl::OkStatus();
}

}  // namespace vistream::scenes
