#include "plot.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include <png.h>

namespace lpoe {
namespace tools {
namespace {

// ---------------------------------------------------------------------------------------------
// 5x7 bitmap font, printable ASCII 0x20..0x7E. Five columns per glyph, bit 0 = top row; rows 0..6
// sit on the baseline, rows 7..8 are descenders (g, j, p, q, y).

constexpr int kGlyphW = 5;
constexpr int kGlyphH = 7;       // cap height (layout unit)
constexpr int kGlyphRows = 9;    // including descenders
constexpr int kGlyphAdvance = 6;  // one column of spacing

const uint16_t kFont[95][5] = {
    {0x00, 0x00, 0x00, 0x00, 0x00},  // ' '
    {0x00, 0x00, 0x5F, 0x00, 0x00},  // !
    {0x00, 0x07, 0x00, 0x07, 0x00},  // "
    {0x14, 0x7F, 0x14, 0x7F, 0x14},  // #
    {0x24, 0x2A, 0x7F, 0x2A, 0x12},  // $
    {0x23, 0x13, 0x08, 0x64, 0x62},  // %
    {0x36, 0x49, 0x55, 0x22, 0x50},  // &
    {0x00, 0x05, 0x03, 0x00, 0x00},  // '
    {0x00, 0x1C, 0x22, 0x41, 0x00},  // (
    {0x00, 0x41, 0x22, 0x1C, 0x00},  // )
    {0x08, 0x2A, 0x1C, 0x2A, 0x08},  // *
    {0x08, 0x08, 0x3E, 0x08, 0x08},  // +
    {0x00, 0x50, 0x30, 0x00, 0x00},  // ,
    {0x08, 0x08, 0x08, 0x08, 0x08},  // -
    {0x00, 0x60, 0x60, 0x00, 0x00},  // .
    {0x20, 0x10, 0x08, 0x04, 0x02},  // /
    {0x3E, 0x51, 0x49, 0x45, 0x3E},  // 0
    {0x00, 0x42, 0x7F, 0x40, 0x00},  // 1
    {0x42, 0x61, 0x51, 0x49, 0x46},  // 2
    {0x21, 0x41, 0x45, 0x4B, 0x31},  // 3
    {0x18, 0x14, 0x12, 0x7F, 0x10},  // 4
    {0x27, 0x45, 0x45, 0x45, 0x39},  // 5
    {0x3C, 0x4A, 0x49, 0x49, 0x30},  // 6
    {0x01, 0x71, 0x09, 0x05, 0x03},  // 7
    {0x36, 0x49, 0x49, 0x49, 0x36},  // 8
    {0x06, 0x49, 0x49, 0x29, 0x1E},  // 9
    {0x00, 0x36, 0x36, 0x00, 0x00},  // :
    {0x00, 0x56, 0x36, 0x00, 0x00},  // ;
    {0x08, 0x14, 0x22, 0x41, 0x00},  // <
    {0x14, 0x14, 0x14, 0x14, 0x14},  // =
    {0x00, 0x41, 0x22, 0x14, 0x08},  // >
    {0x02, 0x01, 0x51, 0x09, 0x06},  // ?
    {0x32, 0x49, 0x79, 0x41, 0x3E},  // @
    {0x7E, 0x11, 0x11, 0x11, 0x7E},  // A
    {0x7F, 0x49, 0x49, 0x49, 0x36},  // B
    {0x3E, 0x41, 0x41, 0x41, 0x22},  // C
    {0x7F, 0x41, 0x41, 0x22, 0x1C},  // D
    {0x7F, 0x49, 0x49, 0x49, 0x41},  // E
    {0x7F, 0x09, 0x09, 0x09, 0x01},  // F
    {0x3E, 0x41, 0x49, 0x49, 0x7A},  // G
    {0x7F, 0x08, 0x08, 0x08, 0x7F},  // H
    {0x00, 0x41, 0x7F, 0x41, 0x00},  // I
    {0x20, 0x40, 0x41, 0x3F, 0x01},  // J
    {0x7F, 0x08, 0x14, 0x22, 0x41},  // K
    {0x7F, 0x40, 0x40, 0x40, 0x40},  // L
    {0x7F, 0x02, 0x0C, 0x02, 0x7F},  // M
    {0x7F, 0x04, 0x08, 0x10, 0x7F},  // N
    {0x3E, 0x41, 0x41, 0x41, 0x3E},  // O
    {0x7F, 0x09, 0x09, 0x09, 0x06},  // P
    {0x3E, 0x41, 0x51, 0x21, 0x5E},  // Q
    {0x7F, 0x09, 0x19, 0x29, 0x46},  // R
    {0x46, 0x49, 0x49, 0x49, 0x31},  // S
    {0x01, 0x01, 0x7F, 0x01, 0x01},  // T
    {0x3F, 0x40, 0x40, 0x40, 0x3F},  // U
    {0x1F, 0x20, 0x40, 0x20, 0x1F},  // V
    {0x3F, 0x40, 0x38, 0x40, 0x3F},  // W
    {0x63, 0x14, 0x08, 0x14, 0x63},  // X
    {0x07, 0x08, 0x70, 0x08, 0x07},  // Y
    {0x61, 0x51, 0x49, 0x45, 0x43},  // Z
    {0x00, 0x7F, 0x41, 0x41, 0x00},  // [
    {0x02, 0x04, 0x08, 0x10, 0x20},  // backslash
    {0x00, 0x41, 0x41, 0x7F, 0x00},  // ]
    {0x04, 0x02, 0x01, 0x02, 0x04},  // ^
    {0x40, 0x40, 0x40, 0x40, 0x40},  // _
    {0x00, 0x01, 0x02, 0x04, 0x00},  // `
    {0x20, 0x54, 0x54, 0x54, 0x78},  // a
    {0x7F, 0x48, 0x44, 0x44, 0x38},  // b
    {0x38, 0x44, 0x44, 0x44, 0x20},  // c
    {0x38, 0x44, 0x44, 0x48, 0x7F},  // d
    {0x38, 0x54, 0x54, 0x54, 0x18},  // e
    {0x08, 0x7E, 0x09, 0x01, 0x02},  // f
    {0x038, 0x144, 0x144, 0x144, 0x0FC},  // g
    {0x7F, 0x08, 0x04, 0x04, 0x78},  // h
    {0x00, 0x44, 0x7D, 0x40, 0x00},  // i
    {0x080, 0x100, 0x104, 0x0FD, 0x000},  // j
    {0x7F, 0x10, 0x28, 0x44, 0x00},  // k
    {0x00, 0x41, 0x7F, 0x40, 0x00},  // l
    {0x7C, 0x04, 0x18, 0x04, 0x78},  // m
    {0x7C, 0x08, 0x04, 0x04, 0x78},  // n
    {0x38, 0x44, 0x44, 0x44, 0x38},  // o
    {0x1FC, 0x044, 0x044, 0x044, 0x038},  // p
    {0x038, 0x044, 0x044, 0x044, 0x1FC},  // q
    {0x7C, 0x08, 0x04, 0x04, 0x08},  // r
    {0x48, 0x54, 0x54, 0x54, 0x20},  // s
    {0x04, 0x3F, 0x44, 0x40, 0x20},  // t
    {0x3C, 0x40, 0x40, 0x20, 0x7C},  // u
    {0x1C, 0x20, 0x40, 0x20, 0x1C},  // v
    {0x3C, 0x40, 0x30, 0x40, 0x3C},  // w
    {0x44, 0x28, 0x10, 0x28, 0x44},  // x
    {0x03C, 0x140, 0x140, 0x140, 0x0FC},  // y
    {0x44, 0x64, 0x54, 0x4C, 0x44},  // z
    {0x00, 0x08, 0x36, 0x41, 0x00},  // {
    {0x00, 0x00, 0x7F, 0x00, 0x00},  // |
    {0x00, 0x41, 0x36, 0x08, 0x00},  // }
    {0x08, 0x04, 0x08, 0x10, 0x08},  // ~
};

int TextWidth(const std::string& s, int scale) {
  return s.empty() ? 0 : static_cast<int>(s.size()) * kGlyphAdvance * scale - scale;
}
int TextHeight(int scale) { return kGlyphH * scale; }

// Colors used by the frame.
constexpr uint32_t kInk = 0x222222;
constexpr uint32_t kFrame = 0x444444;
constexpr uint32_t kGrid = 0xE3E3E3;
constexpr uint32_t kMinorGrid = 0xF1F1F1;
constexpr uint32_t kMuted = 0x888888;

constexpr int kScale = 2;  // text scale: 10x14 pixel glyphs

// ---------------------------------------------------------------------------------------------
// Canvas: an RGB8 image with a clip rectangle, alpha blending and a coverage layer for
// anti-aliased polylines (max coverage per pixel, composited once, so joints do not darken).

struct Rect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // [x0, x1) x [y0, y1)
  int w() const { return x1 - x0; }
  int h() const { return y1 - y0; }
};

class Canvas {
 public:
  Canvas(int w, int h) : w_(w), h_(h), pix_(static_cast<size_t>(w) * h * 3, 255) { ResetClip(); }

  int width() const { return w_; }
  int height() const { return h_; }
  const uint8_t* data() const { return pix_.data(); }

  void SetClip(const Rect& r) {
    clip_.x0 = std::max(0, r.x0);
    clip_.y0 = std::max(0, r.y0);
    clip_.x1 = std::min(w_, r.x1);
    clip_.y1 = std::min(h_, r.y1);
  }
  void ResetClip() { clip_ = Rect{0, 0, w_, h_}; }

  void Blend(int x, int y, uint32_t rgb, double a) {
    if (x < clip_.x0 || x >= clip_.x1 || y < clip_.y0 || y >= clip_.y1 || !(a > 0)) return;
    a = std::min(a, 1.0);
    uint8_t* p = &pix_[(static_cast<size_t>(y) * w_ + x) * 3];
    const double c[3] = {double((rgb >> 16) & 0xFF), double((rgb >> 8) & 0xFF),
                         double(rgb & 0xFF)};
    for (int k = 0; k < 3; ++k) p[k] = static_cast<uint8_t>(std::lround(p[k] + a * (c[k] - p[k])));
  }

  void FillRect(int x0, int y0, int x1, int y1, uint32_t rgb, double a = 1.0) {
    if (x0 > x1) std::swap(x0, x1);
    if (y0 > y1) std::swap(y0, y1);
    for (int y = std::max(y0, clip_.y0); y < std::min(y1, clip_.y1); ++y)
      for (int x = std::max(x0, clip_.x0); x < std::min(x1, clip_.x1); ++x) Blend(x, y, rgb, a);
  }
  void HLine(int x0, int x1, int y, uint32_t rgb) { FillRect(x0, y, x1 + 1, y + 1, rgb); }
  void VLine(int x, int y0, int y1, uint32_t rgb) { FillRect(x, y0, x + 1, y1 + 1, rgb); }
  void StrokeRect(const Rect& r, uint32_t rgb) {
    HLine(r.x0, r.x1 - 1, r.y0, rgb);
    HLine(r.x0, r.x1 - 1, r.y1 - 1, rgb);
    VLine(r.x0, r.y0, r.y1 - 1, rgb);
    VLine(r.x1 - 1, r.y0, r.y1 - 1, rgb);
  }

  // Text with its top-left corner at (x, y).
  void Text(int x, int y, const std::string& s, int scale, uint32_t rgb, bool bold = false) {
    ForEachTextPixel(s, scale, [&](int px, int py) {
      FillRect(x + px, y + py, x + px + scale + (bold ? 1 : 0), y + py + scale, rgb);
    });
  }
  // Text rotated 90 degrees counter-clockwise (reads bottom to top); (x, y) is the top-left
  // corner of its bounding box, which is TextHeight wide and TextWidth tall.
  void TextUp(int x, int y, const std::string& s, int scale, uint32_t rgb) {
    const int len = TextWidth(s, scale);
    ForEachTextPixel(s, scale, [&](int px, int py) {
      // Horizontal (px, py) -> rotated (py, len - px - scale).
      FillRect(x + py, y + len - px - scale, x + py + scale, y + len - px, rgb);
    });
  }

  // Coverage layer for anti-aliased thick lines.
  void BeginLayer() { cov_.assign(static_cast<size_t>(w_) * h_, 0.0f); }
  void LayerLine(double x0, double y0, double x1, double y1, double width) {
    const double hw = 0.5 * width;
    const double dx = x1 - x0, dy = y1 - y0;
    const double len2 = dx * dx + dy * dy;
    const int bx0 = std::max(clip_.x0, static_cast<int>(std::floor(std::min(x0, x1) - hw - 1)));
    const int bx1 = std::min(clip_.x1 - 1, static_cast<int>(std::ceil(std::max(x0, x1) + hw + 1)));
    const int by0 = std::max(clip_.y0, static_cast<int>(std::floor(std::min(y0, y1) - hw - 1)));
    const int by1 = std::min(clip_.y1 - 1, static_cast<int>(std::ceil(std::max(y0, y1) + hw + 1)));
    if (bx0 > bx1 || by0 > by1) return;
    const bool x_major = std::abs(dx) >= std::abs(dy);
    const double len = std::sqrt(len2);
    // Half-extent of the band in the minor direction.
    const double band = len > 0 ? hw * len / std::max(std::abs(x_major ? dx : dy), 1e-12) + 2 : hw + 2;
    auto visit = [&](int x, int y) {
      double t = len2 > 0 ? ((x - x0) * dx + (y - y0) * dy) / len2 : 0.0;
      t = std::clamp(t, 0.0, 1.0);
      const double ex = x0 + t * dx - x, ey = y0 + t * dy - y;
      const double c = std::clamp(hw + 0.5 - std::sqrt(ex * ex + ey * ey), 0.0, 1.0);
      float& dst = cov_[static_cast<size_t>(y) * w_ + x];
      dst = std::max(dst, static_cast<float>(c));
    };
    if (x_major) {
      for (int x = bx0; x <= bx1; ++x) {
        const double t = std::abs(dx) > 0 ? std::clamp((x - x0) / dx, 0.0, 1.0) : 0.0;
        const double yc = y0 + t * dy;
        for (int y = std::max(by0, static_cast<int>(std::floor(yc - band)));
             y <= std::min(by1, static_cast<int>(std::ceil(yc + band))); ++y)
          visit(x, y);
      }
    } else {
      for (int y = by0; y <= by1; ++y) {
        const double t = std::abs(dy) > 0 ? std::clamp((y - y0) / dy, 0.0, 1.0) : 0.0;
        const double xc = x0 + t * dx;
        for (int x = std::max(bx0, static_cast<int>(std::floor(xc - band)));
             x <= std::min(bx1, static_cast<int>(std::ceil(xc + band))); ++x)
          visit(x, y);
      }
    }
  }
  void EndLayer(uint32_t rgb) {
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) {
        const float c = cov_[static_cast<size_t>(y) * w_ + x];
        if (c > 0) Blend(x, y, rgb, c);
      }
    cov_.clear();
  }

 private:
  template <typename F>
  static void ForEachTextPixel(const std::string& s, int scale, F f) {
    for (size_t i = 0; i < s.size(); ++i) {
      unsigned char ch = static_cast<unsigned char>(s[i]);
      if (ch < 0x20 || ch > 0x7E) ch = '?';
      const uint16_t* g = kFont[ch - 0x20];
      for (int c = 0; c < kGlyphW; ++c)
        for (int r = 0; r < kGlyphRows; ++r)
          if (g[c] & (1u << r))
            f(static_cast<int>(i) * kGlyphAdvance * scale + c * scale, r * scale);
    }
  }

  int w_, h_;
  std::vector<uint8_t> pix_;
  std::vector<float> cov_;
  Rect clip_;
};

// ---------------------------------------------------------------------------------------------
// Axes: nice linear ticks (1, 2, 5 x 10^k) and log decades.

bool Finite(double v) { return std::isfinite(v); }

double NiceStep(double range, double target) {
  const double raw = range / std::max(target, 1.0);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double norm = raw / mag;
  return (norm < 1.5 ? 1 : norm < 3 ? 2 : norm < 7 ? 5 : 10) * mag;
}

std::string CompactExp(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*e", digits, v);
  std::string s = buf;
  const size_t e = s.find('e');
  if (e == std::string::npos) return s;
  std::string mant = s.substr(0, e), ex = s.substr(e + 1);
  if (mant.find('.') != std::string::npos) {  // 1.50 -> 1.5, 1.0 -> 1
    while (mant.back() == '0') mant.pop_back();
    if (mant.back() == '.') mant.pop_back();
  }
  const bool neg = ex[0] == '-';
  size_t k = (ex[0] == '-' || ex[0] == '+') ? 1 : 0;
  while (k + 1 < ex.size() && ex[k] == '0') ++k;
  return mant + "e" + (neg ? "-" : "") + ex.substr(k);
}

// A tick label for `v` on an axis with tick spacing `step` and largest magnitude `mag`.
std::string FormatTick(double v, double step, double mag) {
  if (std::abs(v) < step * 1e-6) v = 0;
  if (mag >= 1e5 || (mag > 0 && mag < 1e-3)) {
    const int digits = std::clamp(
        static_cast<int>(std::floor(std::log10(mag)) - std::floor(std::log10(step) + 1e-9)), 0, 4);
    return v == 0 ? "0" : CompactExp(v, digits);
  }
  const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  std::string s = buf;
  if (s == "-0" || s.find_first_not_of("-0.") == std::string::npos) s = "0";
  return s;
}

// A plain number for legends and titles: 3 significant digits.
std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

struct Tick {
  double value;  // in data units
  std::string label;
  bool major;
};

struct Axis {
  bool log = false;
  double lo = 0, hi = 1;  // in data units, or log10 of data units when log
  std::vector<Tick> ticks;

  // Fraction along the axis, 0 at lo and 1 at hi.
  double Frac(double v) const {
    const double u = log ? std::log10(v) : v;
    return (u - lo) / (hi - lo);
  }
  int MaxLabelWidth(int scale) const {
    int w = 0;
    for (const Tick& t : ticks) w = std::max(w, TextWidth(t.label, scale));
    return w;
  }
};

// A linear axis covering [dmin, dmax] with ~target ticks. `pad` is the fraction of the range
// added on both sides; `from_zero` pins the lower end to 0 (counts).
// Ticks at multiples of a nice step (about `target` of them) within [lo, hi].
void SetLinearTicks(Axis* a, double target, bool integer) {
  a->ticks.clear();
  double step = NiceStep(a->hi - a->lo, target);
  if (integer) step = std::max(1.0, std::round(step));
  const double mag = std::max(std::abs(a->lo), std::abs(a->hi));
  for (double k = std::ceil(a->lo / step - 1e-9); k * step <= a->hi + 1e-9 * step; k += 1) {
    const double v = k * step;
    a->ticks.push_back({v, FormatTick(v, step, mag), true});
  }
}

Axis LinearAxis(double dmin, double dmax, double target, bool integer, double pad,
                bool from_zero = false) {
  Axis a;
  if (!Finite(dmin) || !Finite(dmax) || dmin > dmax) {
    dmin = 0;
    dmax = 1;
  }
  if (dmax - dmin <= 1e-12 * std::max(std::abs(dmin), std::abs(dmax))) {
    const double p = dmin == 0 ? 1.0 : 0.1 * std::abs(dmin);
    dmin -= p;
    dmax += p;
    if (from_zero && dmin < 0) dmin = 0;
  }
  const double r = dmax - dmin;
  a.lo = from_zero ? 0.0 : dmin - pad * r;
  a.hi = dmax + pad * r;
  SetLinearTicks(&a, target, integer);
  return a;
}

std::string DecadeLabel(int e) {
  if (e >= 0 && e <= 4) return FormatTick(std::pow(10.0, e), 1, 1);
  if (e < 0 && e >= -3) return FormatTick(std::pow(10.0, e), std::pow(10.0, e), 1);
  return "1e" + std::to_string(e);
}

// Decade ticks within [lo, hi] (log10 units), minor ticks at 2..9 (labelled at 2 and 5 when the
// axis spans little more than two decades).
void SetLogTicks(Axis* a) {
  a->ticks.clear();
  const int first = static_cast<int>(std::floor(a->lo)), last = static_cast<int>(std::ceil(a->hi));
  const int elo = static_cast<int>(std::ceil(a->lo - 1e-9));
  const int decades = static_cast<int>(std::floor(a->hi + 1e-9)) - elo;
  const int every = std::max(1, (decades + 7) / 8);
  const bool minor_labels = a->hi - a->lo <= 2.3;
  auto inside = [&](double v) {
    const double u = std::log10(v);
    return u >= a->lo - 1e-9 && u <= a->hi + 1e-9;
  };
  for (int e = first; e <= last; ++e) {
    const double d = std::pow(10.0, e);
    if (inside(d)) a->ticks.push_back({d, (e - elo) % every == 0 ? DecadeLabel(e) : "", true});
    if (decades > 6) continue;
    for (int m = 2; m <= 9; ++m) {
      if (!inside(m * d)) continue;
      std::string label;
      if (minor_labels && (m == 2 || m == 5)) {
        label = (e >= -3 && e <= 3) ? FormatTick(m * d, d, 1) : CompactExp(m * d, 0);
      }
      a->ticks.push_back({m * d, label, false});
    }
  }
}

// A log axis over positive [dmin, dmax], widened to whole decades.
Axis LogAxis(double dmin, double dmax, double pad) {
  Axis a;
  a.log = true;
  if (!(dmin > 0) || !Finite(dmin) || !(dmax >= dmin) || !Finite(dmax)) {
    dmin = 1;
    dmax = 10;
  }
  int elo = static_cast<int>(std::floor(std::log10(dmin) + 1e-9));
  int ehi = static_cast<int>(std::ceil(std::log10(dmax) - 1e-9));
  if (ehi <= elo) ehi = elo + 1;
  const double span = ehi - elo;
  a.lo = elo - pad * span;
  a.hi = ehi + pad * span;
  SetLogTicks(&a);
  return a;
}

// ---------------------------------------------------------------------------------------------
// Frame: title, axis labels, ticks, grid. Computes the plot area inside `outer`.

constexpr int kTickLen = 6;
constexpr int kPad = 8;

struct Frame {
  Rect plot;
  Axis x, y;
  double Px(double v) const { return plot.x0 + x.Frac(v) * (plot.w() - 1); }
  double Py(double v) const { return plot.y1 - 1 - y.Frac(v) * (plot.h() - 1); }
};

Frame Layout(const Rect& outer, const Axis& x, const Axis& y, bool has_title, bool has_xlabel,
             bool has_ylabel) {
  Frame f;
  f.x = x;
  f.y = y;
  const int th = TextHeight(kScale);
  f.plot.y0 = outer.y0 + 2 * kPad + (has_title ? th + 2 * kPad : kPad);
  f.plot.y1 = outer.y1 - (kTickLen + kPad / 2 + th + kPad + (has_xlabel ? th + kPad : 0));
  f.plot.x0 = outer.x0 + kPad + (has_ylabel ? th + kPad + 4 : 0) + y.MaxLabelWidth(kScale) +
              kPad / 2 + kTickLen;
  // Room for the last x tick label to hang over the right edge.
  const int half_last = x.ticks.empty() ? 0 : TextWidth(x.ticks.back().label, kScale) / 2;
  f.plot.x1 = outer.x1 - std::max(2 * kPad + 4, half_last + kPad);
  return f;
}

void DrawFrame(Canvas* c, const Rect& outer, const Frame& f, const std::string& title,
               const std::string& x_label, const std::string& y_label) {
  const Rect& p = f.plot;
  const int th = TextHeight(kScale);
  // Grid.
  c->SetClip(p);
  for (const Tick& t : f.x.ticks) {
    const int px = static_cast<int>(std::lround(f.Px(t.value)));
    c->VLine(px, p.y0, p.y1 - 1, t.major ? kGrid : kMinorGrid);
  }
  for (const Tick& t : f.y.ticks) {
    const int py = static_cast<int>(std::lround(f.Py(t.value)));
    c->HLine(p.x0, p.x1 - 1, py, t.major ? kGrid : kMinorGrid);
  }
  c->ResetClip();
  c->StrokeRect(p, kFrame);
  // Ticks and labels.
  for (const Tick& t : f.x.ticks) {
    const double fx = f.x.Frac(t.value);
    if (fx < -1e-9 || fx > 1 + 1e-9) continue;
    const int px = static_cast<int>(std::lround(f.Px(t.value)));
    const int len = t.major ? kTickLen : kTickLen / 2;
    c->VLine(px, p.y1, p.y1 + len - 1, kFrame);
    if (!t.label.empty())
      c->Text(px - TextWidth(t.label, kScale) / 2, p.y1 + kTickLen + kPad / 2, t.label, kScale,
              kInk);
  }
  for (const Tick& t : f.y.ticks) {
    const double fy = f.y.Frac(t.value);
    if (fy < -1e-9 || fy > 1 + 1e-9) continue;
    const int py = static_cast<int>(std::lround(f.Py(t.value)));
    const int len = t.major ? kTickLen : kTickLen / 2;
    c->HLine(p.x0 - len, p.x0 - 1, py, kFrame);
    if (!t.label.empty())
      c->Text(p.x0 - kTickLen - kPad / 2 - TextWidth(t.label, kScale), py - th / 2, t.label,
              kScale, kInk);
  }
  // Title (bold, shrunk if it does not fit), axis labels.
  if (!title.empty()) {
    const int scale = TextWidth(title, kScale) <= outer.w() - 2 * kPad ? kScale : 1;
    const int cx = std::max(outer.x0 + kPad,
                            (p.x0 + p.x1) / 2 - TextWidth(title, scale) / 2);
    c->Text(cx, outer.y0 + 2 * kPad + (th - TextHeight(scale)) / 2, title, scale, kInk, true);
  }
  if (!x_label.empty()) {
    c->Text((p.x0 + p.x1) / 2 - TextWidth(x_label, kScale) / 2,
            p.y1 + kTickLen + kPad / 2 + th + kPad, x_label, kScale, kInk);
  }
  if (!y_label.empty()) {
    c->TextUp(outer.x0 + kPad, (p.y0 + p.y1) / 2 - TextWidth(y_label, kScale) / 2, y_label, kScale,
              kInk);
  }
}

// Legend: placed in the corner of the plot area that needs the least extra headroom (the value
// axis is widened so that no data point or line sits under the legend box).
struct LegendEntry {
  std::string label;
  uint32_t rgb;
  bool line, marker, box;
};

constexpr int kLegendMargin = 10;

void LegendSize(const std::vector<LegendEntry>& entries, int* w, int* h) {
  const int row = TextHeight(kScale) + 8, swatch = 30;
  int text_w = 0;
  for (const auto& e : entries) text_w = std::max(text_w, TextWidth(e.label, kScale));
  *w = kPad + swatch + kPad + text_w + kPad;
  *h = kPad / 2 + static_cast<int>(entries.size()) * row + kPad / 2;
}

enum Corner { kTopRight = 0, kTopLeft, kBottomRight, kBottomLeft };

// Chooses a corner for a legend of w x h pixels in a plot area of pw x ph pixels given the data
// as axis fractions (0..1 in x and y). Returns the corner and, in *scale, the factor by which the
// value axis must be widened (>= 1; from the top for top corners, from the bottom for bottom ones).
Corner ChooseLegendCorner(const std::vector<std::pair<double, double>>& frac, int pw, int ph,
                          int w, int h, bool allow_bottom, double* scale) {
  const double fw = double(w + kLegendMargin + 6) / pw, fh = double(h + kLegendMargin + 6) / ph;
  Corner best = kTopRight;
  double best_s = std::numeric_limits<double>::infinity();
  for (int k = 0; k < (allow_bottom ? 4 : 2); ++k) {
    const bool right = k == kTopRight || k == kBottomRight, top = k < 2;
    double worst = 0;  // top: largest y fraction under the box; bottom: largest 1 - y
    for (const auto& q : frac) {
      if (right ? q.first < 1 - fw : q.first > fw) continue;
      worst = std::max(worst, top ? q.second : 1 - q.second);
    }
    const double s = fh >= 0.9 ? 1.0 : std::max(1.0, worst / (1 - fh));
    if (s < best_s - 1e-9) {
      best_s = s;
      best = static_cast<Corner>(k);
    }
  }
  // Do not squash the data into less than ~55% of the panel; overlap a little instead.
  *scale = best_s > 1.8 ? 1.0 : best_s;
  return best;
}

// Widens the value axis by `scale` (top or bottom) and recomputes its ticks.
void WidenAxis(Axis* a, double scale, bool top, double target, bool integer) {
  if (scale <= 1.0) return;
  const double r = a->hi - a->lo;
  if (top) a->hi = a->lo + scale * r;
  else a->lo = a->hi - scale * r;
  if (a->log) SetLogTicks(a);
  else SetLinearTicks(a, target, integer);
}

// Samples of the polyline through `pts` (axis fractions), so that lines count as well as points.
void AddSegmentSamples(const std::vector<std::pair<double, double>>& pts,
                       std::vector<std::pair<double, double>>* out) {
  for (size_t i = 0; i + 1 < pts.size(); ++i)
    for (int k = 1; k < 16; ++k) {
      const double t = k / 16.0;
      out->emplace_back(pts[i].first + t * (pts[i + 1].first - pts[i].first),
                        pts[i].second + t * (pts[i + 1].second - pts[i].second));
    }
}

void DrawLegend(Canvas* c, const Frame& f, const std::vector<LegendEntry>& entries,
                Corner corner) {
  if (entries.empty()) return;
  const int th = TextHeight(kScale);
  const int row = th + 8, swatch = 30;
  int w, h;
  LegendSize(entries, &w, &h);
  const Rect& p = f.plot;
  const int m = kLegendMargin;
  const bool right = corner == kTopRight || corner == kBottomRight;
  const bool top = corner == kTopRight || corner == kTopLeft;
  Rect b;
  b.x0 = right ? p.x1 - m - w : p.x0 + m;
  b.y0 = top ? p.y0 + m : p.y1 - m - h;
  b.x1 = b.x0 + w;
  b.y1 = b.y0 + h;
  c->SetClip(p);
  c->FillRect(b.x0, b.y0, b.x1, b.y1, 0xFFFFFF, 0.9);
  c->StrokeRect(b, 0xAAAAAA);
  for (size_t i = 0; i < entries.size(); ++i) {
    const LegendEntry& e = entries[i];
    const int cy = b.y0 + kPad / 2 + static_cast<int>(i) * row + row / 2;
    const int sx0 = b.x0 + kPad, sx1 = sx0 + swatch;
    if (e.box) {
      c->FillRect(sx0, cy - th / 2, sx1, cy + th / 2, e.rgb, 0.45);
      c->StrokeRect(Rect{sx0, cy - th / 2, sx1, cy + th / 2}, e.rgb);
    }
    if (e.line) c->FillRect(sx0, cy - 1, sx1, cy + 1, e.rgb);
    if (e.marker) c->FillRect((sx0 + sx1) / 2 - 3, cy - 3, (sx0 + sx1) / 2 + 4, cy + 4, e.rgb);
    c->Text(sx1 + kPad, cy - th / 2, e.label, kScale, kInk);
  }
  c->ResetClip();
}

void DrawNoData(Canvas* c, const Frame& f) {
  const std::string s = "no data";
  c->Text((f.plot.x0 + f.plot.x1) / 2 - TextWidth(s, kScale) / 2,
          (f.plot.y0 + f.plot.y1) / 2 - TextHeight(kScale) / 2, s, kScale, kMuted);
}

// ---------------------------------------------------------------------------------------------
// Output.

Status CheckSize(const std::string& path, int width, int height) {
  if (width < 200 || height < 150 || width > 16384 || height > 16384) {
    return Status::Error("plot " + path + ": image size " + std::to_string(width) + "x" +
                         std::to_string(height) + " outside 200x150 .. 16384x16384");
  }
  return Status::Ok();
}

Status WritePng(const std::string& path, const Canvas& canvas) {
  const std::string tmp = path + ".tmp";
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(canvas.width());
  image.height = static_cast<png_uint_32>(canvas.height());
  image.format = PNG_FORMAT_RGB;
  errno = 0;
  if (!png_image_write_to_file(&image, tmp.c_str(), 0, canvas.data(), 0, nullptr)) {
    std::string why = image.message;
    if (why.empty() && errno != 0) why = std::strerror(errno);
    png_image_free(&image);
    std::remove(tmp.c_str());
    return Status::Error("cannot write plot " + path + ": " + why);
  }
  png_image_free(&image);
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(tmp.c_str());
    return Status::Error("cannot write plot " + path + ": rename from " + tmp + ": " + why);
  }
  return Status::Ok();
}

// Target tick count for an axis `px` pixels long with labels about `label_px` wide.
double TickTarget(int px, int spacing) { return std::clamp(px / double(spacing), 2.0, 12.0); }

// Builds a linear x axis whose labels do not collide.
Axis FittingLinearX(double lo, double hi, int px, bool integer, double pad) {
  Axis a;
  for (int spacing = 80; spacing <= 640; spacing = spacing * 3 / 2) {
    a = LinearAxis(lo, hi, TickTarget(px, spacing), integer, pad);
    const double gap = a.ticks.size() > 1 ? px / ((a.hi - a.lo) / (a.ticks[1].value -
                                                                    a.ticks[0].value))
                                          : px;
    if (a.MaxLabelWidth(kScale) + 16 < gap) break;
  }
  return a;
}

void RenderPanel(Canvas* c, const Rect& outer, const Panel& panel) {
  // Data ranges (with log clamping).
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin;
  double ymin = xmin, ymax = -xmin, min_pos = xmin;
  bool any_nonpos = false;
  for (const Series& s : panel.series)
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (!Finite(s.x[i]) || !Finite(s.y[i])) continue;
      xmin = std::min(xmin, s.x[i]);
      xmax = std::max(xmax, s.x[i]);
      ymin = std::min(ymin, s.y[i]);
      ymax = std::max(ymax, s.y[i]);
      if (s.y[i] > 0) min_pos = std::min(min_pos, s.y[i]);
      else any_nonpos = true;
    }
  const bool has_data = Finite(xmin);
  std::string title = panel.title;
  double floor_y = 0;
  if (panel.log_y && has_data) {
    if (any_nonpos) {
      floor_y = Finite(min_pos) ? std::pow(10.0, std::floor(std::log10(min_pos)) - 1) : 1e-3;
      title += " (values <= 0 shown at " + Num(floor_y) + ")";
      ymin = floor_y;
      if (!Finite(min_pos)) ymax = floor_y;
    }
    ymin = std::max(ymin, floor_y);
  }
  auto yval = [&](double v) { return panel.log_y ? std::max(v, floor_y) : v; };
  const int approx_w = outer.w() - 140, approx_h = outer.h() - 90;
  const double y_target = TickTarget(approx_h, 55);
  Axis y = panel.log_y ? LogAxis(has_data ? ymin : 1, has_data ? ymax : 10, 0.02)
                       : LinearAxis(ymin, ymax, y_target, false, 0.06);
  Axis x = FittingLinearX(has_data ? xmin : 0, has_data ? xmax : 1, approx_w, panel.integer_x,
                          0.03);
  Frame f = Layout(outer, x, y, !title.empty(), !panel.x_label.empty(), !panel.y_label.empty());

  // Legend placement; widen the value axis so the legend does not hide data.
  std::vector<LegendEntry> legend;
  std::vector<std::pair<double, double>> frac;
  for (const Series& s : panel.series) {
    if (!s.label.empty()) legend.push_back({s.label, s.rgb, s.lines, s.markers, false});
    std::vector<std::pair<double, double>> run;
    for (size_t i = 0; i <= s.x.size(); ++i) {
      if (i == s.x.size() || !Finite(s.x[i]) || !Finite(s.y[i])) {
        if (s.lines) AddSegmentSamples(run, &frac);
        frac.insert(frac.end(), run.begin(), run.end());
        run.clear();
        continue;
      }
      run.emplace_back(x.Frac(s.x[i]), y.Frac(yval(s.y[i])));
    }
  }
  Corner corner = kTopRight;
  if (!legend.empty() && has_data) {
    int lw, lh;
    LegendSize(legend, &lw, &lh);
    double scale = 1;
    corner = ChooseLegendCorner(frac, f.plot.w(), f.plot.h(), lw, lh, true, &scale);
    if (scale > 1) {
      WidenAxis(&y, scale, corner == kTopRight || corner == kTopLeft, y_target, false);
      f = Layout(outer, x, y, !title.empty(), !panel.x_label.empty(), !panel.y_label.empty());
    }
  }

  DrawFrame(c, outer, f, title, panel.x_label, panel.y_label);
  if (!has_data) {
    DrawNoData(c, f);
    return;
  }
  if (panel.zero_line && !panel.log_y && y.lo < 0 && y.hi > 0) {
    c->SetClip(f.plot);
    c->HLine(f.plot.x0, f.plot.x1 - 1, static_cast<int>(std::lround(f.Py(0))), 0x999999);
    c->ResetClip();
  }
  const Rect inner{f.plot.x0 + 1, f.plot.y0 + 1, f.plot.x1 - 1, f.plot.y1 - 1};
  for (const Series& s : panel.series) {
    c->SetClip(inner);
    if (s.lines) {
      c->BeginLayer();
      bool have_prev = false;
      double px = 0, py = 0;
      for (size_t i = 0; i < s.x.size(); ++i) {
        if (!Finite(s.x[i]) || !Finite(s.y[i])) {
          have_prev = false;
          continue;
        }
        const double qx = f.Px(s.x[i]), qy = f.Py(yval(s.y[i]));
        if (have_prev) c->LayerLine(px, py, qx, qy, 2.0);
        px = qx;
        py = qy;
        have_prev = true;
      }
      c->EndLayer(s.rgb);
    }
    if (s.markers) {
      for (size_t i = 0; i < s.x.size(); ++i) {
        if (!Finite(s.x[i]) || !Finite(s.y[i])) continue;
        const int ix = static_cast<int>(std::lround(f.Px(s.x[i])));
        const int iy = static_cast<int>(std::lround(f.Py(yval(s.y[i]))));
        c->FillRect(ix - 3, iy - 3, ix + 4, iy + 4, s.rgb);
      }
    }
    c->ResetClip();
  }
  DrawLegend(c, f, legend, corner);
}

}  // namespace

Status WritePlotPng(const std::string& path, const std::vector<Panel>& panels, int width,
                    int height) {
  if (Status s = CheckSize(path, width, height); !s.ok()) return s;
  if (panels.empty()) return Status::Error("plot " + path + ": no panels");
  if (height / static_cast<int>(panels.size()) < 120)
    return Status::Error("plot " + path + ": " + std::to_string(panels.size()) +
                         " panels do not fit in height " + std::to_string(height));
  for (const Panel& p : panels)
    for (const Series& s : p.series)
      if (s.x.size() != s.y.size())
        return Status::Error("plot " + path + ": series '" + s.label + "' has " +
                             std::to_string(s.x.size()) + " x values but " +
                             std::to_string(s.y.size()) + " y values");
  Canvas canvas(width, height);
  const int n = static_cast<int>(panels.size());
  for (int i = 0; i < n; ++i) {
    const Rect outer{0, height * i / n, width, height * (i + 1) / n};
    RenderPanel(&canvas, outer, panels[i]);
  }
  return WritePng(path, canvas);
}

Status WriteHistogramPng(const std::string& path, const std::string& title,
                         const std::string& x_label,
                         const std::vector<std::pair<std::string, std::vector<double>>>& samples,
                         int bins, int width, int height, bool log_x) {
  if (Status s = CheckSize(path, width, height); !s.ok()) return s;
  if (bins < 1 || bins > 10000)
    return Status::Error("plot " + path + ": bin count " + std::to_string(bins) +
                         " outside 1 .. 10000");
  // Usable values and the shared range.
  std::vector<std::vector<double>> vals(samples.size());
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  size_t dropped = 0;
  for (size_t k = 0; k < samples.size(); ++k)
    for (double v : samples[k].second) {
      if (!Finite(v)) continue;
      if (log_x && !(v > 0)) {
        ++dropped;
        continue;
      }
      vals[k].push_back(v);
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  const bool has_data = Finite(lo);
  if (has_data && hi - lo <= 1e-12 * std::max(std::abs(lo), std::abs(hi))) {
    if (log_x) {
      lo /= 1.5;
      hi *= 1.5;
    } else {
      const double p = lo == 0 ? 0.5 : 0.1 * std::abs(lo);
      lo -= p;
      hi += p;
    }
  }
  // Bin edges and counts.
  std::vector<double> edges(bins + 1);
  for (int i = 0; i <= bins; ++i) {
    const double t = double(i) / bins;
    edges[i] = !has_data ? t
               : log_x   ? std::pow(10.0, std::log10(lo) + t * (std::log10(hi) - std::log10(lo)))
                         : lo + t * (hi - lo);
  }
  std::vector<std::vector<int>> counts(samples.size(), std::vector<int>(bins, 0));
  int max_count = 0;
  for (size_t k = 0; k < vals.size(); ++k)
    for (double v : vals[k]) {
      const double t = log_x ? (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo))
                             : (v - lo) / (hi - lo);
      const int b = std::clamp(static_cast<int>(t * bins), 0, bins - 1);
      max_count = std::max(max_count, ++counts[k][b]);
    }

  std::string full_title = title;
  if (dropped > 0) full_title += " (" + std::to_string(dropped) + " values <= 0 not shown)";
  Canvas canvas(width, height);
  const Rect outer{0, 0, width, height};
  const int approx_w = width - 140, approx_h = height - 90;
  Axis y = LinearAxis(0, std::max(max_count, 1), TickTarget(approx_h, 55), true, 0.08, true);
  Axis x = log_x ? LogAxis(edges.front(), edges.back(), 0.01)
                 : FittingLinearX(edges.front(), edges.back(), approx_w, false, 0.02);
  const uint32_t palette[] = {kColorBefore, kColorAfter, 0x009E73, 0xCC79A7, 0xE69F00, 0x56B4E9};
  auto color = [&](size_t k) { return palette[k % (sizeof palette / sizeof palette[0])]; };
  std::vector<LegendEntry> legend;
  for (size_t k = 0; k < samples.size(); ++k)
    if (!samples[k].first.empty()) legend.push_back({samples[k].first, color(k), false, false, true});
  Frame f = Layout(outer, x, y, !full_title.empty(), !x_label.empty(), true);
  Corner corner = kTopRight;
  if (!legend.empty() && has_data) {
    std::vector<std::pair<double, double>> frac;  // bar tops
    for (size_t k = 0; k < samples.size(); ++k)
      for (int b = 0; b < bins; ++b) {
        if (counts[k][b] == 0) continue;
        const double x0 = x.Frac(edges[b]), x1 = x.Frac(edges[b + 1]), yb = y.Frac(counts[k][b]);
        for (int i = 0; i <= 8; ++i) frac.emplace_back(x0 + (x1 - x0) * i / 8.0, yb);
      }
    int lw, lh;
    LegendSize(legend, &lw, &lh);
    double scale = 1;
    corner = ChooseLegendCorner(frac, f.plot.w(), f.plot.h(), lw, lh, false, &scale);
    if (scale > 1) {
      WidenAxis(&y, scale, true, TickTarget(approx_h, 55), true);
      f = Layout(outer, x, y, !full_title.empty(), !x_label.empty(), true);
    }
  }
  DrawFrame(&canvas, outer, f, full_title, x_label, "count");
  if (!has_data) {
    DrawNoData(&canvas, f);
    return WritePng(path, canvas);
  }
  const Rect inner{f.plot.x0 + 1, f.plot.y0 + 1, f.plot.x1 - 1, f.plot.y1 - 1};
  canvas.SetClip(inner);
  const double y0 = f.Py(0);
  // Translucent bars first, then all opaque outlines (step lines) on top.
  for (size_t k = 0; k < samples.size(); ++k) {
    for (int b = 0; b < bins; ++b) {
      if (counts[k][b] == 0) continue;
      const double x0 = f.Px(edges[b]), x1 = f.Px(edges[b + 1]), y1 = f.Py(counts[k][b]);
      canvas.FillRect(static_cast<int>(std::lround(x0)), static_cast<int>(std::lround(y1)),
                      static_cast<int>(std::lround(x1)), static_cast<int>(std::lround(y0)),
                      color(k), 0.4);
    }
  }
  for (size_t k = 0; k < samples.size(); ++k) {
    canvas.BeginLayer();
    double prev_y = y0;
    for (int b = 0; b < bins; ++b) {
      const double x0 = f.Px(edges[b]), x1 = f.Px(edges[b + 1]);
      const double yb = counts[k][b] > 0 ? f.Py(counts[k][b]) : y0;
      if (yb != prev_y) canvas.LayerLine(x0, prev_y, x0, yb, 2.0);
      if (counts[k][b] > 0) canvas.LayerLine(x0, yb, x1, yb, 2.0);
      prev_y = yb;
    }
    if (prev_y != y0) canvas.LayerLine(f.Px(edges[bins]), prev_y, f.Px(edges[bins]), y0, 2.0);
    canvas.EndLayer(color(k));
  }
  canvas.ResetClip();
  DrawLegend(&canvas, f, legend, corner);
  return WritePng(path, canvas);
}

namespace {

double Median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double a) { return !Finite(a); }), v.end());
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// "before (rms 1.23 mm)"-style summary over the finite values.
std::string Summary(const std::string& name, const std::vector<double>& v, bool rms) {
  double sum = 0, sum2 = 0, mx = 0;
  size_t n = 0;
  for (double a : v) {
    if (!Finite(a)) continue;
    sum += a;
    sum2 += a * a;
    mx = std::max(mx, std::abs(a));
    ++n;
  }
  if (n == 0) return name + " (no data)";
  if (rms) return name + " (rms " + Num(std::sqrt(sum2 / n)) + " mm)";
  return name + " (n=" + std::to_string(n) + ", mean " + Num(sum / n) + ", max " + Num(mx) +
         " mm)";
}

}  // namespace

Status WriteConvergencePlot(const std::string& path, const std::vector<int>& iteration,
                            const std::vector<double>& max_err, const std::vector<double>& mean_err,
                            int width, int height) {
  if (max_err.size() != iteration.size() || mean_err.size() != iteration.size())
    return Status::Error("plot " + path + ": " + std::to_string(iteration.size()) +
                         " iterations but " + std::to_string(max_err.size()) + " max and " +
                         std::to_string(mean_err.size()) + " mean errors");
  Panel p;
  p.title = "Convergence: position error per iteration";
  p.x_label = "iteration";
  p.y_label = "position error [mm]";
  p.log_y = true;
  p.integer_x = true;
  std::vector<double> it(iteration.begin(), iteration.end());
  const bool markers = iteration.size() <= 100;
  p.series.push_back({"max error", it, max_err, kColorMax, markers, true});
  p.series.push_back({"mean error", it, mean_err, kColorMean, markers, true});
  return WritePlotPng(path, {p}, width, height);
}

Status WriteAxisErrorPlot(const std::string& path, const std::vector<Eigen::Vector3d>& before,
                          const std::vector<Eigen::Vector3d>& after, int width, int height,
                          const std::string& set_name) {
  static const char* kAxis[3] = {"x", "y", "z"};
  std::vector<Panel> panels(3);
  for (int a = 0; a < 3; ++a) {
    Panel& p = panels[a];
    p.title = std::string(kAxis[a]) + " position error per " + set_name + " pose";
    p.y_label = std::string(kAxis[a]) + " error [mm]";
    if (a == 2) p.x_label = "pose index";
    p.integer_x = true;
    p.zero_line = true;
    const std::vector<Eigen::Vector3d>* sets[2] = {&before, &after};
    const char* names[2] = {"before", "after"};
    const uint32_t colors[2] = {kColorBefore, kColorAfter};
    for (int k = 0; k < 2; ++k) {
      const std::vector<Eigen::Vector3d>& set = *sets[k];
      const size_t n = set.size();
      Series s;
      s.rgb = colors[k];
      s.markers = n <= 80;
      std::vector<double> all(n);
      for (size_t i = 0; i < n; ++i) all[i] = set[i][a];
      s.label = Summary(names[k], all, /*rms=*/true);
      // More poses than pixel columns: keep the minimum and maximum of each column's poses (in
      // pose order), which draws the same image as every point at a fraction of the cost.
      const size_t columns = static_cast<size_t>(std::max(width, 1));
      const size_t per_column = n > 2 * columns ? (n + columns - 1) / columns : 1;
      s.x.reserve(per_column > 1 ? 2 * columns : n);
      s.y.reserve(s.x.capacity());
      for (size_t begin = 0; begin < n; begin += per_column) {
        const size_t end = std::min(n, begin + per_column);
        size_t lo = begin, hi = begin;
        for (size_t i = begin; i < end; ++i) {
          if (all[i] < all[lo]) lo = i;
          if (all[i] > all[hi]) hi = i;
        }
        for (size_t i : {std::min(lo, hi), std::max(lo, hi)}) {
          if (!s.x.empty() && s.x.back() == static_cast<double>(i)) continue;
          s.x.push_back(static_cast<double>(i));
          s.y.push_back(all[i]);
        }
      }
      p.series.push_back(std::move(s));
    }
  }
  return WritePlotPng(path, panels, width, height);
}

Status WriteErrorHistogram(const std::string& path, const std::vector<double>& before_norm,
                           const std::vector<double>& after_norm, int width, int height) {
  size_t n = 0, nonpos = 0;
  for (const auto* v : {&before_norm, &after_norm})
    for (double a : *v)
      if (Finite(a)) {
        ++n;
        if (!(a > 0)) ++nonpos;
      }
  const double mb = Median(before_norm), ma = Median(after_norm);
  const bool log_x = nonpos == 0 && mb > 0 && ma > 0 &&
                     std::max(mb, ma) / std::min(mb, ma) > 10.0;
  const int bins = std::clamp(static_cast<int>(std::ceil(2.0 * std::sqrt(double(n)))), 8, 40);
  return WriteHistogramPng(
      path,
      std::string("Position error norm before / after calibration") +
          (log_x ? " (log-spaced bins)" : ""),
      "position error norm [mm]",
      {{Summary("before", before_norm, false), before_norm},
       {Summary("after", after_norm, false), after_norm}},
      bins, width, height, log_x);
}

}  // namespace tools
}  // namespace lpoe
