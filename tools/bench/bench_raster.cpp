// Benchmark of the rasterizer alone on a synthetic large case: a flat square
// of ~100k fluid triangles cut into chart blocks packed with gutters (so patch
// triangles straddle seams as on a real atlas), ~5k grid patches of ~290
// triangles each at Poisson-like spacing r, weights that erode, a 512^2
// structured exemplar. Prints seconds per sub-stage and peak RSS.
#include <fmt/format.h>
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <string>

#include "bench.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/raster/raster.hpp"

namespace lapflow::bench {
namespace {

struct Plane {
  TriMesh mesh;
  SurfaceAtlas atlas;
  int g = 0, blocks = 0;
  double L = 1;
  int locate(double x, double y) const {
    if (x < 0 || y < 0 || x > L || y > L) return -1;
    const double h = L / g;
    const int i = std::min(g - 1, int(x / h)), j = std::min(g - 1, int(y / h));
    return 2 * (j * g + i) + (x / h - i >= y / h - j ? 0 : 1);
  }
};

// g x g cells over the unit square, cut into blocks x blocks charts laid out
// on a grid in the atlas with `gutter` texels between them.
Plane make_plane(int g, int blocks, int N, int gutter) {
  Plane P;
  P.g = g, P.blocks = blocks;
  const double h = 1.0 / g;
  for (int j = 0; j <= g; ++j)
    for (int i = 0; i <= g; ++i) P.mesh.positions.push_back({i * h, j * h, 0});
  for (int j = 0; j < g; ++j)
    for (int i = 0; i < g; ++i) {
      const int32_t a = j * (g + 1) + i;
      P.mesh.triangles.push_back({a, a + 1, a + g + 2});
      P.mesh.triangles.push_back({a, a + g + 2, a + g + 1});
    }
  const int cells = g / blocks;  // cells per chart side (g divisible by blocks)
  const double slot = 1.0 / blocks, pad = double(gutter) / N;
  const double scale = (slot - pad) / (cells * h);  // atlas uv per metre
  auto origin = [&](int bi, int bj) { return Vec2{bi * slot + 0.5 * pad, bj * slot + 0.5 * pad}; };
  SurfaceAtlas& A = P.atlas;
  A.resolution = N;
  A.chart_count = blocks * blocks;
  for (int j = 0; j < g; ++j)
    for (int i = 0; i < g; ++i)
      for (int half = 0; half < 2; ++half) {
        const int bi = i / cells, bj = j / cells;
        A.chart_of_triangle.push_back(bj * blocks + bi);
        const Tri& T = P.mesh.triangles[A.chart_of_triangle.size() - 1];
        for (int k = 0; k < 3; ++k) {
          const Vec3& p = P.mesh.positions[T[k]];
          A.corner_uv.push_back(origin(bi, bj) + Vec2{p.x - bi * cells * h, p.y - bj * cells * h} * scale);
        }
      }
  // Texel map, chart by chart then sorted by texel (bucket per row keeps it linear).
  std::vector<std::vector<std::size_t>> rows(N);
  TexelMap tmp;
  for (int bj = 0; bj < blocks; ++bj)
    for (int bi = 0; bi < blocks; ++bi) {
      const Vec2 o = origin(bi, bj);
      const double size = cells * h * scale;
      const int x0 = std::max(0, int(std::floor(o.x * N))), x1 = std::min(N - 1, int(std::ceil((o.x + size) * N)));
      const int y0 = std::max(0, int(std::floor((1 - o.y - size) * N))), y1 = std::min(N - 1, int(std::ceil((1 - o.y) * N)));
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const Vec2 uv{(x + 0.5) / N, 1.0 - (y + 0.5) / N};
          const Vec2 q = (uv - o) / scale;
          if (!(q.x >= 0 && q.y >= 0 && q.x < cells * h && q.y < cells * h)) continue;
          const double px = q.x + bi * cells * h, py = q.y + bj * cells * h;
          const int t = P.locate(px, py);
          rows[y].push_back(tmp.texel.size());
          tmp.texel.push_back(uint32_t(y * N + x));
          tmp.triangle.push_back(t);
        }
    }
  TexelMap& tm = A.texels;
  for (auto& row : rows) {
    std::sort(row.begin(), row.end(), [&](std::size_t a, std::size_t b) { return tmp.texel[a] < tmp.texel[b]; });
    for (std::size_t k : row) {
      tm.texel.push_back(tmp.texel[k]);
      tm.triangle.push_back(tmp.triangle[k]);
    }
  }
  return P;
}

Patch grid_patch(const Plane& P, Vec3 c, double r, double angle, int m, uint32_t id, double w_centre) {
  Patch p;
  p.id = id;
  p.center = c;
  p.center_normal = {0, 0, 1};
  const double x0 = std::max(0.0, c.x - r), x1 = std::min(1.0, c.x + r);
  const double y0 = std::max(0.0, c.y - r), y1 = std::min(1.0, c.y + r);
  const double cs = std::cos(angle), sn = std::sin(angle);
  for (int j = 0; j <= m; ++j)
    for (int i = 0; i <= m; ++i) {
      const Vec3 q{x0 + (x1 - x0) * i / m, y0 + (y1 - y0) * j / m, 0};
      const double dx = q.x - c.x, dy = q.y - c.y;
      p.positions.push_back(q);
      p.rest_uv.push_back({0.5 + (cs * dx - sn * dy) / (2 * r), 0.5 + (sn * dx + cs * dy) / (2 * r)});
      // B_V as ALGORITHM.md step 5: boundary vertices at 0 unless within r/4
      // of the centre; interior ones at w_centre. Erosion eats the rim.
      const bool border = (i == 0 || j == 0 || i == m || j == m) && std::hypot(dx, dy) > 0.25 * r;
      p.weight.push_back(border ? 0.f : float(w_centre));
      p.surface_triangle.push_back(P.locate(q.x, q.y));
    }
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) {
      const int32_t a = j * (m + 1) + i, b = a + 1, cc = a + m + 2, d = a + m + 1;
      p.triangles.push_back({a, b, cc});
      p.triangles.push_back({a, cc, d});
    }
  return p;
}

Exemplar structured_exemplar(int size) {
  Exemplar ex;
  ex.color = Image(size, size, 3);
  ex.feature = Image(size, size, 1);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const double f = 0.5 + 0.5 * std::sin(x * 0.11) * std::cos(y * 0.07 + 0.3 * std::sin(x * 0.05));
      ex.feature.at(x, y, 0) = float(f);
      ex.color.at(x, y, 0) = float(f);
      ex.color.at(x, y, 1) = float(0.3 + 0.4 * ((x / 16 + y / 16) % 2));
      ex.color.at(x, y, 2) = float(x) / size;
    }
  ex.displacement = ex.feature;
  return ex;
}

// User + system CPU seconds of the process so far: on this shared 2-core
// machine wall times swing with the load, CPU seconds do not.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double peak_rss_gb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / (1024.0 * 1024.0);
}

// ns per exemplar lookup at a level of detail, along rows of a rotated
// patch (the resolve pass's access pattern).
double lookup_ns(const ExemplarMips& mips, double lod, bool trilinear = true) {
  constexpr int kRows = 2000, kCols = 2000;
  float sink = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (int j = 0; j < kRows; ++j)
    for (int i = 0; i < kCols; ++i) {
      const double u = 0.5 + 0.45 * ((i - kCols / 2) * 0.8 - (j - kRows / 2) * 0.6) / kCols;
      const double v = 0.5 + 0.45 * ((i - kCols / 2) * 0.6 + (j - kRows / 2) * 0.8) / kRows;
      float out[4];
      sample_exemplar(mips, u, v, lod, out, trilinear);
      sink += out[0];
    }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (sink == -1) fmt::print("");  // keep the loop
  return s * 1e9 / (double(kRows) * kCols);
}

// The output images' digest: equal before and after an optimisation means
// the output did not change.
uint64_t digest(const FrameTextures& t) {
  uint64_t h = kFnvOffset;
  for (const Image* img : {&t.color, &t.displacement, &t.aov})
    h = fnv1a(img->pixels.data(), img->pixels.size() * sizeof(float), h);
  return h;
}

}  // namespace

void bench_raster(const std::vector<int>& resolutions, int grid_cells, int target_patches, int threads) {
  set_thread_count(threads);
  const Exemplar ex = structured_exemplar(512);
  const RasterExemplar rex = prepare_raster_exemplar(ex, 0.1);
  fmt::print("exemplar lookup (512^2, one thread): bilinear level 0 {:.1f} ns, nearest mip {:.1f} ns, trilinear {:.1f} ns\n",
             lookup_ns(rex.mips, 0.0), lookup_ns(rex.mips, 1.6, false), lookup_ns(rex.mips, 1.6));
  // Poisson spacing r over the unit square: ~1/r^2 patches, jittered grid.
  const int side = std::max(1, int(std::lround(std::sqrt(double(target_patches)))));
  const double r = 1.0 / side;
  fmt::print("bench_raster: {} fluid triangles, {} patches of r = {:.4f} ({} triangles each), {} threads\n",
             2 * grid_cells * grid_cells, side * side, r, 2 * 12 * 12, thread_count());
  fmt::print("{:>6} {:>10} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>6} {:>7} {:>7}\n", "N", "texels",
             "pass", "setup", "draw", "holes", "resolve", "retire", "dilate", "total", "seam", "born", "retired",
             "RSS GB");
  fmt::print("       (track_pass then output_pass at the same resolution, as a bake with --track-texel at the output's\n"
             "        texel; seconds are wall per step; 'cpu' = process CPU seconds of both passes)\n");
  for (int N : resolutions) {
    const Plane P = make_plane(grid_cells, 16, N, 4);
    PatchSet patches;
    for (int j = 0; j < side; ++j)
      for (int i = 0; i < side; ++i) {
        const uint32_t id = patches.next_id++;
        const Vec3 c{(i + 0.25 + 0.5 * hash_to_unit(hash64(1, id))) * r, (j + 0.25 + 0.5 * hash_to_unit(hash64(2, id))) * r, 0};
        patches.patches.push_back(
            grid_patch(P, c, r, 6.2831853 * hash_to_unit(hash64(3, id)), 12, id, 0.8 + 0.2 * hash_to_unit(hash64(4, id))));
      }
    const PatchMaker maker = [&](const SurfacePoint& at, uint32_t id) -> std::optional<Patch> {
      return grid_patch(P, at.position, r, 6.2831853 * hash_to_unit(hash64(3, id)), 12, id, 1.0);
    };
    RasterOptions o;
    o.radius = r;
    // LAPFLOW_BENCH_MODE=blend|advect benchmarks the other raster modes.
    if (const char* m = std::getenv("LAPFLOW_BENCH_MODE"))
      o.mode = std::string(m) == "blend" ? RasterMode::Blend
                                         : std::string(m) == "advect" ? RasterMode::NoErosion : RasterMode::Erosion;
    const double cpu0 = cpu_seconds();
    const RasterStats t =
        track_pass(P.mesh, P.atlas, rex, o, WeightOptions{}, TriangleLocator{}, 0, maker, patches);
    const FrameTextures out = output_pass(P.mesh, P.atlas, rex, o, WeightOptions{}, TriangleLocator{}, patches);
    const RasterStats& s = out.stats;
    for (const auto& [pass, x] : {std::pair<const char*, const RasterStats&>{"track", t}, {"output", s}})
      fmt::print("{:>6} {:>10} {:>6} {:>7.3f} {:>7.3f} {:>7.3f} {:>7.3f} {:>7.3f} {:>7.3f} {:>7.3f} {:>7} {:>6} {:>7} {:>7.2f}\n",
                 N, x.chart_texels, pass, x.seconds_setup, x.seconds_raster, x.seconds_holes, x.seconds_resolve,
                 x.seconds_retire, x.seconds_dilate, x.seconds_total, x.seam_triangles, x.patches_born,
                 x.patches_retired, peak_rss_gb());
    fmt::print("       cpu {:.3f} s, output digest {:016x}\n", cpu_seconds() - cpu0, digest(out));
    if (t.covered_texels != t.chart_texels)
      fmt::print("  coverage {} of {} chart texels!\n", t.covered_texels, t.chart_texels);
  }
}

}  // namespace lapflow::bench
