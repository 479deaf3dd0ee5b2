#pragma once
// Top-view maps of a scene, drawn with Cairo and written as PNG: footprints, viewcells, paths,
// framed by what makes a map readable on its own: a title, scene-local axes in metres, a
// legend of the colours (and a colour bar with labelled ticks for a ramp), a scale bar and a
// north arrow. Used by `vistream scene map`, `pvs --map`, `epsilon --map`, `agvs heatmap`.
//
// Layout of the PNG: the title on top; the map (north up, +y) inside a 1-pixel frame of pure
// black (0, 0, 0), the one pure black in the image (text and marks are near-black), so that a
// reader (or a test) can find the map area; x and y ticks left of and below the frame; the
// legend panel right of it. Legend swatches and the colour bar are drawn without antialiasing,
// so their colours are exact.

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <absl/status/status.h>
#include <glm/vec2.hpp>

#include "scenes/aabb.h"
#include "scenes/scene.h"

// Cairo's types, so that users of the map need not include cairo.h.
struct _cairo;
struct _cairo_surface;

namespace vistream::tools {

struct Rgb {
  uint8_t r = 0, g = 0, b = 0;
  bool operator==(const Rgb&) const = default;
};

// How a legend entry shows its colour.
enum class Swatch {
  kFill,     // a filled box: areas (footprints, viewcells)
  kLine,     // a thick line: paths
  kOutline,  // a thin outline: footprint edges drawn over something else
};

class TopViewMap {
 public:
  // A map of the xy extent of `bounds` (scene-local metres), `max_pixels` on its longer side,
  // north (+y) up, filled with `background`. The PNG adds the title, axes and legend around it.
  TopViewMap(const scenes::Aabb& bounds, int max_pixels, Rgb background);
  ~TopViewMap();
  TopViewMap(const TopViewMap&) = delete;
  TopViewMap& operator=(const TopViewMap&) = delete;

  // The map area, in pixels, and its scale.
  int map_width() const { return width_; }
  int map_height() const { return height_; }
  double metres_per_pixel() const { return scale_; }
  // Whether footprint outlines read at this scale: a pixel under kOutlineMetresPerPixel. On a
  // coarser map a street is a pixel or two, the strokes of neighbouring buildings merge into
  // noise, and that noise is most of the PNG's bytes (london at 9 m a pixel: several MB).
  static constexpr double kOutlineMetresPerPixel = 1.5;
  bool outlines_readable() const { return scale_ < kOutlineMetresPerPixel; }
  // The whole image WritePng writes (map, frame, title, axes, legend).
  int width() const;
  int height() const;

  // Antialiased drawing in scene-local metres. Polygons: any orientation, even-odd rule.
  // `antialias` false keeps the edges of touching squares (a viewcell grid) seamless.
  void FillPolygon(std::span<const glm::dvec2> polygon, Rgb colour, bool antialias = true);
  // Line widths in pixels.
  void StrokePolygon(std::span<const glm::dvec2> polygon, Rgb colour, double width_px = 1.0);
  void Line(const glm::dvec2& a, const glm::dvec2& b, Rgb colour, double width_px = 1.0);

  // The title (what scene, what it shows) and a second line (what cell or box, what figures).
  void SetTitle(std::string title, std::string subtitle = "");
  // One legend row: the colour and what it means.
  void AddLegend(Rgb colour, std::string label, Swatch swatch = Swatch::kFill);
  // A colour bar for values drawn with Ramp(log1p(v) / log1p(max_value)): `label` names the
  // quantity and its unit, e.g. "building height (m, log scale)".
  void SetColourBar(std::string label, double max_value);
  // A last line in the legend panel (e.g. counts).
  void AddNote(std::string note);

  // Composes the image and writes it (to `path`.tmp, renamed over `path`: a failed write
  // leaves what was there). Errors name the path.
  absl::Status WritePng(const std::string& path);

 private:
  struct Layout;
  glm::dvec2 PixelFromScene(const glm::dvec2& p) const;
  void SetColour(Rgb c);
  // The closed polygon (scene-local metres) as Cairo's current path, in pixels.
  void TracePolygon(std::span<const glm::dvec2> polygon);
  Layout ComputeLayout() const;

  glm::dvec2 min_;
  double scale_ = 1.0;  // metres per pixel
  int width_ = 1, height_ = 1;
  double ui_ = 1.0;  // size of text and marks relative to a 1200-pixel map
  _cairo_surface* surface_ = nullptr;
  _cairo* cr_ = nullptr;

  std::string title_, subtitle_;
  struct Entry {
    Rgb colour;
    std::string label;
    Swatch swatch;
  };
  std::vector<Entry> legend_;
  std::string bar_label_;
  double bar_max_ = 0.0;
  std::vector<std::string> notes_;
};

// The legend rows of a visible-set map (DrawVisibleSet): what the region is, and what a
// footprint in the set and one not in it mean.
struct VisibleSetLegend {
  std::string region, in_set, hidden;
};

// The objects visible from one region (a viewcell, an ε-neighbourhood) on `map`: each occluder
// footprint of `scene` blue when its object is in `visible`, red when not, outlined where the
// scale lets outlines read (outlines_readable); then `region` (scene-local metres) green over
// them. Adds the legend rows region, in set, hidden, and the outline's when drawn; the caller
// sets the title and writes the PNG.
void DrawVisibleSet(const scenes::Scene& scene, std::span<const scenes::ObjectId> visible,
                    std::span<const glm::dvec2> region, const VisibleSetLegend& legend, TopViewMap* map);

// A perceptually ordered colour ramp for t in [0, 1] (viridis-like: dark violet, teal, yellow).
Rgb Ramp(double t);

// The largest 1, 2 or 5 times a power of ten that is at most `x` (x > 0): scale-bar lengths
// and tick steps.
double RoundDown125(double x);

}  // namespace vistream::tools
