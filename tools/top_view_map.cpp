#include "tools/top_view_map.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include <cairo.h>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "tools/cli_common.h"

namespace vistream::tools {

namespace {

constexpr Rgb kInk{25, 25, 25};       // text and marks: near-black, never the frame's pure black
constexpr Rgb kFrame{0, 0, 0};
constexpr Rgb kPaper{255, 255, 255};  // around the map
constexpr const char* kFont = "DejaVu Sans";

void Colour(cairo_t* cr, Rgb c) { cairo_set_source_rgb(cr, c.r / 255.0, c.g / 255.0, c.b / 255.0); }

enum class Align { kLeft, kCentre, kRight };

// Text with its baseline at y; returns its width in pixels.
double Text(cairo_t* cr, double x, double y, const std::string& s, double size, Align align = Align::kLeft,
            bool bold = false) {
  cairo_select_font_face(cr, kFont, CAIRO_FONT_SLANT_NORMAL, bold ? CAIRO_FONT_WEIGHT_BOLD : CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, size);
  cairo_text_extents_t e;
  cairo_text_extents(cr, s.c_str(), &e);
  const double dx = align == Align::kLeft ? 0.0 : align == Align::kCentre ? -0.5 * e.x_advance : -e.x_advance;
  cairo_move_to(cr, x + dx, y);
  Colour(cr, kInk);
  cairo_show_text(cr, s.c_str());
  cairo_new_path(cr);
  return e.x_advance;
}

double TextWidth(cairo_t* cr, const std::string& s, double size) {
  cairo_select_font_face(cr, kFont, CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, size);
  cairo_text_extents_t e;
  cairo_text_extents(cr, s.c_str(), &e);
  return e.x_advance;
}

// "1,234" style for tick labels and lengths; negative numbers with a minus sign.
std::string Number(double v) {
  if (std::abs(v) < 1e-9) return "0";
  if (std::abs(v) >= 1.0 && std::abs(v - std::round(v)) < 1e-9) {
    const auto n = static_cast<long long>(std::llround(std::abs(v)));
    std::string digits = std::to_string(n), out;
    for (size_t i = 0; i < digits.size(); ++i) {
      if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
      out += digits[i];
    }
    return (v < 0 ? "\xe2\x88\x92" : "") + out;  // U+2212 minus
  }
  return absl::StrFormat("%g", v);
}

std::string Length(double metres) {
  return metres >= 1000.0 ? absl::StrCat(Number(metres / 1000.0), " km") : absl::StrCat(Number(metres), " m");
}

}  // namespace

void DrawVisibleSet(const scenes::Scene& scene, std::span<const scenes::ObjectId> visible,
                    std::span<const glm::dvec2> region, const VisibleSetLegend& legend, TopViewMap* map) {
  std::vector<bool> in(scene.objects.size(), false);
  for (scenes::ObjectId id : visible) in[id] = true;
  const Rgb in_set{40, 90, 220}, hidden{215, 50, 40}, region_fill{30, 200, 60}, outline{60, 60, 60};
  for (const auto& oc : scene.occluders) map->FillPolygon(oc.footprint, in[oc.object] ? in_set : hidden);
  const bool outlines = map->outlines_readable();
  if (outlines) {
    for (const auto& oc : scene.occluders) map->StrokePolygon(oc.footprint, outline);
  }
  map->FillPolygon(region, region_fill);
  map->StrokePolygon(region, Rgb{0, 120, 30}, 2.0);
  map->AddLegend(region_fill, legend.region);
  map->AddLegend(in_set, legend.in_set);
  map->AddLegend(hidden, legend.hidden);
  if (outlines) map->AddLegend(outline, "building footprint edge", Swatch::kOutline);
}

double RoundDown125(double x) {
  if (!(x > 0) || !std::isfinite(x)) return 1.0;
  const double p = std::pow(10.0, std::floor(std::log10(x)));
  for (double m : {5.0, 2.0, 1.0}) {
    if (m * p <= x * (1 + 1e-12)) return m * p;
  }
  return p;
}

struct TopViewMap::Layout {
  double left, top, bottom, panel;  // margins in pixels
  int width, height;                // the whole image
};

TopViewMap::TopViewMap(const scenes::Aabb& bounds, int max_pixels, Rgb background) {
  const double w = std::max(bounds.max.x - bounds.min.x, 1e-6);
  const double h = std::max(bounds.max.y - bounds.min.y, 1e-6);
  max_pixels = std::clamp(max_pixels, 16, 16384);
  scale_ = std::max(w, h) / max_pixels;
  // The longer side is max_pixels exactly: w / (w / n) can round to a hair above n.
  width_ = std::max(1, static_cast<int>(std::ceil(w / scale_ - 1e-6)));
  height_ = std::max(1, static_cast<int>(std::ceil(h / scale_ - 1e-6)));
  min_ = glm::dvec2(bounds.min.x, bounds.min.y);
  ui_ = std::clamp(max_pixels / 1200.0, 0.8, 3.0);
  surface_ = cairo_image_surface_create(CAIRO_FORMAT_RGB24, width_, height_);
  cr_ = cairo_create(surface_);
  SetColour(background);
  cairo_paint(cr_);
  cairo_set_fill_rule(cr_, CAIRO_FILL_RULE_EVEN_ODD);
  cairo_set_line_join(cr_, CAIRO_LINE_JOIN_ROUND);
  cairo_set_line_cap(cr_, CAIRO_LINE_CAP_ROUND);
}

TopViewMap::~TopViewMap() {
  cairo_destroy(cr_);
  cairo_surface_destroy(surface_);
}

glm::dvec2 TopViewMap::PixelFromScene(const glm::dvec2& p) const {
  return {(p.x - min_.x) / scale_, height_ - (p.y - min_.y) / scale_};
}

void TopViewMap::SetColour(Rgb c) { Colour(cr_, c); }

void TopViewMap::TracePolygon(std::span<const glm::dvec2> polygon) {
  for (const glm::dvec2& p : polygon) {
    const glm::dvec2 q = PixelFromScene(p);
    cairo_line_to(cr_, q.x, q.y);
  }
  cairo_close_path(cr_);
}

void TopViewMap::FillPolygon(std::span<const glm::dvec2> polygon, Rgb colour, bool antialias) {
  if (polygon.size() < 3) return;
  TracePolygon(polygon);
  SetColour(colour);
  cairo_set_antialias(cr_, antialias ? CAIRO_ANTIALIAS_DEFAULT : CAIRO_ANTIALIAS_NONE);
  cairo_fill(cr_);
  cairo_set_antialias(cr_, CAIRO_ANTIALIAS_DEFAULT);
}

void TopViewMap::StrokePolygon(std::span<const glm::dvec2> polygon, Rgb colour, double width_px) {
  if (polygon.size() < 2) return;
  TracePolygon(polygon);
  SetColour(colour);
  cairo_set_line_width(cr_, width_px);
  cairo_stroke(cr_);
}

void TopViewMap::Line(const glm::dvec2& a, const glm::dvec2& b, Rgb colour, double width_px) {
  const glm::dvec2 pa = PixelFromScene(a), pb = PixelFromScene(b);
  cairo_move_to(cr_, pa.x, pa.y);
  cairo_line_to(cr_, pb.x, pb.y);
  SetColour(colour);
  cairo_set_line_width(cr_, width_px);
  cairo_stroke(cr_);
}

void TopViewMap::SetTitle(std::string title, std::string subtitle) {
  title_ = std::move(title);
  subtitle_ = std::move(subtitle);
}

void TopViewMap::AddLegend(Rgb colour, std::string label, Swatch swatch) {
  legend_.push_back({colour, std::move(label), swatch});
}

void TopViewMap::SetColourBar(std::string label, double max_value) {
  bar_label_ = std::move(label);
  bar_max_ = std::max(max_value, 1.0);
}

void TopViewMap::AddNote(std::string note) { notes_.push_back(std::move(note)); }

TopViewMap::Layout TopViewMap::ComputeLayout() const {
  const double u = ui_;
  Layout l;
  l.left = std::round(95 * u);
  l.top = std::round((subtitle_.empty() ? 50 : 72) * u);
  l.bottom = std::round(62 * u);
  l.panel = std::round(400 * u);
  // The panel: heading, entries, colour bar, scale bar, north arrow, notes.
  double panel_h = 40 * u + 26 * u * static_cast<double>(legend_.size());
  if (bar_max_ > 0) panel_h += 270 * u;
  panel_h += 90 * u + 110 * u + 22 * u * static_cast<double>(notes_.size() + 1);
  l.width = static_cast<int>(l.left + width_ + l.panel);
  l.height = static_cast<int>(l.top + std::max<double>(height_, panel_h) + l.bottom);
  return l;
}

int TopViewMap::width() const { return ComputeLayout().width; }
int TopViewMap::height() const { return ComputeLayout().height; }

absl::Status TopViewMap::WritePng(const std::string& path) {
  const Layout l = ComputeLayout();
  const double u = ui_;
  cairo_surface_t* out = cairo_image_surface_create(CAIRO_FORMAT_RGB24, l.width, l.height);
  cairo_t* cr = cairo_create(out);
  Colour(cr, kPaper);
  cairo_paint(cr);
  cairo_surface_flush(surface_);
  cairo_set_source_surface(cr, surface_, l.left, l.top);
  cairo_paint(cr);

  // The frame, pixel-aligned: the map area is [left, left + width) x [top, top + height).
  cairo_set_antialias(cr, CAIRO_ANTIALIAS_NONE);
  Colour(cr, kFrame);
  cairo_set_line_width(cr, 1.0);
  cairo_rectangle(cr, l.left - 0.5, l.top - 0.5, width_ + 1.0, height_ + 1.0);
  cairo_stroke(cr);
  cairo_set_antialias(cr, CAIRO_ANTIALIAS_DEFAULT);

  // Title.
  const double text = 14 * u;
  if (!title_.empty()) Text(cr, l.left, 30 * u, title_, 20 * u, Align::kLeft, true);
  if (!subtitle_.empty()) Text(cr, l.left, 56 * u, subtitle_, text);

  // Axes: scene-local metres (km when the ticks are a kilometre or more apart).
  const double wm = width_ * scale_, hm = height_ * scale_;
  auto axis = [&](bool is_x) {
    const double lo = is_x ? min_.x : min_.y, span = is_x ? wm : hm;
    const double step = RoundDown125(span / 5.0);
    const bool km = step >= 1000.0;
    double last = -1e300;  // the end of the last label along the axis, in pixels from its start
    Colour(cr, kInk);
    cairo_set_line_width(cr, std::max(1.0, u));
    for (double v = std::ceil(lo / step) * step; v <= lo + span + 1e-9 * step; v += step) {
      const double p = (v - lo) / scale_;
      const std::string label = Number(km ? v / 1000.0 : v);
      if (is_x) {
        const double x = l.left + p;
        cairo_move_to(cr, x, l.top + height_ + 1);
        cairo_line_to(cr, x, l.top + height_ + 7 * u);
        cairo_stroke(cr);
        const double w = TextWidth(cr, label, 12 * u);
        if (p - 0.5 * w > last + 8 * u) {
          Text(cr, x, l.top + height_ + 22 * u, label, 12 * u, Align::kCentre);
          last = p + 0.5 * w;
        }
      } else {
        const double y = l.top + height_ - p;
        cairo_move_to(cr, l.left - 1, y);
        cairo_line_to(cr, l.left - 7 * u, y);
        cairo_stroke(cr);
        if (p - 6 * u > last + 8 * u) {
          Text(cr, l.left - 10 * u, y + 4 * u, label, 12 * u, Align::kRight);
          last = p + 6 * u;
        }
      }
    }
    return km;
  };
  const bool x_km = axis(true), y_km = axis(false);
  Text(cr, l.left + 0.5 * width_, l.top + height_ + 46 * u,
       absl::StrCat("x, east (", x_km ? "km" : "m", ", scene-local)"), 13 * u, Align::kCentre);
  cairo_save(cr);
  cairo_translate(cr, 22 * u, l.top + 0.5 * height_);
  cairo_rotate(cr, -M_PI / 2);
  Text(cr, 0, 0, absl::StrCat("y, north (", y_km ? "km" : "m", ", scene-local)"), 13 * u, Align::kCentre);
  cairo_restore(cr);

  // The panel.
  const double px = l.left + width_ + 24 * u;
  const double inner = l.panel - 40 * u;
  double y = l.top + 16 * u;
  Text(cr, px, y, "Legend", 15 * u, Align::kLeft, true);
  y += 24 * u;
  for (const Entry& e : legend_) {
    const double sw = 30 * u, sh = 16 * u;
    cairo_set_antialias(cr, CAIRO_ANTIALIAS_NONE);
    switch (e.swatch) {
      case Swatch::kFill:
        Colour(cr, {120, 120, 120});
        cairo_rectangle(cr, std::round(px), std::round(y - sh + 2), std::round(sw), std::round(sh));
        cairo_fill(cr);
        Colour(cr, e.colour);
        cairo_rectangle(cr, std::round(px) + 1, std::round(y - sh + 2) + 1, std::round(sw) - 2, std::round(sh) - 2);
        cairo_fill(cr);
        break;
      case Swatch::kLine:
        Colour(cr, e.colour);
        cairo_rectangle(cr, std::round(px), std::round(y - 0.5 * sh - 2 * u + 2), std::round(sw), std::round(4 * u));
        cairo_fill(cr);
        break;
      case Swatch::kOutline:
        Colour(cr, e.colour);
        cairo_set_line_width(cr, 1.0);
        cairo_rectangle(cr, std::round(px) + 0.5, std::round(y - sh + 2) + 0.5, std::round(sw) - 1, std::round(sh) - 1);
        cairo_stroke(cr);
        break;
    }
    cairo_set_antialias(cr, CAIRO_ANTIALIAS_DEFAULT);
    Text(cr, px + 40 * u, y, e.label, text);
    y += 26 * u;
  }

  if (bar_max_ > 0) {
    y += 14 * u;
    Text(cr, px, y, bar_label_, text);
    y += 14 * u;
    // Ramp(t) row by row, t = 1 at the top, exact colours (no antialiasing, no gradient).
    const int bar_h = static_cast<int>(std::round(200 * u)), bar_w = static_cast<int>(std::round(28 * u));
    const double bx = std::round(px), by = std::round(y);
    cairo_set_antialias(cr, CAIRO_ANTIALIAS_NONE);
    for (int r = 0; r < bar_h; ++r) {
      Colour(cr, Ramp(1.0 - static_cast<double>(r) / (bar_h - 1)));
      cairo_rectangle(cr, bx, by + r, bar_w, 1);
      cairo_fill(cr);
    }
    cairo_set_antialias(cr, CAIRO_ANTIALIAS_DEFAULT);
    const double top = std::log1p(bar_max_);
    auto tick = [&](double v, const std::string& label) {
      const double ty = by + (bar_h - 1) * (1.0 - std::log1p(v) / top);
      Colour(cr, kInk);
      cairo_set_line_width(cr, std::max(1.0, u));
      cairo_move_to(cr, bx + bar_w, ty);
      cairo_line_to(cr, bx + bar_w + 6 * u, ty);
      cairo_stroke(cr);
      Text(cr, bx + bar_w + 10 * u, ty + 4.5 * u, label, 12 * u);
    };
    // 0, then 1, 2, 5 x 10^k up to the maximum, spaced at least a line apart; the maximum.
    tick(0.0, "0");
    double last = by + bar_h - 1;
    const double max_y = by;
    for (double p = 1.0; p <= bar_max_; p *= 10.0) {
      for (double m : {1.0, 2.0, 5.0}) {
        const double v = m * p;
        if (v > bar_max_) break;
        const double ty = by + (bar_h - 1) * (1.0 - std::log1p(v) / top);
        if (last - ty >= 16 * u && ty - max_y >= 16 * u) {
          tick(v, Number(v));
          last = ty;
        }
      }
    }
    tick(bar_max_, absl::StrCat(Number(std::round(bar_max_)), " (max)"));
    y += bar_h + 24 * u;
  }

  // Scale bar: a round length that fits the panel and is at most a third of the map.
  y += 10 * u;
  Text(cr, px, y, "Scale", 15 * u, Align::kLeft, true);
  y += 14 * u;
  const double length = RoundDown125(std::min(wm / 3.0, inner * scale_));
  const double bar_px = length / scale_;
  cairo_set_antialias(cr, CAIRO_ANTIALIAS_NONE);
  for (int k = 0; k < 4; ++k) {
    Colour(cr, kInk);
    cairo_rectangle(cr, std::round(px + k * bar_px / 4), std::round(y), std::round(bar_px / 4), std::round(10 * u));
    cairo_fill(cr);
    if (k % 2 == 1) {
      Colour(cr, kPaper);
      cairo_rectangle(cr, std::round(px + k * bar_px / 4) + 1, std::round(y) + 1, std::round(bar_px / 4) - 2,
                      std::round(10 * u) - 2);
      cairo_fill(cr);
    }
  }
  cairo_set_antialias(cr, CAIRO_ANTIALIAS_DEFAULT);
  Text(cr, px, y + 28 * u, "0", 12 * u, Align::kCentre);
  Text(cr, px + bar_px / 2, y + 28 * u, Length(length / 2), 12 * u, Align::kCentre);
  Text(cr, px + bar_px, y + 28 * u, Length(length), 12 * u, Align::kCentre);
  y += 56 * u;

  // North arrow.
  const double ax = px + 16 * u, ay = y + 10 * u;
  Colour(cr, kInk);
  cairo_move_to(cr, ax, ay);
  cairo_line_to(cr, ax + 10 * u, ay + 40 * u);
  cairo_line_to(cr, ax, ay + 32 * u);
  cairo_line_to(cr, ax - 10 * u, ay + 40 * u);
  cairo_close_path(cr);
  cairo_fill(cr);
  Text(cr, ax, ay + 60 * u, "N", 14 * u, Align::kCentre, true);
  Text(cr, ax + 24 * u, ay + 24 * u, "north up (+y)", text);
  Text(cr, ax + 24 * u, ay + 44 * u, absl::StrFormat("%.3g m per pixel", scale_), text);
  y += 100 * u;
  for (const std::string& n : notes_) {
    Text(cr, px, y, n, text);
    y += 22 * u;
  }

  cairo_destroy(cr);
  cairo_surface_flush(out);
  // Encoded in memory, then written by WriteFile: through FILE.tmp renamed once whole, so a
  // failed write leaves no half PNG where the map should be.
  std::string png;
  const cairo_status_t st = cairo_surface_write_to_png_stream(
      out,
      [](void* closure, const unsigned char* data, unsigned int size) {
        static_cast<std::string*>(closure)->append(reinterpret_cast<const char*>(data), size);
        return CAIRO_STATUS_SUCCESS;
      },
      &png);
  cairo_surface_destroy(out);
  if (st != CAIRO_STATUS_SUCCESS) {
    return absl::UnavailableError(absl::StrCat("cannot write the PNG '", path, "': ", cairo_status_to_string(st)));
  }
  if (absl::Status w = WriteFile(path, png); !w.ok()) {
    return absl::UnavailableError(absl::StrCat("cannot write the PNG '", path, "': ", w.message()));
  }
  return absl::OkStatus();
}

Rgb Ramp(double t) {
  t = std::clamp(t, 0.0, 1.0);
  // Piecewise-linear through a few viridis-like stops.
  static constexpr double stops[5][3] = {{68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}};
  const double x = t * 4.0;
  const int i = std::min(3, static_cast<int>(x));
  const double f = x - i;
  auto mix = [&](int c) { return static_cast<uint8_t>(std::lround(stops[i][c] + f * (stops[i + 1][c] - stops[i][c]))); };
  return {mix(0), mix(1), mix(2)};
}

}  // namespace vistream::tools
