#include "tests/osm_test_util.h"

#include <GeographicLib/UTMUPS.hpp>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <glm/geometric.hpp>
#include <map>
#include <tuple>

namespace vistream::scenes::testing_osm {

std::string WriteMetricOsm(const std::string& path, glm::dvec2 centre, const std::vector<MetricWay>& ways,
                           const std::vector<MetricRelation>& relations, bool negative_ids,
                           bool shuffle) {
  int zone;
  bool north;
  double cx, cy;
  GeographicLib::UTMUPS::Forward(centre.x, centre.y, zone, north, cx, cy);
  std::map<std::pair<double, double>, long long> ids;
  std::vector<std::string> nodes, elements;
  auto node = [&](const glm::dvec2& m) {
    const auto [it, fresh] = ids.emplace(std::make_pair(m.x, m.y), 0);
    if (!fresh) return it->second;
    const long long n = static_cast<long long>(ids.size());
    it->second = negative_ids ? -n : n;
    double lat, lon;
    GeographicLib::UTMUPS::Reverse(zone, north, cx + m.x, cy + m.y, lat, lon);
    char buf[160];
    std::snprintf(buf, sizeof buf, " <node id=\"%lld\" lat=\"%.10f\" lon=\"%.10f\"/>", it->second,
                  lat, lon);
    nodes.emplace_back(buf);
    return it->second;
  };
  auto tags = [](const std::vector<std::pair<std::string, std::string>>& t) {
    std::string out;
    for (const auto& [k, v] : t) out += "<tag k=\"" + k + "\" v=\"" + v + "\"/>";
    return out;
  };
  for (const MetricWay& w : ways) {
    std::string e = " <way id=\"" + std::to_string(w.id) + "\">";
    std::vector<long long> refs;
    for (const glm::dvec2& p : w.ring) refs.push_back(node(p));
    if (!refs.empty()) refs.push_back(refs.front());
    for (long long r : refs) e += "<nd ref=\"" + std::to_string(r) + "\"/>";
    elements.push_back(e + tags(w.tags) + "</way>");
  }
  for (const MetricRelation& r : relations) {
    std::string e = " <relation id=\"" + std::to_string(r.id) + "\">";
    for (const auto& [ref, role] : r.members)
      e += "<member type=\"way\" ref=\"" + std::to_string(ref) + "\" role=\"" + role + "\"/>";
    elements.push_back(e + tags(r.tags) + "</relation>");
  }
  std::vector<std::string> all = nodes;
  all.insert(all.end(), elements.begin(), elements.end());
  if (shuffle) std::reverse(all.begin(), all.end());
  std::ofstream out(path);
  out << "<?xml version='1.0' encoding='UTF-8'?>\n<osm version='0.6' generator='vistream test'>\n";
  for (const std::string& line : all) out << line << "\n";
  out << "</osm>\n";
  return path;
}

double Shoelace(const std::vector<glm::dvec2>& ring) {
  double a = 0.0;
  for (size_t i = 0; i < ring.size(); ++i) {
    const glm::dvec2 p = ring[i], q = ring[(i + 1) % ring.size()];
    a += p.x * q.y - q.x * p.y;
  }
  return 0.5 * a;
}

double RoofArea(const Mesh& m, float z) {
  double area = 0.0;
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
    const glm::dvec3 a(m.positions[m.indices[t]]), b(m.positions[m.indices[t + 1]]),
        c(m.positions[m.indices[t + 2]]);
    if (a.z != z || b.z != z || c.z != z) continue;
    area += 0.5 * glm::cross(b - a, c - a).z;
  }
  return area;
}

std::vector<glm::dvec2> Rect(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

bool Closed(const Mesh& m) {
  using P = std::tuple<float, float, float>;
  std::map<std::pair<P, P>, int> edges;
  auto key = [&](uint32_t i) { return P{m.positions[i].x, m.positions[i].y, m.positions[i].z}; };
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
    for (int k = 0; k < 3; ++k) {
      const P a = key(m.indices[t + k]), b = key(m.indices[t + (k + 1) % 3]);
      ++edges[{a, b}];
      --edges[{b, a}];
    }
  }
  return std::all_of(edges.begin(), edges.end(), [](const auto& e) { return e.second == 0; });
}

const Object* ByName(const Scene& s, const std::string& name) {
  for (const Object& o : s.objects) {
    if (o.name == name) return &o;
  }
  return nullptr;
}

size_t OccluderCount(const Scene& s, ObjectId id) {
  return static_cast<size_t>(std::count_if(s.occluders.begin(), s.occluders.end(),
                                           [&](const Occluder25D& o) { return o.object == id; }));
}

double OccluderArea(const Scene& s, ObjectId id) {
  double a = 0.0;
  for (const Occluder25D& o : s.occluders) {
    if (o.object == id) a += Shoelace(o.footprint);
  }
  return a;
}

}  // namespace vistream::scenes::testing_osm
