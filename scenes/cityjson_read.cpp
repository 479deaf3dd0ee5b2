// CityJSON reader (scenes/city_model.h): the CityJSON 1.0, 1.1 and 2.0 specifications
// (https://www.cityjson.org/specs/), sections "CityJSON Object", "Transform Object",
// "Geometry Objects" and "Geometry templates"; the 0.x ones (github.com/cityjson/specs, tags
// 0.1 to 0.9) where they differ.
//
// What it reads and how:
// - CityJSON 0.1 to 0.9, 1.0, 1.1 and 2.0, all of whose geometry is encoded as in 1.0, in the
//   two headers they were written with; anything else is refused naming the version:
//   - "type": "CityJSON" with "version" "1.0", "1.1", "2.0" (a patch suffix such as "1.0.3" is
//     accepted) or "0.3" to "0.9" (of these 0.3, 0.5, 0.6, 0.8 and 0.9 were published);
//   - "type": "CityModel" with "version" a URL, "http://www.cityjson.org/version/0.1" or
//     .../0.2 (https, without "www." or with a trailing slash too): the header of 0.1 and 0.2
//     (0.3 changed it; citygml4j wrote 0.2 so).
//   CityJSONFeature streams (.jsonl) are not read. CityModel::format is "CityJSON <version>":
//   as written ("1.0.3"), or the URL's ("0.1").
// - "vertices" are integers with "transform" (scale, translate; mandatory from 1.1) or plain
//   numbers without it (1.0 and 0.x); any JSON number is taken either way. Each vertex is
//   transformed once, up front; a coordinate that is not finite after the transform is an
//   error only where a ring uses it (it is that object's malformed geometry).
// - City objects keep the file's order (recorded by a SAX pass, as nlohmann::json sorts an
//   object's keys), their "type" as written ("+Extension" types too), and their parent from
//   "parents"[0] (0.9 and later) or "parent" (0.8, Den Haag's), or else from the object that
//   lists it in its "Parts" or "Installations" (0.1 to 0.6: a Building's BuildingParts, ...).
// - "lod" is a number in 1.0 and 0.x (the 0.1 and 0.2 examples write "2") and a string from
//   1.1; either is kept as its text ("2", "2.2") in any version.
// - Solid, MultiSolid, CompositeSolid, MultiSurface, CompositeSurface (a TINRelief's
//   CompositeSurface is CityGeometryType::kTin) and GeometryInstance: the template
//   ("geometry-templates": templates and "vertices-templates", which "transform" does not
//   apply to) is transformed by the 4x4 row-major "transformationMatrix" (its top three rows:
//   an affine map) and then translated by the reference point, the vertex boundaries[0]; the
//   instance takes the template's type and lod. MultiPoint and MultiLineString geometries, and
//   types this reader does not know, are left out and counted in CityModel::skipped.
// - Semantics (in any version's form: 0.1's nested strings, 0.2's objects, 0.5's "surfaces" and
//   "values"), materials, textures and attributes are not read.
// - Rings come out open: a ring whose last point repeats its first has that point dropped,
//   counted in CityModel::repaired["ring closed by repeating its first point"].
//
// Errors: INVALID_ARGUMENT "<name>: <JSON path>: <what>", for example
// `x.city.json: CityObjects["b12"].geometry[0].boundaries[0][3][0][2]: vertex index 991 is out
// of range (991 vertices)`. Problems of the whole file (not JSON, wrong "type" or "version",
// malformed "transform", "vertices" or "metadata") always fail the read. Problems of one city
// object (wrong JSON types in it, a vertex index out of range, a non-finite coordinate, an
// empty geometry, solid, shell, surface or ring, a ring of fewer than 3 points, a bad
// template reference) fail it too unless CityReadOptions::keep_going: then the object is left
// out and counted in skipped["malformed geometry"]. No exception leaves the reader.

#include <absl/status/status.h>
#include <absl/status/statusor.h>
#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <new>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "scenes/city_model.h"
#include "scenes/progress.h"

namespace vistream::scenes {
namespace {

using Json = nlohmann::json;

constexpr char kMalformed[] = "malformed geometry";
constexpr char kClosedRing[] = "ring closed by repeating its first point";

// A place in the document, built on the stack as the reader descends and turned into text
// only for an error: CityObjects["b12"].geometry[0].boundaries[0][3]. It points at its parent:
// keep each step of a stored path in a variable of its own (a chain of temporaries dangles).
struct JsonPath {
  const JsonPath* parent = nullptr;
  std::string_view key;  // a member name, or
  size_t index = 0;      // an array index when key is empty and is_index
  bool is_index = false;
  bool quoted = false;  // ["key"] rather than .key (city object ids)

  JsonPath Member(std::string_view k) const { return JsonPath{this, k, 0, false, false}; }
  JsonPath Quoted(std::string_view k) const { return JsonPath{this, k, 0, false, true}; }
  JsonPath At(size_t i) const { return JsonPath{this, {}, i, true, false}; }

  std::string Text() const {
    std::vector<const JsonPath*> chain;
    for (const JsonPath* p = this; p != nullptr; p = p->parent) chain.push_back(p);
    std::string out;
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      const JsonPath& p = **it;
      if (p.is_index) {
        absl::StrAppend(&out, "[", p.index, "]");
      } else if (p.quoted) {
        absl::StrAppend(
            &out, "[",
            Json(std::string(p.key)).dump(-1, ' ', false, Json::error_handler_t::replace), "]");
      } else if (!p.key.empty()) {
        absl::StrAppend(&out, out.empty() ? "" : ".", std::string(p.key));
      }
    }
    return out;
  }
};

absl::Status Invalid(const std::string& name, const JsonPath& path, const std::string& what) {
  const std::string where = path.Text();
  return absl::InvalidArgumentError(where.empty() ? absl::StrCat(name, ": ", what)
                                                  : absl::StrCat(name, ": ", where, ": ", what));
}

// A value as an error message shows it: a primitive as JSON, cut short; an array or object by
// its type only (dumping one recurses as deep as it nests, and a hostile file nests deep).
std::string Shown(const Json& j) {
  if (!j.is_primitive()) return j.type_name();
  std::string s = j.dump(-1, ' ', false, Json::error_handler_t::replace);
  if (s.size() > 40) s = s.substr(0, 37) + "...";
  return s;
}

std::string Expected(const std::string& what, const Json& got) {
  return absl::StrCat("expected ", what, ", got ", got.type_name(),
                      got.is_primitive() ? " " + Shown(got) : "");
}

std::string Point(const glm::dvec3& p) { return absl::StrCat("(", p.x, ", ", p.y, ", ", p.z, ")"); }

// "major.minor" or "major.minor.patch", each a number of at most 3 digits, into `n`; the
// number of dots, or -1 for other text.
int ParseVersion(std::string_view version, int n[3]) {
  n[0] = n[1] = n[2] = 0;
  int dots = 0;
  size_t digits = 0;
  for (const char c : version) {
    if (c == '.') {
      if (digits == 0 || ++dots == 3) return -1;
      digits = 0;
    } else if (c >= '0' && c <= '9' && digits < 3) {
      n[dots] = n[dots] * 10 + (c - '0');
      ++digits;
    } else {
      return -1;
    }
  }
  return digits == 0 || dots == 0 ? -1 : dots;
}

// What this reader reads, for the message that refuses a file. 0.1 and 0.2 wrote the CityModel
// form (their specifications' "CityJSON Object"; citygml4j wrote 0.2 so), 0.3 changed the
// header to the CityJSON form; the geometry is encoded as in 1.0 throughout 0.x.
constexpr char kVersionsRead[] =
    "this reader reads CityJSON 0.1 and 0.2 (\"type\": \"CityModel\", \"version\": "
    "\"http://www.cityjson.org/version/0.1\" or .../0.2) and 0.3 to 0.9, 1.0, 1.1 and 2.0 "
    "(\"type\": \"CityJSON\", \"version\": \"0.3\" to \"2.0\", from 1.0 with or without a patch "
    "number)";

// "type": "CityJSON": the version as written when this reader knows its encoding.
bool KnownVersion(std::string_view version) {
  int n[3];
  const int dots = ParseVersion(version, n);
  if (dots < 0) return false;
  if (n[0] == 0) return dots == 1 && n[1] >= 3 && n[1] <= 9;
  return (n[0] == 1 && (n[1] == 0 || n[1] == 1)) || (n[0] == 2 && n[1] == 0);
}

// "type": "CityModel" (0.1, 0.2): "http://www.cityjson.org/version/0.1" -> "0.1"; https, no
// "www." and a trailing slash too; "" for any other text.
std::string CityModelVersion(std::string_view url) {
  for (const std::string_view scheme : {"http://", "https://"}) {
    if (url.starts_with(scheme)) url.remove_prefix(scheme.size());
  }
  if (url.starts_with("www.")) url.remove_prefix(4);
  constexpr std::string_view kPath = "cityjson.org/version/";
  if (!url.starts_with(kPath)) return "";
  url.remove_prefix(kPath.size());
  if (url.ends_with('/')) url.remove_suffix(1);
  return url == "0.1" || url == "0.2" ? std::string(url) : "";
}

bool TransformRequired(std::string_view version) {
  return !(version.starts_with("0.") || version.starts_with("1.0"));
}

// "urn:ogc:def:crs:EPSG::28992", "https://www.opengis.net/def/crs/EPSG/0/7415", "EPSG:7415"
// -> "EPSG:<code>"; other text as it is (a compound URN with a comma, an OGC CRS, ...).
std::string NormaliseCrs(const std::string& text) {
  std::string upper = text;
  for (char& c : upper) c = static_cast<char>(c >= 'a' && c <= 'z' ? c - 'a' + 'A' : c);
  const size_t epsg = upper.find("EPSG");
  if (epsg == std::string::npos || text.find(',') != std::string::npos) return text;
  size_t end = text.size();
  while (end > 0 && (text[end - 1] == '/' || text[end - 1] == ' ')) --end;
  size_t begin = end;
  while (begin > 0 && text[begin - 1] >= '0' && text[begin - 1] <= '9') --begin;
  if (begin == end || begin <= epsg + 4 || (text[begin - 1] != ':' && text[begin - 1] != '/'))
    return text;
  return absl::StrCat("EPSG:", text.substr(begin, end - begin));
}

// One geometry as parsed, before placement; the kind the model keeps or the reason it skips.
struct ParsedGeometry {
  std::optional<CityGeometry> geometry;  // empty: skipped
  std::string skip_reason;
};

// SAX events (nlohmann::json_sax) in, the keys of the top-level "CityObjects" member out.
struct CityObjectsOrder {
  std::vector<std::string> ids;
  int depth = 0;
  bool in_city_objects = false;

  bool null() { return true; }
  bool boolean(bool) { return true; }
  bool number_integer(Json::number_integer_t) { return true; }
  bool number_unsigned(Json::number_unsigned_t) { return true; }
  bool number_float(Json::number_float_t, const Json::string_t&) { return true; }
  bool string(Json::string_t&) { return true; }
  bool binary(Json::binary_t&) { return true; }
  bool start_object(size_t) { return ++depth, true; }
  bool end_object() { return --depth, true; }
  bool start_array(size_t) { return ++depth, true; }
  bool end_array() { return --depth, true; }
  bool key(Json::string_t& k) {
    if (depth == 1) {
      in_city_objects = k == "CityObjects";
    } else if (depth == 2 && in_city_objects) {
      ids.push_back(k);
    }
    return true;
  }
  bool parse_error(size_t, const std::string&, const Json::exception&) { return false; }
};

struct ObjectCounts {
  std::map<std::string, uint64_t> skipped;
  std::map<std::string, uint64_t> repaired;
};

class Reader {
 public:
  Reader(std::string name, const CityReadOptions& options, const RunControl& run)
      : name_(std::move(name)), options_(options), run_(run) {}

  absl::StatusOr<CityModel> Read(std::string_view bytes) {
    try {
      return ReadDocument(bytes);
    } catch (const Json::exception& e) {
      // Parse errors land here; the rest of the reader checks types before every access.
      return absl::InvalidArgumentError(
          absl::StrCat(name_, ": not valid JSON: ", std::string(Stripped(e.what()))));
    } catch (const std::bad_alloc&) {
      return absl::ResourceExhaustedError(absl::StrCat(name_, ": out of memory reading the file"));
    }
  }

 private:
  static std::string_view Stripped(std::string_view what) {
    // "[json.exception.parse_error.101] parse error at line 1, ..." -> "parse error at line 1, ..."
    if (what.starts_with("[json.exception.")) {
      const size_t close = what.find("] ");
      if (close != std::string_view::npos) what.remove_prefix(close + 2);
    }
    return what;
  }

  absl::StatusOr<CityModel> ReadDocument(std::string_view bytes) {
    const Json doc = Json::parse(bytes);
    // nlohmann::json keeps an object's members sorted by key; a second, SAX-only pass over the
    // bytes records the order in which CityObjects' ids appear, so that the model (and the ids
    // a scene gives its objects) follow the file. (nlohmann's parse callback would do it in one
    // pass, but its parser scans the whole parent object at every object's end: quadratic in
    // the number of city objects.)
    CityObjectsOrder order;
    Json::sax_parse(bytes, &order);
    const JsonPath root;
    if (!doc.is_object()) return Invalid(name_, root, Expected("a JSON object (CityJSON)", doc));

    const auto type = doc.find("type");
    if (type == doc.end()) return Invalid(name_, root, "no \"type\": not a CityJSON file");
    // "CityModel": the header of 0.1 and 0.2, with the version as a URL.
    const bool city_model = type->is_string() && type->get_ref<const std::string&>() == "CityModel";
    if (!type->is_string() || (!city_model && type->get_ref<const std::string&>() != "CityJSON")) {
      return Invalid(name_, root.Member("type"),
                     absl::StrCat(Shown(*type),
                                  " is not \"CityJSON\" (nor \"CityModel\", CityJSON 0.1 and 0.2; "
                                  "CityJSONFeature streams are not read)"));
    }
    const auto version = doc.find("version");
    if (version == doc.end())
      return Invalid(name_, root, "no \"version\": unknown CityJSON version");
    std::string version_text;
    if (version->is_string()) {
      const std::string& text = version->get_ref<const std::string&>();
      version_text = city_model ? CityModelVersion(text) : KnownVersion(text) ? text : "";
    }
    if (version_text.empty()) {
      return Invalid(
          name_, root.Member("version"),
          absl::StrCat(city_model ? "type \"CityModel\" with version " : "CityJSON version ",
                       Shown(*version), " is not one this reader knows: ", kVersionsRead));
    }
    CityModel model;
    model.format = absl::StrCat("CityJSON ", version_text);

    if (absl::Status s = ReadCrs(doc, root, &model.crs); !s.ok()) return s;
    if (absl::Status s = ReadVertices(doc, root, version_text); !s.ok()) return s;
    if (absl::Status s = ReadTemplates(doc, root); !s.ok()) return s;

    const auto objects = doc.find("CityObjects");
    if (objects == doc.end()) return Invalid(name_, root, "no \"CityObjects\"");
    if (!objects->is_object())
      return Invalid(name_, root.Member("CityObjects"), Expected("an object", *objects));

    // File order; an id given twice keeps its first place (and the value JSON keeps: the last).
    std::vector<Json::const_iterator> in_order;
    in_order.reserve(objects->size());
    {
      std::unordered_set<std::string_view> seen;
      for (const std::string& id : order.ids) {
        if (!seen.insert(id).second) continue;
        const auto it = objects->find(id);
        if (it != objects->end()) in_order.push_back(it);
      }
      if (in_order.size() != objects->size()) {  // a second "CityObjects" member; not expected
        for (auto it = objects->begin(); it != objects->end(); ++it) {
          if (!seen.contains(it.key())) in_order.push_back(it);
        }
      }
    }

    // (index in model.objects of the object that lists it, id): "Parts" and "Installations".
    std::vector<std::pair<size_t, std::string>> listed;
    Progress progress(run_, absl::StrCat("reading ", name_), in_order.size());
    const JsonPath objects_path = root.Member("CityObjects");
    model.objects.reserve(in_order.size());
    for (const auto& it : in_order) {
      if (progress.Cancelled()) {
        progress.Finish();
        return absl::CancelledError(absl::StrCat(name_, ": cancelled"));
      }
      CityObject object;
      ObjectCounts counts;
      std::vector<std::string> parts;
      const JsonPath path = objects_path.Quoted(it.key());
      absl::Status s = ReadObject(it.key(), it.value(), path, &object, &counts, &parts);
      if (s.ok()) {
        for (std::string& part : parts) listed.emplace_back(model.objects.size(), std::move(part));
        model.objects.push_back(std::move(object));
        for (const auto& [reason, n] : counts.skipped) model.skipped[reason] += n;
        for (const auto& [reason, n] : counts.repaired) model.repaired[reason] += n;
      } else if (options_.keep_going) {
        ++model.skipped[std::string(kMalformed)];
      } else {
        return s;
      }
      progress.Advance();
    }
    progress.Finish();
    SetListedParents(listed, &model);
    return model;
  }

  // 0.1 to 0.6 list a Building's (Bridge's, Tunnel's) parts and installations on it, and the
  // listed objects name no parent; from 0.8 each names its own. The parent an object names
  // wins, then the first object that lists it; an id not in the model is passed over.
  static void SetListedParents(const std::vector<std::pair<size_t, std::string>>& listed,
                               CityModel* model) {
    if (listed.empty()) return;
    std::unordered_map<std::string_view, size_t> index;
    for (size_t i = 0; i < model->objects.size(); ++i) index.emplace(model->objects[i].id, i);
    for (const auto& [owner, id] : listed) {
      const auto it = index.find(id);
      if (it == index.end() || it->second == owner) continue;
      CityObject& child = model->objects[it->second];
      if (child.parent.empty()) child.parent = model->objects[owner].id;
    }
  }

  absl::Status ReadCrs(const Json& doc, const JsonPath& root, std::string* crs) {
    const auto metadata = doc.find("metadata");
    if (metadata == doc.end()) return absl::OkStatus();
    const JsonPath path = root.Member("metadata");
    if (!metadata->is_object()) return Invalid(name_, path, Expected("an object", *metadata));
    if (const auto rs = metadata->find("referenceSystem"); rs != metadata->end()) {
      if (!rs->is_string())
        return Invalid(name_, path.Member("referenceSystem"), Expected("a string", *rs));
      *crs = NormaliseCrs(rs->get<std::string>());
      return absl::OkStatus();
    }
    // 0.x: "crs": {"epsg": 7415}.
    if (const auto c = metadata->find("crs"); c != metadata->end() && c->is_object()) {
      if (const auto epsg = c->find("epsg"); epsg != c->end()) {
        if (!epsg->is_number_unsigned()) {
          return Invalid(name_, path.Member("crs").Member("epsg"), Expected("an EPSG code", *epsg));
        }
        *crs = absl::StrCat("EPSG:", epsg->get<uint64_t>());
      }
    }
    return absl::OkStatus();
  }

  // Three numbers, finite: a transform's scale or translate.
  absl::Status ReadTriple(const Json& j, const JsonPath& path, glm::dvec3* out) {
    if (!j.is_array() || j.size() != 3)
      return Invalid(name_, path, Expected("an array of 3 numbers", j));
    for (size_t i = 0; i < 3; ++i) {
      if (!j[i].is_number()) return Invalid(name_, path.At(i), Expected("a number", j[i]));
      (*out)[static_cast<glm::length_t>(i)] = j[i].get<double>();
      if (!std::isfinite((*out)[static_cast<glm::length_t>(i)]))
        return Invalid(name_, path.At(i), "not finite");
    }
    return absl::OkStatus();
  }

  // An array of [x, y, z] numbers into `out`, mapped by scale and translate.
  absl::Status ReadPoints(const Json& j, const JsonPath& path, const glm::dvec3& scale,
                          const glm::dvec3& translate, std::vector<glm::dvec3>* out) {
    if (!j.is_array()) return Invalid(name_, path, Expected("an array of [x, y, z]", j));
    out->reserve(j.size());
    // A scale of 1/D for a whole D (0.001: millimetres) and a translate on that grid: the
    // coordinate is the integer n = v + translate·D over D, computed as one correctly rounded
    // division, the double nearest the decimal the file stands for, the same double a CityGML
    // reader parses from the same decimal text (so both formats give the same geometry).
    int64_t divisor[3] = {0, 0, 0}, offset[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      const double d = 1.0 / scale[k];
      const double t = translate[k] * std::round(d);
      if (std::isfinite(d) && d >= 1.0 && d <= 1e9 && std::abs(d - std::round(d)) <= 1e-9 * d &&
          std::abs(t) < 0x1p52 && std::abs(t - std::round(t)) <= 1e-6) {
        divisor[k] = static_cast<int64_t>(std::round(d));
        offset[k] = static_cast<int64_t>(std::round(t));
      }
    }
    for (size_t v = 0; v < j.size(); ++v) {
      const Json& p = j[v];
      if (!p.is_array() || p.size() != 3)
        return Invalid(name_, path.At(v), Expected("[x, y, z]", p));
      glm::dvec3 q;
      for (size_t i = 0; i < 3; ++i) {
        if (!p[i].is_number()) return Invalid(name_, path.At(v).At(i), Expected("a number", p[i]));
        const auto k = static_cast<glm::length_t>(i);
        const double raw = p[i].get<double>();
        if (divisor[i] != 0 && p[i].is_number_integer() && std::abs(raw) < 0x1p52) {
          q[k] = static_cast<double>(p[i].get<int64_t>() + offset[i]) / static_cast<double>(divisor[i]);
        } else {
          q[k] = raw * scale[k] + translate[k];
        }
      }
      out->push_back(q);
    }
    return absl::OkStatus();
  }

  absl::Status ReadVertices(const Json& doc, const JsonPath& root, const std::string& version) {
    glm::dvec3 scale(1.0), translate(0.0);
    if (const auto t = doc.find("transform"); t != doc.end()) {
      const JsonPath path = root.Member("transform");
      if (!t->is_object()) return Invalid(name_, path, Expected("an object", *t));
      const auto s = t->find("scale");
      const auto tr = t->find("translate");
      if (s == t->end() || tr == t->end())
        return Invalid(name_, path, "needs \"scale\" and \"translate\"");
      if (absl::Status st = ReadTriple(*s, path.Member("scale"), &scale); !st.ok()) return st;
      if (absl::Status st = ReadTriple(*tr, path.Member("translate"), &translate); !st.ok())
        return st;
    } else if (TransformRequired(version)) {
      return Invalid(name_, root,
                     absl::StrCat("no \"transform\": CityJSON ", version, " requires one"));
    }
    const auto v = doc.find("vertices");
    if (v == doc.end()) return Invalid(name_, root, "no \"vertices\"");
    return ReadPoints(*v, root.Member("vertices"), scale, translate, &vertices_);
  }

  absl::Status ReadTemplates(const Json& doc, const JsonPath& root) {
    const auto gt = doc.find("geometry-templates");
    if (gt == doc.end()) return absl::OkStatus();
    const JsonPath path = root.Member("geometry-templates");
    if (!gt->is_object()) return Invalid(name_, path, Expected("an object", *gt));
    const auto templates = gt->find("templates");
    const auto tv = gt->find("vertices-templates");
    if (templates == gt->end() || tv == gt->end()) {
      return Invalid(name_, path, "needs \"templates\" and \"vertices-templates\"");
    }
    if (!templates->is_array())
      return Invalid(name_, path.Member("templates"), Expected("an array", *templates));
    templates_ = &*templates;
    template_cache_.resize(templates->size());
    return ReadPoints(*tv, path.Member("vertices-templates"), glm::dvec3(1.0), glm::dvec3(0.0),
                      &template_vertices_);
  }

  // ---- one city object ----

  // `parts`: the ids the object lists as its "Parts" and "Installations" (0.1 to 0.6).
  absl::Status ReadObject(const std::string& id, const Json& j, const JsonPath& path,
                          CityObject* out, ObjectCounts* counts, std::vector<std::string>* parts) {
    if (!j.is_object()) return Invalid(name_, path, Expected("a city object", j));
    out->id = id;
    const auto type = j.find("type");
    if (type == j.end()) return Invalid(name_, path, "no \"type\"");
    if (!type->is_string()) return Invalid(name_, path.Member("type"), Expected("a string", *type));
    out->type = type->get<std::string>();
    if (const auto parents = j.find("parents"); parents != j.end()) {
      if (!parents->is_array())
        return Invalid(name_, path.Member("parents"), Expected("an array of ids", *parents));
      if (!parents->empty()) {
        if (!(*parents)[0].is_string())
          return Invalid(name_, path.Member("parents").At(0), Expected("an id", (*parents)[0]));
        out->parent = (*parents)[0].get<std::string>();
      }
    } else if (const auto parent = j.find("parent"); parent != j.end()) {  // 0.x
      if (!parent->is_string())
        return Invalid(name_, path.Member("parent"), Expected("an id", *parent));
      out->parent = parent->get<std::string>();
    }
    for (const char* key : {"Parts", "Installations"}) {
      const auto list = j.find(key);
      if (list == j.end()) continue;
      const JsonPath lpath = path.Member(key);
      if (!list->is_array()) return Invalid(name_, lpath, Expected("an array of ids", *list));
      for (size_t i = 0; i < list->size(); ++i) {
        if (!(*list)[i].is_string())
          return Invalid(name_, lpath.At(i), Expected("an id", (*list)[i]));
        parts->push_back((*list)[i].get<std::string>());
      }
    }
    const auto geometry = j.find("geometry");
    if (geometry == j.end()) return absl::OkStatus();
    const JsonPath gpath = path.Member("geometry");
    if (!geometry->is_array())
      return Invalid(name_, gpath, Expected("an array of geometries", *geometry));
    for (size_t g = 0; g < geometry->size(); ++g) {
      ParsedGeometry parsed;
      if (absl::Status s = ReadGeometry((*geometry)[g], gpath.At(g), out->type, &parsed, counts);
          !s.ok())
        return s;
      if (parsed.geometry) {
        out->geometries.push_back(*std::move(parsed.geometry));
      } else {
        ++counts->skipped[parsed.skip_reason];
      }
    }
    return absl::OkStatus();
  }

  absl::Status ReadGeometry(const Json& j, const JsonPath& path, const std::string& object_type,
                            ParsedGeometry* out, ObjectCounts* counts) {
    if (!j.is_object()) return Invalid(name_, path, Expected("a geometry object", j));
    const auto type = j.find("type");
    if (type == j.end()) return Invalid(name_, path, "no \"type\"");
    if (!type->is_string()) return Invalid(name_, path.Member("type"), Expected("a string", *type));
    const std::string& t = type->get_ref<const std::string&>();
    if (t == "GeometryInstance") return ReadInstance(j, path, out, counts);
    return ReadPlainGeometry(j, path, object_type, vertices_, "vertices", out, counts);
  }

  // Any geometry but an instance, its indices into `verts`.
  absl::Status ReadPlainGeometry(const Json& j, const JsonPath& path, std::string_view object_type,
                                 const std::vector<glm::dvec3>& verts, const char* verts_name,
                                 ParsedGeometry* out, ObjectCounts* counts) {
    const std::string& t = j.find("type")->get_ref<const std::string&>();
    CityGeometry g;
    bool solids = false;
    if (t == "Solid") {
      g.type = CityGeometryType::kSolid;
      solids = true;
    } else if (t == "MultiSolid") {
      g.type = CityGeometryType::kMultiSolid;
      solids = true;
    } else if (t == "CompositeSolid") {
      g.type = CityGeometryType::kCompositeSolid;
      solids = true;
    } else if (t == "MultiSurface") {
      g.type = CityGeometryType::kMultiSurface;
    } else if (t == "CompositeSurface") {
      g.type =
          object_type == "TINRelief" ? CityGeometryType::kTin : CityGeometryType::kCompositeSurface;
    } else if (t == "MultiPoint" || t == "MultiLineString") {
      out->skip_reason = t + " geometry";
      return absl::OkStatus();
    } else {
      out->skip_reason = "geometry with unknown type";
      return absl::OkStatus();
    }
    const auto lod = j.find("lod");
    if (lod == j.end()) return Invalid(name_, path, "no \"lod\"");
    if (lod->is_string()) {
      g.lod = lod->get<std::string>();
    } else if (lod->is_number()) {
      g.lod = lod->dump();
    } else {
      return Invalid(name_, path.Member("lod"), Expected("a level of detail", *lod));
    }
    const auto boundaries = j.find("boundaries");
    if (boundaries == j.end()) return Invalid(name_, path, "no \"boundaries\"");
    const Rings rings{this, verts, verts_name, counts};
    const JsonPath bpath = path.Member("boundaries");
    absl::Status s;
    if (t == "Solid") {
      g.solids.emplace_back();
      s = rings.Solid(*boundaries, bpath, &g.solids.back());
    } else if (solids) {
      s = rings.Array(*boundaries, bpath, "solids", [&](const Json& e, const JsonPath& p) {
        g.solids.emplace_back();
        return rings.Solid(e, p, &g.solids.back());
      });
    } else {
      s = rings.Shell(*boundaries, bpath, "surfaces", &g.surfaces);
    }
    if (!s.ok()) return s;
    out->geometry = std::move(g);
    return absl::OkStatus();
  }

  absl::Status ReadInstance(const Json& j, const JsonPath& path, ParsedGeometry* out,
                            ObjectCounts* counts) {
    const auto tmpl = j.find("template");
    if (tmpl == j.end()) return Invalid(name_, path, "no \"template\"");
    if (!tmpl->is_number_unsigned())
      return Invalid(name_, path.Member("template"), Expected("a template index", *tmpl));
    const uint64_t index = tmpl->get<uint64_t>();
    const size_t count = templates_ == nullptr ? 0 : templates_->size();
    if (index >= count) {
      return Invalid(
          name_, path.Member("template"),
          absl::StrCat("template ", index, " is out of range (", count, " geometry templates)"));
    }
    const auto boundaries = j.find("boundaries");
    if (boundaries == j.end()) return Invalid(name_, path, "no \"boundaries\"");
    if (!boundaries->is_array() || boundaries->size() != 1) {
      return Invalid(name_, path.Member("boundaries"),
                     Expected("[the reference point's vertex index]", *boundaries));
    }
    glm::dvec3 reference;
    const Rings rings{this, vertices_, "vertices", counts};
    if (absl::Status s =
            rings.Vertex((*boundaries)[0], path.Member("boundaries").At(0), &reference);
        !s.ok())
      return s;
    const auto matrix = j.find("transformationMatrix");
    if (matrix == j.end()) return Invalid(name_, path, "no \"transformationMatrix\"");
    if (!matrix->is_array() || matrix->size() != 16) {
      return Invalid(name_, path.Member("transformationMatrix"),
                     Expected("an array of 16 numbers", *matrix));
    }
    double m[16];
    for (size_t i = 0; i < 16; ++i) {
      const Json& e = (*matrix)[i];
      if (!e.is_number())
        return Invalid(name_, path.Member("transformationMatrix").At(i), Expected("a number", e));
      m[i] = e.get<double>();
    }

    // The template, parsed once; its repairs are counted for every instance placed.
    TemplateEntry& entry = template_cache_[index];
    if (!entry.parsed) {
      entry.parsed = true;
      // Each step named: a JsonPath points at its parent, which must outlive it.
      const JsonPath troot;
      const JsonPath tgroup = troot.Member("geometry-templates");
      const JsonPath tlist = tgroup.Member("templates");
      const JsonPath tpath = tlist.At(index);
      const Json& tj = (*templates_)[index];
      if (!tj.is_object()) {
        entry.status = Invalid(name_, tpath, Expected("a geometry object", tj));
      } else if (const auto tt = tj.find("type"); tt == tj.end() || !tt->is_string()) {
        entry.status = Invalid(name_, tpath, "no \"type\" string");
      } else if (tt->get_ref<const std::string&>() == "GeometryInstance") {
        entry.status = Invalid(name_, tpath, "a template cannot be a GeometryInstance");
      } else {
        entry.status = ReadPlainGeometry(tj, tpath, "", template_vertices_, "template vertices",
                                         &entry.geometry, &entry.counts);
      }
    }
    if (!entry.status.ok()) {
      // "<name>: geometry-templates.templates[0]...: what" below the instance's own path.
      std::string what(entry.status.message());
      if (what.starts_with(name_ + ": ")) what.erase(0, name_.size() + 2);
      return Invalid(name_, path, absl::StrCat("template ", index, ": ", what));
    }
    for (const auto& [reason, n] : entry.counts.repaired) counts->repaired[reason] += n;
    if (!entry.geometry.geometry) {
      out->skip_reason = entry.geometry.skip_reason;
      return absl::OkStatus();
    }
    CityGeometry g = *entry.geometry.geometry;
    // Row-major: x' = m[0] x + m[1] y + m[2] z + m[3], ...; then the reference point.
    bool finite = true;
    auto place = [&](glm::dvec3& p) {
      const glm::dvec3 q(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3],
                         m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                         m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
      p = q + reference;
      finite = finite && std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
    };
    auto place_surface = [&](CitySurface& s) {
      for (glm::dvec3& p : s.outer) place(p);
      for (auto& h : s.holes) {
        for (glm::dvec3& p : h) place(p);
      }
    };
    for (CitySurface& s : g.surfaces) place_surface(s);
    for (CitySolid& solid : g.solids) {
      for (auto& shell : solid.shells) {
        for (CitySurface& s : shell) place_surface(s);
      }
    }
    if (!finite) {
      return Invalid(name_, path.Member("transformationMatrix"),
                     absl::StrCat("template ", index, " placed at ", Point(reference),
                                  " has coordinates that are not finite"));
    }
    out->geometry = std::move(g);
    return absl::OkStatus();
  }

  // The nested boundary arrays of one geometry, indices into `verts`.
  struct Rings {
    Reader* reader;
    const std::vector<glm::dvec3>& verts;
    const char* verts_name;
    ObjectCounts* counts;

    absl::Status Fail(const JsonPath& path, const std::string& what) const {
      return Invalid(reader->name_, path, what);
    }

    // A non-empty array, `each` called on every element.
    template <typename Each>
    absl::Status Array(const Json& j, const JsonPath& path, const std::string& of,
                       Each&& each) const {
      if (!j.is_array()) return Fail(path, Expected(absl::StrCat("an array of ", of), j));
      if (j.empty()) return Fail(path, absl::StrCat("empty: no ", of));
      for (size_t i = 0; i < j.size(); ++i) {
        if (absl::Status s = each(j[i], path.At(i)); !s.ok()) return s;
      }
      return absl::OkStatus();
    }

    absl::Status Vertex(const Json& j, const JsonPath& path, glm::dvec3* out) const {
      if (!j.is_number_unsigned()) return Fail(path, Expected("a vertex index", j));
      const uint64_t i = j.get<uint64_t>();
      if (i >= verts.size()) {
        return Fail(path, absl::StrCat("vertex index ", i, " is out of range (", verts.size(), " ",
                                       verts_name, ")"));
      }
      *out = verts[i];
      if (!std::isfinite(out->x) || !std::isfinite(out->y) || !std::isfinite(out->z)) {
        return Fail(
            path, absl::StrCat("vertex ", i, " is not finite after the transform: ", Point(*out)));
      }
      return absl::OkStatus();
    }

    absl::Status Ring(const Json& j, const JsonPath& path, std::vector<glm::dvec3>* out) const {
      if (!j.is_array()) return Fail(path, Expected("a ring (an array of vertex indices)", j));
      out->resize(j.size());
      for (size_t i = 0; i < j.size(); ++i) {
        if (absl::Status s = Vertex(j[i], path.At(i), &(*out)[i]); !s.ok()) return s;
      }
      if (out->size() >= 2 && out->front() == out->back()) {
        out->pop_back();
        ++counts->repaired[std::string(kClosedRing)];
      }
      if (out->size() < 3) {
        return Fail(path,
                    absl::StrCat("ring of ", out->size(), out->size() == 1 ? " point" : " points",
                                 " (at least 3 needed)"));
      }
      return absl::OkStatus();
    }

    absl::Status Surface(const Json& j, const JsonPath& path, CitySurface* out) const {
      size_t r = 0;
      return Array(j, path, "rings", [&](const Json& e, const JsonPath& p) {
        if (r++ == 0) return Ring(e, p, &out->outer);
        out->holes.emplace_back();
        return Ring(e, p, &out->holes.back());
      });
    }

    absl::Status Shell(const Json& j, const JsonPath& path, const std::string& of,
                       std::vector<CitySurface>* out) const {
      if (j.is_array()) out->reserve(j.size());
      return Array(j, path, of, [&](const Json& e, const JsonPath& p) {
        out->emplace_back();
        return Surface(e, p, &out->back());
      });
    }

    absl::Status Solid(const Json& j, const JsonPath& path, CitySolid* out) const {
      return Array(j, path, "shells", [&](const Json& e, const JsonPath& p) {
        out->shells.emplace_back();
        return Shell(e, p, "surfaces", &out->shells.back());
      });
    }
  };

  struct TemplateEntry {
    bool parsed = false;
    absl::Status status;
    ParsedGeometry geometry;
    ObjectCounts counts;
  };

  std::string name_;
  const CityReadOptions& options_;
  RunControl run_;
  std::vector<glm::dvec3> vertices_;
  std::vector<glm::dvec3> template_vertices_;
  const Json* templates_ = nullptr;
  std::vector<TemplateEntry> template_cache_;
};

}  // namespace

absl::StatusOr<CityModel> ReadCityJsonFromMemory(std::string_view bytes, const std::string& name,
                                                 const CityReadOptions& options) {
  return Reader(name, options, RunControl{}).Read(bytes);
}

absl::StatusOr<CityModel> ReadCityJson(const std::string& path, const CityReadOptions& options,
                                       const RunControl& run) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec))
    return absl::NotFoundError(absl::StrCat(path, ": no such file"));
  if (std::filesystem::is_directory(path, ec)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": is a folder, not a CityJSON file"));
  }
  std::string bytes;
  try {
    std::ifstream in(path, std::ios::binary);
    if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open file"));
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    if (in.bad()) return absl::DataLossError(absl::StrCat(path, ": read error"));
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(absl::StrCat(path, ": out of memory reading the file"));
  }
  return Reader(path, options, run).Read(bytes);
}

}  // namespace vistream::scenes
