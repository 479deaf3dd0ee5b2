// CityGML 1.0 and 2.0 into a CityModel (scenes/city_model.h) through libcitygml.
//
// libcitygml keeps polygons and their rings but forgets what the GML geometry element was: a
// gml:Solid, a gml:MultiSurface and a gml:CompositeSurface all become a citygml::Geometry,
// known only by its gml:id. So the bytes go through expat first (a pre-scan), which
//   - checks that the document is well-formed XML whose root is a CityGML 1.0 or 2.0
//     CityModel, with no DOCTYPE (xerces, under libcitygml, would fetch external DTDs) and
//     nesting no deeper than kMaxDepth (libcitygml and this file recurse over the tree);
//   - names the format from the root's namespace and the CRS from the first gml:Envelope's
//     srsName (else the first srsName anywhere);
//   - records the element name of every geometry by its gml:id, and gives the geometries and
//     city objects that have no gml:id one ("vistream-L<line>C<column>", inserted into the
//     bytes libcitygml reads), so that every geometry can be looked up and every object named;
//   - checks every coordinate list (gml:pos, gml:posList, gml:coordinates) for numbers that
//     are not finite (libcitygml's stream parsing silently stops at "NaN"), charging them to
//     the innermost city object that is not a semantic surface.
// Then libcitygml loads the rewritten bytes (no tesselation, no reprojection, no
// optimisation: rings as written), and its tree is mapped to CityObjects.

#include <absl/strings/ascii.h>
#include <absl/strings/match.h>
#include <absl/strings/str_cat.h>
#include <expat.h>

#include <citygml/citygml.h>
#include <citygml/citygmllogger.h>
#include <citygml/citymodel.h>
#include <citygml/cityobject.h>
#include <citygml/geometry.h>
#include <citygml/implictgeometry.h>
#include <citygml/linearring.h>
#include <citygml/polygon.h>
#include <citygml/transformmatrix.h>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <mutex>
#include <sstream>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "scenes/city_model.h"

namespace vistream::scenes {

namespace {

// Deeper documents are refused: no CityGML file nests anywhere near this, and libcitygml
// recurses over its tree (destructors too).
constexpr int kMaxDepth = 256;

std::string_view LocalName(std::string_view qname) {
  const size_t colon = qname.rfind(':');
  return colon == std::string_view::npos ? qname : qname.substr(colon + 1);
}

// GML geometry elements libcitygml makes a citygml::Geometry of.
enum class GmlKind {
  kSolid, kMultiSolid, kCompositeSolid, kMultiSurface, kCompositeSurface, kTriangulatedSurface,
  kOtherSurface, kCurve,
};

const std::unordered_map<std::string_view, GmlKind>& GeometryElements() {
  static const auto* const kElements = new std::unordered_map<std::string_view, GmlKind>{
      {"Solid", GmlKind::kSolid},
      {"MultiSolid", GmlKind::kMultiSolid},
      {"CompositeSolid", GmlKind::kCompositeSolid},
      {"MultiSurface", GmlKind::kMultiSurface},
      {"CompositeSurface", GmlKind::kCompositeSurface},
      {"Shell", GmlKind::kCompositeSurface},
      {"TriangulatedSurface", GmlKind::kTriangulatedSurface},
      {"Tin", GmlKind::kTriangulatedSurface},
      {"PolyhedralSurface", GmlKind::kOtherSurface},
      {"Surface", GmlKind::kOtherSurface},
      {"OrientableSurface", GmlKind::kOtherSurface},
      {"MultiCurve", GmlKind::kCurve},
      {"MultiPoint", GmlKind::kCurve},
  };
  return *kElements;
}

// City objects libcitygml knows, by element name, and whether they are semantic surfaces (or
// openings, traffic areas, water boundaries) whose polygons belong to the nearest city object
// above them that is not one.
const std::unordered_map<std::string_view, bool>& CityObjectElements() {
  static const auto* const kElements = new std::unordered_map<std::string_view, bool>{
      {"GenericCityObject", false}, {"Building", false}, {"BuildingPart", false},
      {"Room", false}, {"BuildingInstallation", false}, {"IntBuildingInstallation", false},
      {"BuildingFurniture", false}, {"CityFurniture", false}, {"Track", false},
      {"Road", false}, {"Railway", false}, {"Square", false},
      {"TransportationComplex", false}, {"PlantCover", false},
      {"SolitaryVegetationObject", false}, {"WaterBody", false}, {"LandUse", false},
      {"Tunnel", false}, {"Bridge", false}, {"BridgeConstructionElement", false},
      {"BridgeInstallation", false}, {"BridgePart", false}, {"CityObjectGroup", false},
      {"ReliefFeature", false}, {"TINRelief", false}, {"MassPointRelief", false},
      {"BreaklineRelief", false}, {"RasterRelief", false},
      {"WallSurface", true}, {"RoofSurface", true}, {"GroundSurface", true},
      {"ClosureSurface", true}, {"FloorSurface", true}, {"InteriorWallSurface", true},
      {"CeilingSurface", true}, {"OuterCeilingSurface", true}, {"OuterFloorSurface", true},
      {"Door", true}, {"Window", true}, {"TrafficArea", true}, {"AuxiliaryTrafficArea", true},
      {"WaterSurface", true}, {"WaterGroundSurface", true}, {"WaterClosureSurface", true},
  };
  return *kElements;
}

// "EPSG:<code>" for the EPSG forms srsName takes ("EPSG:28992", "urn:ogc:def:crs:EPSG::28992",
// "urn:ogc:def:crs:EPSG:6.6:28992", "http://www.opengis.net/def/crs/EPSG/0/28992"); a compound
// ("urn:ogc:def:crs,crs:EPSG::28992,crs:EPSG::5109") as "EPSG:28992+5109"; other text as is.
std::string NormaliseCrs(std::string_view srs) {
  const std::string upper = absl::AsciiStrToUpper(std::string(srs));
  std::vector<std::string> codes;
  size_t at = upper.find("EPSG");
  while (at != std::string::npos) {
    const size_t next = upper.find("EPSG", at + 4);
    size_t end = std::min(next, upper.find(',', at));
    if (end == std::string::npos) end = upper.size();
    std::string_view segment = std::string_view(upper).substr(at + 4, end - at - 4);
    while (!segment.empty() && !absl::ascii_isdigit(static_cast<unsigned char>(segment.back()))) {
      segment.remove_suffix(1);
    }
    size_t digits = segment.size();
    while (digits > 0 && absl::ascii_isdigit(static_cast<unsigned char>(segment[digits - 1]))) --digits;
    if (digits < segment.size()) codes.emplace_back(segment.substr(digits));
    at = next;
  }
  if (codes.empty()) return std::string(srs);
  std::string out = "EPSG:" + codes[0];
  for (size_t i = 1; i < codes.size(); ++i) absl::StrAppend(&out, "+", codes[i]);
  return out;
}

// What expat found before libcitygml reads the bytes.
struct Prescan {
  std::string error;          // set: the document is refused with this message
  std::string format;         // "CityGML 1.0" or "CityGML 2.0"
  std::string envelope_srs, any_srs;
  std::unordered_map<std::string, GmlKind> kinds;          // geometry gml:id -> element
  std::vector<std::pair<size_t, std::string>> insertions;  // byte offset, text (ids)
  std::unordered_map<std::string, std::string> malformed;  // city object id -> first problem
};

class PrescanParser {
 public:
  PrescanParser(std::string_view bytes, Prescan* out) : bytes_(bytes), out_(out) {}

  void Run() {
    XML_Parser parser = XML_ParserCreate(nullptr);
    if (parser == nullptr) {
      out_->error = "out of memory";
      return;
    }
    parser_ = parser;
    XML_SetUserData(parser, this);
    XML_SetElementHandler(parser, &PrescanParser::Start, &PrescanParser::End);
    XML_SetCharacterDataHandler(parser, &PrescanParser::Text);
    XML_SetStartDoctypeDeclHandler(parser, &PrescanParser::Doctype);
    // Parsed in pieces: one XML_Parse over a buffer past INT_MAX bytes would overflow.
    constexpr size_t kChunk = size_t{1} << 24;
    size_t done = 0;
    bool ok = true;
    do {
      const size_t n = std::min(kChunk, bytes_.size() - done);
      const bool last = done + n == bytes_.size();
      ok = XML_Parse(parser, bytes_.data() + done, static_cast<int>(n), last) == XML_STATUS_OK;
      done += n;
      if (!ok || last) break;
    } while (true);
    if (!ok && out_->error.empty()) {
      out_->error = absl::StrCat("not well-formed XML: ", XML_ErrorString(XML_GetErrorCode(parser)),
                                 " at line ", XML_GetCurrentLineNumber(parser), ", column ",
                                 XML_GetCurrentColumnNumber(parser) + 1);
    }
    XML_ParserFree(parser);
    if (out_->error.empty() && !saw_root_) out_->error = "no XML element";
  }

 private:
  struct Element {
    std::string id;
    bool city_object = false;
    bool semantic = false;
  };

  void Fail(std::string message) {
    if (out_->error.empty()) out_->error = std::move(message);
    XML_StopParser(parser_, XML_FALSE);
  }

  std::string Where() const {
    return absl::StrCat("line ", XML_GetCurrentLineNumber(parser_));
  }

  static void Doctype(void* self, const XML_Char*, const XML_Char*, const XML_Char*, int) {
    auto* p = static_cast<PrescanParser*>(self);
    p->Fail(absl::StrCat("a DOCTYPE declaration at ", p->Where(), " (CityGML has none; refused)"));
  }

  static void Start(void* self, const XML_Char* name, const XML_Char** atts) {
    static_cast<PrescanParser*>(self)->OnStart(name, atts);
  }
  static void End(void* self, const XML_Char*) { static_cast<PrescanParser*>(self)->OnEnd(); }
  static void Text(void* self, const XML_Char* s, int len) {
    auto* p = static_cast<PrescanParser*>(self);
    if (p->collecting_) p->text_.append(s, static_cast<size_t>(len));
  }

  static const char* Attribute(const XML_Char** atts, std::string_view key) {
    for (int i = 0; atts[i] != nullptr && atts[i + 1] != nullptr; i += 2) {
      if (key == atts[i]) return atts[i + 1];
    }
    return nullptr;
  }

  void OnRoot(std::string_view qname, const XML_Char** atts) {
    saw_root_ = true;
    if (LocalName(qname) != "CityModel") {
      Fail(absl::StrCat("not CityGML: the root element is <", std::string(qname), ">, not a CityModel"));
      return;
    }
    const size_t colon = qname.rfind(':');
    const std::string xmlns =
        colon == std::string_view::npos ? "xmlns" : absl::StrCat("xmlns:", std::string(qname.substr(0, colon)));
    const char* ns = Attribute(atts, xmlns);
    const std::string_view uri = ns == nullptr ? "" : ns;
    if (uri == "http://www.opengis.net/citygml/1.0") {
      out_->format = "CityGML 1.0";
    } else if (uri == "http://www.opengis.net/citygml/2.0") {
      out_->format = "CityGML 2.0";
    } else {
      Fail(absl::StrCat("not CityGML 1.0 or 2.0: the root CityModel's namespace is '", std::string(uri), "'"));
    }
  }

  void OnStart(const XML_Char* name, const XML_Char** atts) {
    const std::string_view qname = name;
    if (++depth_ > kMaxDepth) {
      Fail(absl::StrCat("elements nested deeper than ", kMaxDepth, " at ", Where()));
      return;
    }
    if (depth_ == 1) {
      OnRoot(qname, atts);
      if (!out_->error.empty()) return;
    }
    const std::string_view local = LocalName(qname);
    if (const char* srs = Attribute(atts, "srsName"); srs != nullptr) {
      if (local == "Envelope" && out_->envelope_srs.empty()) out_->envelope_srs = srs;
      if (out_->any_srs.empty()) out_->any_srs = srs;
    }
    Element element;
    const auto geometry = GeometryElements().find(local);
    const auto city_object = CityObjectElements().find(local);
    const bool named = geometry != GeometryElements().end() || city_object != CityObjectElements().end();
    if (const char* id = Attribute(atts, "gml:id"); id != nullptr && *id != '\0') {
      element.id = id;
    } else if (named) {
      // libcitygml reads the attribute by this qualified name (it parses without namespaces).
      element.id = absl::StrCat("vistream-L", XML_GetCurrentLineNumber(parser_), "C",
                                XML_GetCurrentColumnNumber(parser_) + 1);
      const auto index = static_cast<size_t>(XML_GetCurrentByteIndex(parser_));
      const size_t at = index + 1 + qname.size();
      // Only where the bytes are the name as expat reports it (UTF-8 or ASCII text).
      if (index < bytes_.size() && bytes_[index] == '<' && at <= bytes_.size() &&
          bytes_.substr(index + 1, qname.size()) == qname) {
        out_->insertions.emplace_back(at, absl::StrCat(" gml:id=\"", element.id, "\""));
      }
    }
    if (geometry != GeometryElements().end()) out_->kinds[element.id] = geometry->second;
    if (city_object != CityObjectElements().end()) {
      element.city_object = true;
      element.semantic = city_object->second;
    }
    stack_.push_back(std::move(element));
    if (local == "pos" || local == "posList" || local == "coordinates") {
      collecting_ = true;
      text_.clear();
      text_line_ = XML_GetCurrentLineNumber(parser_);
      commas_ = local == "coordinates";
    }
  }

  void OnEnd() {
    if (collecting_) {
      collecting_ = false;
      CheckCoordinates();
    }
    if (!stack_.empty()) stack_.pop_back();
    --depth_;
  }

  void CheckCoordinates() {
    std::string_view t = text_;
    while (!t.empty()) {
      size_t start = 0;
      auto separator = [&](char c) {
        return absl::ascii_isspace(static_cast<unsigned char>(c)) || (commas_ && c == ',');
      };
      while (start < t.size() && separator(t[start])) ++start;
      size_t end = start;
      while (end < t.size() && !separator(t[end])) ++end;
      if (start == end) break;
      std::string_view token = t.substr(start, end - start);
      t.remove_prefix(end);
      if (!token.empty() && token.front() == '+') token.remove_prefix(1);
      double v = 0.0;
      const auto [ptr, err] = std::from_chars(token.data(), token.data() + token.size(), v);
      if (err != std::errc() || ptr != token.data() + token.size() || !std::isfinite(v)) {
        Charge(absl::StrCat("coordinate '", std::string(token.substr(0, 32)), "' (not a finite number) at line ",
                            text_line_));
        return;
      }
    }
  }

  // The problem goes to the innermost city object that is not a semantic surface.
  void Charge(std::string problem) {
    for (auto it = stack_.rbegin(); it != stack_.rend(); ++it) {
      if (it->city_object && !it->semantic) {
        out_->malformed.try_emplace(it->id, std::move(problem));
        return;
      }
    }
    out_->malformed.try_emplace("", std::move(problem));
  }

  std::string_view bytes_;
  Prescan* out_;
  XML_Parser parser_ = nullptr;
  int depth_ = 0;
  bool saw_root_ = false;
  std::vector<Element> stack_;
  bool collecting_ = false, commas_ = false;
  uint64_t text_line_ = 0;
  std::string text_;
};

std::string WithInsertions(std::string_view bytes, std::vector<std::pair<size_t, std::string>> insertions) {
  std::sort(insertions.begin(), insertions.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  std::string out;
  size_t extra = 0;
  for (const auto& [at, text] : insertions) extra += text.size();
  out.reserve(bytes.size() + extra);
  size_t done = 0;
  for (const auto& [at, text] : insertions) {
    out.append(bytes.substr(done, at - done));
    out.append(text);
    done = at;
  }
  out.append(bytes.substr(done));
  return out;
}

// libcitygml's messages, kept instead of printed. Called from the loading thread only, but
// its interface is const and documented as callable from several threads. libcitygml's base
// class has no virtual destructor; this one is final and owned as itself (make_shared), so
// -Wnon-virtual-dtor's worry does not apply.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnon-virtual-dtor"
class CollectingLogger final : public citygml::CityGMLLogger {
 public:
  CollectingLogger() : CityGMLLogger(LOGLEVEL::LL_WARNING) {}
  void log(LOGLEVEL level, const std::string& message, const char*, int) const override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (level == LOGLEVEL::LL_ERROR) {
      ++error_count_;
      if (errors_.size() < 8) errors_.push_back(message);
    } else if (level == LOGLEVEL::LL_WARNING) {
      ++warnings_;
    }
  }
  uint64_t ErrorCount() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return error_count_;
  }
  std::vector<std::string> Errors() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return errors_;
  }

 private:
  mutable std::mutex mutex_;
  mutable std::vector<std::string> errors_;
  mutable uint64_t warnings_ = 0, error_count_ = 0;
};
#pragma GCC diagnostic pop

using CityType = citygml::CityObject::CityObjectsType;

// How a libcitygml object goes into the model.
enum class Role { kObject, kSemantic, kTransparent, kUnsupported };

struct TypeInfo {
  Role role;
  const char* name;  // CityJSON type name for kObject
};

TypeInfo Classify(CityType type, CityType parent_type, bool has_parent) {
  switch (type) {
    case CityType::COT_GenericCityObject: return {Role::kObject, "GenericCityObject"};
    case CityType::COT_Building: return {Role::kObject, "Building"};
    case CityType::COT_BuildingPart: return {Role::kObject, "BuildingPart"};
    case CityType::COT_Room: return {Role::kObject, "BuildingRoom"};
    case CityType::COT_BuildingInstallation:
    case CityType::COT_IntBuildingInstallation: return {Role::kObject, "BuildingInstallation"};
    case CityType::COT_BuildingFurniture: return {Role::kObject, "BuildingFurniture"};
    case CityType::COT_CityFurniture: return {Role::kObject, "CityFurniture"};
    case CityType::COT_Track: return {Role::kObject, "Track"};
    case CityType::COT_Road: return {Role::kObject, "Road"};
    case CityType::COT_Railway: return {Role::kObject, "Railway"};
    case CityType::COT_Square: return {Role::kObject, "TransportSquare"};
    case CityType::COT_PlantCover: return {Role::kObject, "PlantCover"};
    case CityType::COT_SolitaryVegetationObject: return {Role::kObject, "SolitaryVegetationObject"};
    case CityType::COT_LandUse: return {Role::kObject, "LandUse"};
    case CityType::COT_Tunnel: return {Role::kObject, "Tunnel"};
    case CityType::COT_Bridge: return {Role::kObject, "Bridge"};
    case CityType::COT_BridgePart: return {Role::kObject, "BridgePart"};
    case CityType::COT_BridgeInstallation: return {Role::kObject, "BridgeInstallation"};
    case CityType::COT_BridgeConstructionElement: return {Role::kObject, "BridgeConstructiveElement"};
    case CityType::COT_CityObjectGroup: return {Role::kObject, "CityObjectGroup"};
    case CityType::COT_TINRelief: return {Role::kObject, "TINRelief"};
    case CityType::COT_ReliefFeature: return {Role::kTransparent, ""};
    // libcitygml gives wtr:WaterSurface, WaterGroundSurface, WaterClosureSurface the water
    // body's type, and tran:TrafficArea, AuxiliaryTrafficArea the transportation complex's.
    case CityType::COT_WaterBody:
      if (has_parent && parent_type == CityType::COT_WaterBody) return {Role::kSemantic, ""};
      return {Role::kObject, "WaterBody"};
    case CityType::COT_TransportationObject:
      if (has_parent) return {Role::kSemantic, ""};
      return {Role::kObject, "TransportationComplex"};
    case CityType::COT_WallSurface:
    case CityType::COT_RoofSurface:
    case CityType::COT_GroundSurface:
    case CityType::COT_ClosureSurface:
    case CityType::COT_FloorSurface:
    case CityType::COT_InteriorWallSurface:
    case CityType::COT_CeilingSurface:
    case CityType::COT_OuterCeilingSurface:
    case CityType::COT_OuterFloorSurface:
    case CityType::COT_Door:
    case CityType::COT_Window: return {Role::kSemantic, ""};
    default: return {Role::kUnsupported, ""};
  }
}

// Places template coordinates: world = M (row-major 4x4, as GML writes it) * v + reference.
struct Placement {
  const double* m = nullptr;  // null: identity and no reference point
  glm::dvec3 reference{0.0};

  glm::dvec3 operator()(const TVec3d& v) const {
    if (m == nullptr) return {v.x, v.y, v.z};
    return {m[0] * v.x + m[1] * v.y + m[2] * v.z + m[3] + reference.x,
            m[4] * v.x + m[5] * v.y + m[6] * v.z + m[7] + reference.y,
            m[8] * v.x + m[9] * v.y + m[10] * v.z + m[11] + reference.z};
  }
};

class Converter {
 public:
  Converter(const std::string& name, const CityReadOptions& options, const Prescan& prescan, CityModel* model)
      : name_(name), options_(options), prescan_(prescan), model_(model) {}

  absl::Status Object(const citygml::CityObject& o, const citygml::CityObject* parent_object,
                      const std::string& parent_id) {
    const TypeInfo info = Classify(o.getType(), parent_object != nullptr ? parent_object->getType() : CityType::COT_All,
                                   parent_object != nullptr);
    if (info.role == Role::kTransparent) {
      for (unsigned i = 0; i < o.getChildCityObjectsCount(); ++i) {
        if (auto s = Object(o.getChildCityObject(i), &o, parent_id); !s.ok()) return s;
      }
      return absl::OkStatus();
    }
    if (info.role == Role::kUnsupported) {
      model_->skipped[absl::StrCat("city object of type ", o.getTypeAsString())]++;
      return absl::OkStatus();
    }
    if (info.role == Role::kSemantic) {
      // A semantic surface with no object above it to belong to.
      model_->skipped["semantic surface outside a city object"]++;
      return absl::OkStatus();
    }
    CityObject out;
    out.id = o.getId();
    out.type = info.name;
    out.parent = parent_id;
    problem_.clear();
    if (auto it = prescan_.malformed.find(out.id); it != prescan_.malformed.end()) problem_ = it->second;

    std::unordered_set<const citygml::Polygon*> seen;
    std::unordered_set<std::string> seen_rings;
    for (unsigned i = 0; i < o.getGeometriesCount() && problem_.empty(); ++i) {
      AddGeometry(o.getGeometry(i), info, Placement{}, &out, &seen, &seen_rings);
    }
    for (unsigned i = 0; i < o.getImplicitGeometryCount() && problem_.empty(); ++i) {
      const citygml::ImplicitGeometry& g = o.getImplicitGeometry(i);
      Placement place;
      place.m = g.getTransformMatrix().getMatrix();
      const TVec3d r = g.getReferencePoint();
      place.reference = {r.x, r.y, r.z};
      for (unsigned k = 0; k < g.getGeometriesCount() && problem_.empty(); ++k) {
        AddGeometry(g.getGeometry(k), info, place, &out, &seen, &seen_rings);
      }
    }
    // Semantic surfaces: polygons not already in the object's own geometry, by LoD.
    std::map<unsigned, CityGeometry> boundary;
    for (unsigned i = 0; i < o.getChildCityObjectsCount() && problem_.empty(); ++i) {
      const citygml::CityObject& child = o.getChildCityObject(i);
      if (Classify(child.getType(), o.getType(), true).role == Role::kSemantic) {
        Fold(child, &boundary, seen, seen_rings);
      }
    }
    for (auto& [lod, g] : boundary) out.geometries.push_back(std::move(g));

    if (problem_.empty()) problem_ = Check(out);
    bool keep = true;
    if (!problem_.empty()) {
      if (!options_.keep_going) {
        return absl::InvalidArgumentError(absl::StrCat(name_, ": city object '", out.id, "': malformed geometry: ", problem_));
      }
      model_->skipped["malformed geometry"]++;
      keep = false;
    }
    if (keep && !ids_.insert(out.id).second) {
      if (!options_.keep_going) {
        return absl::InvalidArgumentError(absl::StrCat(name_, ": gml:id '", out.id, "' is used by two city objects"));
      }
      model_->skipped["duplicate gml:id"]++;
      keep = false;
    }
    const std::string id = out.id;
    if (keep) model_->objects.push_back(std::move(out));
    for (unsigned i = 0; i < o.getChildCityObjectsCount(); ++i) {
      const citygml::CityObject& child = o.getChildCityObject(i);
      if (Classify(child.getType(), o.getType(), true).role == Role::kSemantic) continue;
      if (auto s = Object(child, &o, id); !s.ok()) return s;
    }
    return absl::OkStatus();
  }

 private:
  static void Polygons(const citygml::Geometry& g, std::vector<std::shared_ptr<const citygml::Polygon>>* out) {
    for (unsigned i = 0; i < g.getPolygonsCount(); ++i) out->push_back(g.getPolygon(i));
    for (unsigned i = 0; i < g.getGeometriesCount(); ++i) Polygons(g.getGeometry(i), out);
  }

  std::vector<glm::dvec3> Ring(const citygml::LinearRing* ring, const Placement& place, bool reverse) {
    std::vector<glm::dvec3> out;
    if (ring == nullptr) return out;
    const auto& v = ring->getVertices();
    out.reserve(v.size());
    for (const auto& p : v) out.push_back(place(p));
    if (out.size() > 1 && out.front() == out.back()) out.pop_back();  // GML rings are closed
    if (reverse && out.size() > 2) std::reverse(out.begin() + 1, out.end());
    return out;
  }

  CitySurface Surface(const citygml::Polygon& p, const Placement& place) {
    CitySurface s;
    s.outer = Ring(p.exteriorRing().get(), place, p.negNormal());
    for (const auto& hole : p.interiorRings()) s.holes.push_back(Ring(hole.get(), place, p.negNormal()));
    return s;
  }

  // The rings' bytes: equal keys, identical rings (a total order even with NaN about).
  static std::string Key(const CitySurface& s) {
    std::string key;
    auto add = [&key](const std::vector<glm::dvec3>& ring) {
      const size_t n = ring.size();
      key.append(reinterpret_cast<const char*>(&n), sizeof n);
      key.append(reinterpret_cast<const char*>(ring.data()), ring.size() * sizeof(glm::dvec3));
    };
    add(s.outer);
    for (const auto& h : s.holes) add(h);
    return key;
  }

  std::vector<CitySurface> Surfaces(const citygml::Geometry& g, const Placement& place,
                                    std::unordered_set<const citygml::Polygon*>* seen,
                                    std::unordered_set<std::string>* seen_rings) {
    std::vector<std::shared_ptr<const citygml::Polygon>> polygons;
    Polygons(g, &polygons);
    std::vector<CitySurface> out;
    for (const auto& p : polygons) {
      if (p == nullptr) continue;
      seen->insert(p.get());
      out.push_back(Surface(*p, place));
      seen_rings->insert(Key(out.back()));
    }
    return out;
  }

  GmlKind KindOf(const citygml::Geometry& g) const {
    if (auto it = prescan_.kinds.find(g.getId()); it != prescan_.kinds.end()) return it->second;
    // Not seen by the pre-scan (a document expat could not mark up): guess from the shape.
    if (g.getPolygonsCount() > 0) return GmlKind::kMultiSurface;
    for (unsigned i = 0; i < g.getGeometriesCount(); ++i) {
      if (g.getGeometry(i).getGeometriesCount() > 0) return GmlKind::kMultiSolid;
    }
    return g.getGeometriesCount() > 0 ? GmlKind::kSolid : GmlKind::kCurve;
  }

  CitySolid Solid(const citygml::Geometry& g, const Placement& place,
                  std::unordered_set<const citygml::Polygon*>* seen, std::unordered_set<std::string>* seen_rings) {
    // libcitygml keeps gml:exterior and gml:interior shells in document order: exterior first.
    CitySolid solid;
    std::vector<CitySurface> direct;
    for (unsigned i = 0; i < g.getPolygonsCount(); ++i) {
      if (auto p = g.getPolygon(i)) {
        seen->insert(p.get());
        direct.push_back(Surface(*p, place));
      }
    }
    for (unsigned i = 0; i < g.getGeometriesCount(); ++i) {
      solid.shells.push_back(Surfaces(g.getGeometry(i), place, seen, seen_rings));
    }
    if (!direct.empty()) {
      if (solid.shells.empty()) solid.shells.emplace_back();
      solid.shells[0].insert(solid.shells[0].begin(), direct.begin(), direct.end());
    }
    return solid;
  }

  void AddGeometry(const citygml::Geometry& g, const TypeInfo& info, const Placement& place, CityObject* out,
                   std::unordered_set<const citygml::Polygon*>* seen, std::unordered_set<std::string>* seen_rings) {
    const GmlKind kind = KindOf(g);
    if (kind == GmlKind::kCurve) return;  // terrain intersection curves, points: not surfaces
    CityGeometry geometry;
    geometry.lod = std::to_string(g.getLOD());
    switch (kind) {
      case GmlKind::kSolid:
        geometry.type = CityGeometryType::kSolid;
        geometry.solids.push_back(Solid(g, place, seen, seen_rings));
        break;
      case GmlKind::kMultiSolid:
      case GmlKind::kCompositeSolid:
        geometry.type = kind == GmlKind::kMultiSolid ? CityGeometryType::kMultiSolid : CityGeometryType::kCompositeSolid;
        for (unsigned i = 0; i < g.getGeometriesCount(); ++i) {
          geometry.solids.push_back(Solid(g.getGeometry(i), place, seen, seen_rings));
        }
        break;
      case GmlKind::kTriangulatedSurface:
        geometry.type = std::string_view(info.name) == "TINRelief" ? CityGeometryType::kTin
                                                                     : CityGeometryType::kCompositeSurface;
        geometry.surfaces = Surfaces(g, place, seen, seen_rings);
        break;
      case GmlKind::kCompositeSurface:
        geometry.type = CityGeometryType::kCompositeSurface;
        geometry.surfaces = Surfaces(g, place, seen, seen_rings);
        break;
      default:
        geometry.type = CityGeometryType::kMultiSurface;
        geometry.surfaces = Surfaces(g, place, seen, seen_rings);
        break;
    }
    if (geometry.solids.empty() && geometry.surfaces.empty() && g.getLineStringCount() > 0) return;
    out->geometries.push_back(std::move(geometry));
  }

  void Fold(const citygml::CityObject& surface, std::map<unsigned, CityGeometry>* boundary,
            const std::unordered_set<const citygml::Polygon*>& seen, const std::unordered_set<std::string>& seen_rings) {
    for (unsigned i = 0; i < surface.getGeometriesCount(); ++i) {
      const citygml::Geometry& g = surface.getGeometry(i);
      std::vector<std::shared_ptr<const citygml::Polygon>> polygons;
      Polygons(g, &polygons);
      for (const auto& p : polygons) {
        if (p == nullptr || seen.count(p.get()) > 0) continue;
        CitySurface s = Surface(*p, Placement{});
        if (seen_rings.count(Key(s)) > 0) continue;
        CityGeometry& target = (*boundary)[g.getLOD()];
        target.type = CityGeometryType::kMultiSurface;
        target.lod = std::to_string(g.getLOD());
        target.surfaces.push_back(std::move(s));
      }
    }
    for (unsigned i = 0; i < surface.getChildCityObjectsCount(); ++i) {
      Fold(surface.getChildCityObject(i), boundary, seen, seen_rings);  // openings
    }
  }

  static std::string CheckSurface(const CitySurface& s) {
    auto ring = [](const std::vector<glm::dvec3>& r) -> std::string {
      if (r.size() < 3) return absl::StrCat("a ring of ", r.size(), " points");
      for (const auto& p : r) {
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) return "a coordinate that is not finite";
      }
      return "";
    };
    if (auto e = ring(s.outer); !e.empty()) return e;
    for (const auto& h : s.holes) {
      if (auto e = ring(h); !e.empty()) return absl::StrCat(e, " (a hole)");
    }
    return "";
  }

  static std::string Check(const CityObject& o) {
    for (const auto& g : o.geometries) {
      const std::string where = absl::StrCat("LoD ", g.lod, " geometry: ");
      if (g.type == CityGeometryType::kSolid || g.type == CityGeometryType::kMultiSolid ||
          g.type == CityGeometryType::kCompositeSolid) {
        if (g.solids.empty()) return where + "no solid";
        for (const auto& solid : g.solids) {
          if (solid.shells.empty()) return where + "an empty solid";
          for (const auto& shell : solid.shells) {
            if (shell.empty()) return where + "an empty shell";
            for (const auto& s : shell) {
              if (auto e = CheckSurface(s); !e.empty()) return where + e;
            }
          }
        }
      } else {
        if (g.surfaces.empty()) return where + "no surface";
        for (const auto& s : g.surfaces) {
          if (auto e = CheckSurface(s); !e.empty()) return where + e;
        }
      }
    }
    return "";
  }

  const std::string& name_;
  const CityReadOptions& options_;
  const Prescan& prescan_;
  CityModel* model_;
  std::string problem_;
  std::unordered_set<std::string> ids_;
};

absl::StatusOr<CityModel> Read(std::string_view bytes, const std::string& name, const CityReadOptions& options,
                               const RunControl& run) {
  Progress progress(run, "Reading CityGML", 3);
  Prescan prescan;
  PrescanParser(bytes, &prescan).Run();
  if (!prescan.error.empty()) return absl::InvalidArgumentError(absl::StrCat(name, ": ", prescan.error));
  if (auto it = prescan.malformed.find(""); it != prescan.malformed.end()) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": malformed geometry outside any city object: ", it->second));
  }
  progress.Advance();
  if (progress.Cancelled()) return absl::CancelledError(absl::StrCat(name, ": reading cancelled"));

  citygml::ParserParams params;
  params.tesselate = false;   // rings as written; the builder triangulates
  params.keepVertices = true;
  params.optimize = false;    // no merging of polygons or removal of repeated points
  params.pruneEmptyObjects = false;
  params.destSRS = "";        // no reprojection
  auto logger = std::make_shared<CollectingLogger>();
  std::shared_ptr<const citygml::CityModel> city;
  {
    std::istringstream stream(prescan.insertions.empty() ? std::string(bytes)
                                                         : WithInsertions(bytes, std::move(prescan.insertions)));
    // Debian's libcitygml is built without NDEBUG, so its parsers' exceptions (an unexpected
    // start tag, a dem:lod that is not a number, xerces' own) reach us; its log says where.
    auto failed = [&](const std::string& what) {
      const auto errors = logger->Errors();
      return absl::InvalidArgumentError(absl::StrCat(name, ": libcitygml: ", errors.empty() ? what : errors.front()));
    };
    try {
      city = citygml::load(stream, params, logger);
    } catch (const std::exception& e) {
      return failed(e.what());
    } catch (...) {
      return failed("an exception that is not a std::exception");
    }
  }
  // Without a model the document was not read to its end: an error. With one, what libcitygml
  // logged as an error did not stop it (e.g. its "end tag reported as unknown" for a
  // veg:lod1Geometry, a parser bug): counted, not fatal.
  const auto errors = logger->Errors();
  if (city == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": libcitygml read no CityModel", errors.empty() ? "" : ": ", errors.empty() ? "" : errors.front()));
  }
  progress.Advance();
  if (progress.Cancelled()) return absl::CancelledError(absl::StrCat(name, ": reading cancelled"));

  CityModel model;
  if (logger->ErrorCount() > 0) model.skipped["libcitygml error"] = logger->ErrorCount();
  model.format = prescan.format;
  const std::string& srs = prescan.envelope_srs.empty() ? prescan.any_srs : prescan.envelope_srs;
  model.crs = srs.empty() ? "" : NormaliseCrs(srs);
  Converter converter(name, options, prescan, &model);
  for (const citygml::CityObject* o : city->getRootCityObjects()) {
    if (o == nullptr) continue;
    if (auto s = converter.Object(*o, nullptr, ""); !s.ok()) return s;
  }
  progress.Advance();
  progress.Finish();
  return model;
}

}  // namespace

absl::StatusOr<CityModel> ReadCityGml(const std::string& path, const CityReadOptions& options,
                                      const RunControl& run) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open file"));
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return absl::InvalidArgumentError(absl::StrCat(path, ": read error"));
  return Read(bytes, path, options, run);
}

absl::StatusOr<CityModel> ReadCityGmlFromMemory(std::string_view bytes, const std::string& name,
                                                const CityReadOptions& options) {
  return Read(bytes, name, options, RunControl{});
}

}  // namespace vistream::scenes
