// lapflow_make_exemplars: draws the shipped exemplars procedurally, so they
// are the project's own (same licence as lapflow). Deterministic: the same
// binary writes the same files on any machine and thread count.
//
//   lapflow_make_exemplars [OUT_DIR] [--size N] [--contact SHEET.png]
//
// Each exemplar is NAME.color.png (8-bit sRGB), NAME.feature.png and
// NAME.disp.png (16-bit grey, linear). The feature map follows the paper's
// intent: high inside the texture's elements, falling to 0 at their borders,
// so that erosion (Eq. 1) cuts a distorted patch along element borders.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "lapflow/io/image.hpp"
#include "lapflow/core/parallel.hpp"

namespace {
using lapflow::Image;
using lapflow::hash64;
using lapflow::hash_to_unit;

constexpr double kPi = 3.14159265358979323846;

struct Rgb {
  double r = 0, g = 0, b = 0;
};
Rgb operator*(const Rgb& c, double s) { return {c.r * s, c.g * s, c.b * s}; }
Rgb operator+(const Rgb& a, const Rgb& b) { return {a.r + b.r, a.g + b.g, a.b + b.b}; }
Rgb mix(const Rgb& a, const Rgb& b, double t) { return a * (1 - t) + b * t; }
Rgb hsv(double h, double s, double v) {
  h = (h - std::floor(h)) * 6;
  const int i = int(h);
  const double f = h - i, p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  switch (i % 6) {
    case 0: return {v, t, p};
    case 1: return {q, v, p};
    case 2: return {p, v, t};
    case 3: return {p, q, v};
    case 4: return {t, p, v};
    default: return {v, p, q};
  }
}

double smoothstep(double a, double b, double x) {
  const double t = std::clamp((x - a) / (b - a), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}
int wrap(int i, int n) { return ((i % n) + n) % n; }

/// Periodic gradient noise (period `n` lattice cells), about [-1, 1].
double noise(double x, double y, int n, uint64_t seed) {
  const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  auto grad = [&](int i, int j, double dx, double dy) {
    const double a = 2 * kPi * hash_to_unit(hash64(seed, uint64_t(wrap(i, n)), uint64_t(wrap(j, n))));
    return std::cos(a) * dx + std::sin(a) * dy;
  };
  auto fade = [](double t) { return t * t * t * (t * (t * 6 - 15) + 10); };
  const double u = fade(fx), v = fade(fy);
  const double a = grad(x0, y0, fx, fy), b = grad(x0 + 1, y0, fx - 1, fy);
  const double c = grad(x0, y0 + 1, fx, fy - 1), d = grad(x0 + 1, y0 + 1, fx - 1, fy - 1);
  return 1.4 * ((a * (1 - u) + b * u) * (1 - v) + (c * (1 - u) + d * u) * v);
}

/// Fractal sum of periodic noise over the unit square, about [-1, 1].
double fbm(double x, double y, int base, int octaves, uint64_t seed, double gain = 0.5) {
  double sum = 0, amp = 1, norm = 0;
  int n = base;
  for (int o = 0; o < octaves; ++o) {
    sum += amp * noise(x * n, y * n, n, hash64(seed, uint64_t(o)));
    norm += amp;
    amp *= gain;
    n *= 2;
  }
  return sum / norm;
}

/// Periodic jittered-grid Voronoi over the unit square with n x n cells.
struct Cell {
  uint64_t id = 0;     ///< which cell (stable hash)
  double border = 0;   ///< distance to the nearest cell border, in cell units
  double centre = 0;   ///< distance to the cell's site, in cell units
};
Cell voronoi(double x, double y, int n, uint64_t seed, double jitter = 0.8) {
  const double px = x * n, py = y * n;
  const int cx = int(std::floor(px)), cy = int(std::floor(py));
  struct Site {
    double x, y;
    uint64_t id;
  };
  std::array<Site, 25> sites;
  int k = 0;
  for (int j = -2; j <= 2; ++j)
    for (int i = -2; i <= 2; ++i) {
      const uint64_t h = hash64(seed, uint64_t(wrap(cx + i, n)), uint64_t(wrap(cy + j, n)));
      const double jx = 0.5 + jitter * (hash_to_unit(h) - 0.5), jy = 0.5 + jitter * (hash_to_unit(hash64(h)) - 0.5);
      sites[k++] = {cx + i + jx, cy + j + jy, h};
    }
  int best = 0;
  double bd = 1e30;
  for (int s = 0; s < 25; ++s) {
    const double d = std::hypot(sites[s].x - px, sites[s].y - py);
    if (d < bd) bd = d, best = s;
  }
  double border = 1e30;
  const Site& a = sites[best];
  for (int s = 0; s < 25; ++s) {
    if (s == best) continue;
    const Site& b = sites[s];
    const double ex = b.x - a.x, ey = b.y - a.y, len = std::hypot(ex, ey);
    const double mx = 0.5 * (a.x + b.x), my = 0.5 * (a.y + b.y);
    border = std::min(border, ((mx - px) * ex + (my - py) * ey) / len);
  }
  return {a.id, border, bd};
}

struct Maps {
  Image color, feature, disp;
};

/// Fills the three maps; `shade(x, y, colour, feature, disp)` gets the pixel
/// centre in [0,1]^2 with y up (uv convention) and returns display (sRGB) colour.
Maps draw(int size, const std::function<void(double, double, Rgb&, double&, double&)>& shade) {
  Maps m{Image(size, size, 3), Image(size, size, 1), Image(size, size, 1)};
  lapflow::parallel_for(std::size_t(size), [&](std::size_t b, std::size_t e) {
    for (std::size_t row = b; row < e; ++row)
      for (int col = 0; col < size; ++col) {
        const double x = (col + 0.5) / size, y = 1.0 - (row + 0.5) / size;
        Rgb c;
        double f = 0, d = 0;
        shade(x, y, c, f, d);
        const double rgb[3] = {c.r, c.g, c.b};
        for (int ch = 0; ch < 3; ++ch) {
          const double v = std::clamp(rgb[ch], 0.0, 1.0);
          // Authored in display values; the Image holds linear light.
          m.color.at(col, int(row), ch) = float(v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4));
        }
        m.feature.at(col, int(row), 0) = float(std::clamp(f, 0.0, 1.0));
        m.disp.at(col, int(row), 0) = float(std::clamp(d, 0.0, 1.0));
      }
  }, 4);
  return m;
}

// Pebbles: Voronoi stones, height = rounded distance to the cell border.
void pebbles(double x, double y, Rgb& c, double& f, double& d) {
  const Cell cell = voronoi(x, y, 7, 11);
  const double gap = 0.06;  // grout half-width, cell units
  const double t = std::clamp((cell.border - gap) / 0.35, 0.0, 1.0);
  const double dome = std::sqrt(1 - (1 - t) * (1 - t));
  f = cell.border > gap ? dome : 0;
  d = f * (0.9 + 0.1 * fbm(x, y, 16, 3, 12));
  const double hue = 0.07 + 0.06 * hash_to_unit(hash64(cell.id, 1));
  const double sat = 0.15 + 0.25 * hash_to_unit(hash64(cell.id, 2));
  const double val = 0.45 + 0.35 * hash_to_unit(hash64(cell.id, 3));
  const double grain = 0.08 * fbm(x, y, 32, 3, cell.id);
  Rgb stone = hsv(hue, sat, val + grain);
  stone = stone * (0.55 + 0.45 * dome);  // rounded tops catch the light
  const Rgb grout{0.09, 0.08, 0.07};
  c = mix(grout, stone, smoothstep(gap * 0.6, gap * 1.4, cell.border));
}

// Lava crust: dark cooled plates separated by glowing cracks.
void lava(double x, double y, Rgb& c, double& f, double& d) {
  const double wx = x + 0.02 * fbm(x, y, 4, 4, 21), wy = y + 0.02 * fbm(x, y, 4, 4, 22);
  const Cell cell = voronoi(wx, wy, 6, 23, 0.9);
  const double crack = 0.05 + 0.04 * (0.5 + 0.5 * fbm(x, y, 8, 3, 24));
  const double plate = smoothstep(0.5 * crack, crack + 0.15, cell.border);
  const double rough = 0.5 + 0.5 * fbm(x, y, 16, 5, 25);
  f = plate;
  d = plate * (0.7 + 0.3 * rough);
  const double heat = 1 - smoothstep(0.0, crack + 0.02, cell.border);  // glow fades into the plate edge
  const Rgb crust = Rgb{0.16, 0.13, 0.12} * (0.5 + 0.8 * rough);
  const Rgb glow = mix(Rgb{0.85, 0.15, 0.02}, Rgb{1.0, 0.85, 0.3}, heat * heat);
  c = mix(crust, glow, heat);
}

// Coloured squares on a dark background (the paper's Fig. 10 exemplar).
void squares(double x, double y, Rgb& c, double& f, double& d) {
  constexpr int n = 4;  // squares per side
  const int i = std::min(int(x * n), n - 1), j = std::min(int(y * n), n - 1);
  const double lx = x * n - i, ly = y * n - j;  // position in the cell, [0,1]
  const double half = 0.36;                       // square half-size, cell units
  const double inside = half - std::max(std::abs(lx - 0.5), std::abs(ly - 0.5));
  const uint64_t id = hash64(31, uint64_t(i), uint64_t(j));
  const Rgb tint = hsv(hash_to_unit(id), 0.75, 0.9);
  f = inside > 0 ? std::min(1.0, 0.25 + inside / half) : 0.0;
  d = inside > 0 ? smoothstep(0.0, 0.08, inside) : 0.0;
  const Rgb background = Rgb{0.05, 0.05, 0.06} * (1 + 0.2 * fbm(x, y, 32, 2, 32));
  c = mix(background, tint * (0.85 + 0.15 * std::min(1.0, inside / half * 2)), smoothstep(-0.004, 0.004, inside));
}

// Scales: rows of overlapping discs, each row over the one above it (fish or
// dragon scales). Feature = distance to the visible scale's rim.
void scales(double x, double y, Rgb& c, double& f, double& d) {
  constexpr int cols = 6, rows = 8;
  const double w = 1.0 / cols, h = 1.0 / rows, radius = 0.62 * w;
  // Find the top-most scale covering (x, y): lower rows lie on top.
  double best_edge = -1, best_r = 0;
  uint64_t best_id = 0;
  int best_row = 1 << 30;
  const int j0 = int(std::floor(y / h));
  for (int j = j0 - 1; j <= j0 + 3; ++j) {
    const double cy = j * h;
    const double shift = (wrap(j, rows) % 2) ? 0.5 * w : 0.0;
    const int i0 = int(std::floor((x - shift) / w));
    for (int i = i0 - 1; i <= i0 + 2; ++i) {
      const double cx = i * w + shift + 0.5 * w;
      const double r = std::hypot(x - cx, (y - cy) * 1.0);
      if (r > radius) continue;
      if (j < best_row) {
        best_row = j;
        best_edge = radius - r;
        best_r = r / radius;
        best_id = hash64(41, uint64_t(wrap(i, cols)), uint64_t(wrap(j, rows)));
      }
    }
  }
  if (best_edge < 0) {  // cannot happen with this overlap; keep the map defined
    c = {0.05, 0.1, 0.1};
    f = d = 0;
    return;
  }
  const double t = std::clamp(best_edge / (0.5 * radius), 0.0, 1.0);
  f = std::sqrt(t);
  d = std::sqrt(t) * (1 - 0.3 * best_r);
  const double hue = 0.42 + 0.1 * hash_to_unit(best_id) + 0.05 * fbm(x, y, 4, 2, 42);
  const Rgb body = hsv(hue, 0.55, 0.25 + 0.55 * (1 - best_r));
  const Rgb rim{0.02, 0.04, 0.04};
  c = mix(rim, body, smoothstep(0.0, 0.12, t)) + Rgb{0.25, 0.3, 0.25} * std::pow(std::max(0.0, 1 - best_r), 6);
}

// Foam: stochastic sea foam, white where the fbm is high, over deep water.
void foam(double x, double y, Rgb& c, double& f, double& d) {
  const double n = 0.5 + 0.5 * fbm(x, y, 4, 6, 51, 0.55);
  const double bubbles = 0.5 + 0.5 * fbm(x, y, 32, 2, 52);
  f = std::clamp((n - 0.3) / 0.45, 0.0, 1.0);
  d = std::clamp(f * (0.8 + 0.2 * bubbles), 0.0, 1.0);
  const Rgb water = mix(Rgb{0.02, 0.12, 0.2}, Rgb{0.05, 0.3, 0.35}, n);
  const double cover = smoothstep(0.35, 0.75, f + 0.15 * (bubbles - 0.5));
  c = mix(water, Rgb{0.92, 0.95, 0.95} * (0.85 + 0.15 * bubbles), cover);
}

// Ripples: calm water with soft caustic lines (the borders of a warped
// Voronoi); feature high inside the cells, 0 on the bright lines, so a
// distorted patch erodes along them. The calm partner of foam (docs/layers.md).
void ripples(double x, double y, Rgb& c, double& f, double& d) {
  const double wx = x + 0.035 * fbm(x, y, 4, 3, 61), wy = y + 0.035 * fbm(x, y, 4, 3, 62);
  const Cell cell = voronoi(wx, wy, 9, 63, 0.9);
  const double line = 1 - smoothstep(0.0, 0.09, cell.border);
  const double swell = 0.5 + 0.5 * fbm(x, y, 2, 3, 64);
  f = smoothstep(0.02, 0.3, cell.border);
  d = std::clamp(0.35 + 0.4 * swell + 0.25 * line, 0.0, 1.0);
  const Rgb deep{0.03, 0.16, 0.24}, shallow{0.07, 0.33, 0.40};
  c = mix(deep, shallow, 0.35 + 0.5 * swell) + Rgb{0.32, 0.38, 0.36} * (line * line);
}

// Boil: an animated exemplar (docs/layers.md), a green slime whose bubbles
// swell and sink back, each cell on a phase of its own; `t` in [0,1) is the
// loop's time, and every term is periodic in it so the sequence loops
// seamlessly. Feature: the bubble's dome (erosion cuts between bubbles).
void boil(double x, double y, double t, Rgb& c, double& f, double& d) {
  const double a = 2 * kPi * t;
  const double slime = 0.5 + 0.5 * fbm(x + 0.03 * std::cos(a), y + 0.03 * std::sin(a), 4, 4, 71);
  // Sites jittered by at most 0.25 lie 0.5 cells apart or more: a bubble of
  // radius 0.25 never reaches past its cell's border.
  const Cell cell = voronoi(x, y, 7, 72, 0.5);
  const double phase = hash_to_unit(hash64(cell.id, 73));
  const double u = t + phase - std::floor(t + phase);
  const double size = 0.25 * std::pow(std::sin(kPi * u), 0.6);
  const double r = size > 1e-3 ? cell.centre / size : 2.0;
  const double dome = r < 1 ? std::sqrt(1 - r * r) : 0.0;
  f = dome;
  d = std::clamp(0.25 + 0.25 * slime + 0.5 * dome, 0.0, 1.0);
  const Rgb dark{0.10, 0.22, 0.05}, light{0.35, 0.62, 0.16};
  c = mix(dark, light, 0.3 + 0.5 * slime);
  if (dome > 0) {
    const double rim = smoothstep(0.75, 1.0, r);
    c = mix(mix(light, Rgb{0.62, 0.86, 0.35}, dome), dark, 0.6 * rim);
    const double hx = (x * 6 - std::floor(x * 6)) - 0.5, hy = (y * 6 - std::floor(y * 6)) - 0.5;
    c = c + Rgb{0.3, 0.3, 0.25} * (dome * smoothstep(0.6, 1.0, dome) * (0.5 + 0.5 * (hy - hx)));
  }
}

/// The animated exemplar's frames, one loop.
constexpr int kBoilFrames = 12;

struct Exemplar {
  const char* name;
  void (*shade)(double, double, Rgb&, double&, double&);
  const char* description;
};
constexpr Exemplar kExemplars[] = {
    {"pebbles", pebbles, "Voronoi pebbles in dark grout; height and feature = rounded distance to the cell border"},
    {"lava", lava, "dark lava crust plates with glowing cracks; feature high on the plates, 0 in the cracks"},
    {"squares", squares, "coloured squares on a dark background (the paper's Fig. 10); feature high inside squares"},
    {"scales", scales, "overlapping fish/dragon scales; feature = distance to the visible scale's rim"},
    {"foam", foam, "stochastic sea foam (fBm noise) over deep water; feature = foam density"},
    {"ripples", ripples, "calm water with soft caustic lines; feature high inside the ripple cells, 0 on the lines"},
};

}  // namespace

int main(int argc, char** argv) {
  std::string out = "exemplars", contact;
  int size = 512;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--size" && a + 1 < argc) {
      size = std::atoi(argv[++a]);
    } else if (arg == "--contact" && a + 1 < argc) {
      contact = argv[++a];
    } else if (arg == "-h" || arg == "--help") {
      fmt::print("usage: lapflow_make_exemplars [OUT_DIR] [--size N] [--contact SHEET.png]\n"
                 "Draws the shipped exemplars (NAME.color.png, NAME.feature.png, NAME.disp.png) into OUT_DIR\n"
                 "(default: exemplars). --contact also writes a contact sheet (colour | feature | disp rows).\n");
      return 0;
    } else if (!arg.empty() && arg[0] != '-') {
      out = arg;
    } else {
      fmt::print(stderr, "error: unknown argument '{}' (see --help)\n", arg);
      return 2;
    }
  }
  if (size < 64 || size > 4096) {
    fmt::print(stderr, "error: --size must be in [64, 4096]\n");
    return 2;
  }
  try {
    std::filesystem::create_directories(out);
    const int tile = 256, n = int(std::size(kExemplars));
    Image sheet(3 * tile, n * tile, 3);
    for (int e = 0; e < n; ++e) {
      const Exemplar& ex = kExemplars[e];
      const Maps m = draw(size, ex.shade);
      const std::string base = (std::filesystem::path(out) / ex.name).string();
      lapflow::write_png(base + ".color.png", m.color, true, 8);
      lapflow::write_png(base + ".feature.png", m.feature, false, 16);
      lapflow::write_png(base + ".disp.png", m.disp, false, 16);
      fmt::print("{}: {}x{}  {}\n", ex.name, size, size, ex.description);
      if (contact.empty()) continue;
      const Image parts[3] = {lapflow::resize_image(m.color, tile, tile), lapflow::resize_image(m.feature, tile, tile),
                              lapflow::resize_image(m.disp, tile, tile)};
      for (int p = 0; p < 3; ++p)
        for (int y = 0; y < tile; ++y)
          for (int x = 0; x < tile; ++x)
            for (int ch = 0; ch < 3; ++ch) {
              const float v = parts[p].at(x, y, parts[p].channels == 3 ? ch : 0);
              sheet.at(p * tile + x, e * tile + y, ch) =
                  p == 0 ? (v <= 0.0031308f ? v * 12.92f : 1.055f * std::pow(v, 1 / 2.4f) - 0.055f) : v;
            }
    }
    // The animated exemplar, at half the size: boil/boil.{color,feature,disp}.NNNN.png.
    const int anim = size / 2;
    const std::filesystem::path folder = std::filesystem::path(out) / "boil";
    std::filesystem::create_directories(folder);
    for (int k = 0; k < kBoilFrames; ++k) {
      const double t = double(k) / kBoilFrames;
      const Maps m = draw(anim, [t](double x, double y, Rgb& c, double& f, double& d) { boil(x, y, t, c, f, d); });
      const std::string base = (folder / "boil").string();
      const std::string number = fmt::format("{:04d}", k + 1);
      lapflow::write_png(base + ".color." + number + ".png", m.color, true, 8);
      lapflow::write_png(base + ".feature." + number + ".png", m.feature, false, 16);
      lapflow::write_png(base + ".disp." + number + ".png", m.disp, false, 16);
    }
    fmt::print("boil: {} frames of {}x{}  animated green slime whose bubbles swell and sink, each on its own phase\n",
               kBoilFrames, anim, anim);
    // Grey maps are data, shown as stored; the colour column is encoded above.
    if (!contact.empty()) lapflow::write_png(contact, sheet, false, 8);
  } catch (const std::exception& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 1;
  }
  return 0;
}
