// Hole filling (ALGORITHM.md step 8) for all of a frame's holes at once, the
// paper's suggested future work: instead of a patch at the first open texel
// in scan order (on a hole's rim, so a hole wider than one patch's kept disk
// takes several), every hole gets a patch at its centre. Rounds: label the
// open texels into holes (8-connected within a chart), seed each hole at the
// texel nearest its centroid, plus texel-order seeds 2r apart in holes too big
// for one patch; keep seeds 2r apart in 3D so that the round's patches cannot
// overlap (the result does not depend on the order they are made in); create
// them in parallel, append them in seed order, draw them into the still-open
// texels (their keys are larger than every older patch's, so they never take
// a texel an older patch keeps). Repeat until no hole is left.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <stdexcept>
#include <unordered_set>

#include "core/spaced_points.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "raster/internal.hpp"

namespace lapflow::detail {
namespace {

SurfacePoint texel_surface_point(const RasterContext& ctx, std::size_t i) {
  const int32_t F = ctx.atlas.texels.triangle[i];
  SurfacePoint at;
  at.position = texel_position(ctx, i);
  at.normal = ctx.tri_normal[F];
  at.triangle = F;
  return at;
}

// The chart texels (in texel order) that no patch keeps and `also` accepts,
// gathered on all threads: a serial scan of 25M keys per round showed at
// 6144^2.
template <class Also>
std::vector<uint32_t> uncovered_texels(const RasterContext& ctx, Also&& also) {
  constexpr std::size_t kChunk = std::size_t(1) << 16;
  const std::size_t n = ctx.keys.size(), chunks = (n + kChunk - 1) / kChunk;
  std::vector<std::vector<uint32_t>> parts(chunks);
  parallel_for(chunks, [&](std::size_t b, std::size_t e) {
    for (std::size_t c = b; c < e; ++c)
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i)
        if (ctx.keys[i] == kNoKey && also(i)) parts[c].push_back(uint32_t(i));
  }, 1);
  std::vector<uint32_t> out;
  for (const auto& part : parts) out.insert(out.end(), part.begin(), part.end());
  return out;
}

// Calls f(n) for each chart texel n among chart texel i's 8 neighbours in
// the atlas image (of any chart), rows first.
template <class F>
void for_each_neighbour(const RasterContext& ctx, uint32_t i, F&& f) {
  const TexelMap& tm = ctx.atlas.texels;
  const int N = ctx.N;
  const int x = int(tm.texel[i] % uint32_t(N)), y = int(tm.texel[i] / uint32_t(N));
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int xx = x + dx, yy = y + dy;
      if ((dx == 0 && dy == 0) || xx < 0 || yy < 0 || xx >= N || yy >= N) continue;
      const int32_t n = ctx.index[std::size_t(yy) * N + xx];
      if (n >= 0) f(uint32_t(n));
    }
}

// Whether every covered texel next to a hole (its rim layer `rim`: the
// members with a covered neighbour) is won or closed by a patch at rest.
// The hole's own texels are open (no key), whatever their label.
bool rim_at_rest(const RasterContext& ctx, const PatchSet& patches, const std::vector<uint32_t>& rim) {
  bool any = false, moving = false;
  for (uint32_t i : rim) {
    for_each_neighbour(ctx, i, [&](uint32_t n) {
      if (ctx.keys[n] == kNoKey) return;
      if (patches.patches[std::size_t(ctx.keys[n] >> 32)].at_rest) any = true;
      else moving = true;
    });
    if (moving) return false;
  }
  return any;
}

// How many texel layers hole `id` (its texels `members`, labelled `id`) has
// inside its rim: 1 for texels next to a covered texel of their chart, 2 for
// their other neighbours, ... A hole no covered texel touches (an island of
// its chart's texels that the atlas image cut off from the rest) is measured
// from its own edge instead. The walk goes layer by layer and can be
// continued to a larger limit (a rim at rest may close a deeper hole). It
// marks the members it reached in `label` (-3 - id) and gives them back `id`
// when it ends: no scratch array the size of the atlas.
class HoleDepth {
 public:
  HoleDepth(const RasterContext& ctx, const std::vector<uint32_t>& members, std::vector<int32_t>& label, int32_t id)
      : ctx_(ctx), members_(members), label_(label), id_(id), reached_mark_(-3 - id) {
    for (uint32_t i : members) {
      bool rim = false;
      for_each_neighbour(ctx, i, [&](uint32_t n) { rim = rim || (load(label, n) != id && ctx.keys[n] != kNoKey); });
      if (rim) layer_.push_back(i);
    }
    rim_ = layer_;
    if (layer_.empty())
      for (uint32_t i : members) {
        int inside = 0;  // neighbours in the hole
        for_each_neighbour(ctx, i, [&](uint32_t n) { inside += load(label, n) == id; });
        if (inside < 8) layer_.push_back(i);
      }
    for (uint32_t i : layer_) store(label, i, reached_mark_);
    reached_ = layer_.size();
  }
  ~HoleDepth() {
    for (uint32_t i : members_) store(label_, i, id_);
  }
  HoleDepth(const HoleDepth&) = delete;
  HoleDepth& operator=(const HoleDepth&) = delete;

  // The members with a covered neighbour (none for an island).
  const std::vector<uint32_t>& rim() const { return rim_; }

  // The hole's depth when it is at most `limit`, else limit + 1; a later
  // call with a larger limit continues from the layer this one stopped at.
  int within(int limit) {
    while (!layer_.empty() && depth_ <= limit && reached_ < members_.size()) {
      next_.clear();
      for (uint32_t i : layer_)
        for_each_neighbour(ctx_, i, [&](uint32_t n) {
          if (load(label_, n) != id_) return;  // not in the hole, or reached
          store(label_, n, reached_mark_);
          next_.push_back(n);
        });
      reached_ += next_.size();
      layer_.swap(next_);
      ++depth_;
    }
    return reached_ == members_.size() ? depth_ : limit + 1;
  }

 private:
  // Holes are measured in parallel: another hole's walk may be rewriting the
  // label of a neighbour of this one (never to this hole's id or mark).
  static int32_t load(std::vector<int32_t>& label, uint32_t i) {
    return std::atomic_ref<int32_t>(label[i]).load(std::memory_order_relaxed);
  }
  static void store(std::vector<int32_t>& label, uint32_t i, int32_t v) {
    std::atomic_ref<int32_t>(label[i]).store(v, std::memory_order_relaxed);
  }

  const RasterContext& ctx_;
  const std::vector<uint32_t>& members_;
  std::vector<int32_t>& label_;
  const int32_t id_, reached_mark_;
  std::vector<uint32_t> rim_, layer_, next_;
  std::size_t reached_ = 0;
  int depth_ = 1;
};

}  // namespace

std::size_t create_hole_patches(RasterContext& ctx, PatchSet& patches, int frame, const PatchMaker& make_patch,
                                std::size_t max_patches, std::size_t& closed) {
  const TexelMap& tm = ctx.atlas.texels;
  const int N = ctx.N;
  std::size_t born = 0;
  closed = 0;
  if (!make_patch) throw std::logic_error("create_hole_patches: no patch maker (a render closes holes instead)");
  // Texel layers a hole may have inside its rim and still be closed by its
  // neighbours: its half-width in texels.
  // A hole held only by patches at rest may be up to rest_hole x r wide.
  auto half_width = [&](double width) {
    return ctx.texel_world_size > 0 ? int(std::floor(0.5 * width * ctx.radius / ctx.texel_world_size)) : 0;
  };
  const int max_closed_depth = half_width(ctx.options.small_hole);
  const int max_rest_depth = std::max(max_closed_depth, half_width(ctx.options.rest_hole));
  const bool measure = max_rest_depth > 0;
  std::vector<uint32_t> chart_texels(std::size_t(std::max(ctx.atlas.chart_count, 0)), 0);
  if (measure)
    for (std::size_t i = 0; i < tm.size(); ++i) ++chart_texels[ctx.atlas.chart_of_triangle[tm.triangle[i]]];
  std::vector<uint8_t>& closed_texel = ctx.closed;
  closed_texel.assign(measure ? tm.size() : 0, 0);
  // A fluid triangle where a seed failed (no patch, or a newborn that does
  // not keep its own centre) is not seeded again: its texels go to
  // propagate_keys.
  std::unordered_set<int32_t> failed;
  std::vector<int32_t> label;  // per chart texel: hole id this round, -1 none
  std::vector<uint32_t> open, queue;
  const double spacing = 2 * ctx.radius;
  const Box3 mesh_box = bounding_box(ctx.mesh);  // every round's seed grid covers it
  for (int round = 0; born < max_patches; ++round) {
    auto still_open = [&](std::size_t i) {
      return (closed_texel.empty() || !closed_texel[i]) && (failed.empty() || !failed.count(tm.triangle[i]));
    };
    // A round only covers, closes or gives up texels: the next round's open
    // texels are among this round's (the whole atlas is scanned once).
    if (round == 0)
      open = uncovered_texels(ctx, still_open);
    else
      std::erase_if(open, [&](uint32_t i) { return ctx.keys[i] != kNoKey || !still_open(i); });
    if (open.empty()) break;
    if (label.empty()) {
      label.resize(tm.size());
      parallel_for(tm.size(), [&](std::size_t b, std::size_t e) { std::fill(&label[b], &label[e - 1] + 1, -1); },
                   1 << 16);
    }
    for (uint32_t i : open) label[i] = -2;  // open, not yet labelled

    // Holes in texel order of their first texel (a serial flood fill), each
    // measured and given its seed candidates on its own (in parallel), then
    // seeds in hole order.
    struct Hole {
      std::vector<uint32_t> members;
      double sx = 0, sy = 0;
      int chart = 0;
      bool closed = false;
      std::vector<Vec3> at;  // the centre's surface point, then the members' in texel order
      uint32_t centre = 0;
    };
    std::vector<Hole> found;
    for (uint32_t start : open) {
      if (label[start] != -2) continue;
      Hole& h = found.emplace_back();
      h.chart = ctx.atlas.chart_of_triangle[tm.triangle[start]];
      const int32_t id = int32_t(found.size() - 1);
      queue.assign(1, start);
      label[start] = id;
      for (std::size_t q = 0; q < queue.size(); ++q) {
        const uint32_t i = queue[q];
        h.members.push_back(i);
        const int x = int(tm.texel[i] % uint32_t(N)), y = int(tm.texel[i] / uint32_t(N));
        h.sx += x, h.sy += y;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= N || yy >= N) continue;
            const int32_t n = ctx.index[std::size_t(yy) * N + xx];
            if (n < 0 || label[n] != -2 || ctx.atlas.chart_of_triangle[tm.triangle[n]] != h.chart) continue;
            label[n] = id;
            queue.push_back(uint32_t(n));
          }
      }
    }
    parallel_for(found.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t k = b; k < e; ++k) {
        Hole& h = found[k];
        // A hole no wider than RasterOptions::small_hole x r is closed by the
        // patches around it (propagate_keys) instead of a new patch:
        // re-meshing alone opens holes of a texel or two at the patches' eroded
        // edges every frame, and slivers along a slowly spreading rim, and a
        // full patch born for each would churn the texture and grow the
        // population without bound. A hole that is its whole chart has no
        // neighbour to close it and always gets a patch.
        // A still liquid that spreads slowly (below --min-speed) uncovers a
        // strip at its rim a texel or so a frame, which outgrows small_hole in
        // a few frames: where only patches at rest hold its rim, the strip is
        // continued by them up to rest_hole x r (RasterOptions::rest_hole).
        // The deeper walk only for a rim at rest: most holes are next to moving
        // patches, and a walk to rest_hole's depth costs up to 8x more layers.
        // Holes are disjoint: each walk marks and reads only its own members'
        // labels as its own (another hole's are never its id or its mark).
        if (measure && h.members.size() < chart_texels[std::size_t(h.chart)]) {
          HoleDepth depth(ctx, h.members, label, int32_t(k));
          h.closed = depth.within(max_closed_depth) <= max_closed_depth;
          if (!h.closed && max_rest_depth > max_closed_depth && rim_at_rest(ctx, patches, depth.rim()))
            h.closed = depth.within(max_rest_depth) <= max_rest_depth;
          if (h.closed) continue;
        }
        // The member nearest the centroid (ties: lowest texel index), then, for
        // holes wider than one patch, members in texel order 2r apart.
        std::sort(h.members.begin(), h.members.end());
        const double cx = h.sx / double(h.members.size()), cy = h.sy / double(h.members.size());
        h.centre = h.members[0];
        double best = INFINITY;
        for (uint32_t i : h.members) {
          const double dx = double(tm.texel[i] % uint32_t(N)) - cx, dy = double(tm.texel[i] / uint32_t(N)) - cy;
          if (dx * dx + dy * dy < best) best = dx * dx + dy * dy, h.centre = i;
        }
        h.at.reserve(h.members.size() + 1);
        h.at.push_back(texel_position(ctx, h.centre));
        for (uint32_t i : h.members) h.at.push_back(texel_position(ctx, i));
      }
    }, 1);
    std::vector<uint32_t> seeds;
    SpacedPoints grid(spacing, mesh_box);
    for (const Hole& h : found) {
      if (h.closed) {
        for (uint32_t i : h.members) closed_texel[i] = 1;
        closed += h.members.size();
        continue;
      }
      for (std::size_t k = 0; k < h.at.size(); ++k) {
        if (!grid.free(h.at[k])) continue;
        grid.add(h.at[k]);
        seeds.push_back(k == 0 ? h.centre : h.members[k - 1]);
      }
    }
    for (uint32_t i : open) label[i] = -1;
    if (seeds.size() > max_patches - born) seeds.resize(max_patches - born);

    // Create in parallel (ids in seed order), append in seed order.
    std::vector<std::optional<Patch>> made(seeds.size());
    const uint32_t first_id = patches.next_id;
    parallel_for(seeds.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t k = b; k < e; ++k) {
        const SurfacePoint at = texel_surface_point(ctx, seeds[k]);
        if (norm2(at.normal) > 0) made[k] = make_patch(at, first_id + uint32_t(k));
      }
    }, 1);
    patches.next_id = first_id + uint32_t(seeds.size());
    const std::size_t first_index = patches.patches.size();
    for (std::size_t k = 0; k < seeds.size(); ++k) {
      if (!made[k] || !made[k]->alive()) {
        failed.insert(tm.triangle[seeds[k]]);
        continue;
      }
      made[k]->id = first_id + uint32_t(k);
      made[k]->birth_frame = frame;
      patches.patches.push_back(std::move(*made[k]));
      ++born;
    }
    if (ctx.mode == RasterMode::Blend) ctx.blend.contributed.resize(patches.patches.size(), 0);
    std::vector<RasterCounters> counters(patches.patches.size() - first_index);
    parallel_for(counters.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t k = b; k < e; ++k)
        rasterize_patch(ctx, patches.patches[first_index + k], first_index + k, counters[k]);
    }, 1);
    if (ctx.mode == RasterMode::Blend) blend_mark_coverage(ctx);
    for (uint32_t i : seeds)
      if (ctx.keys[i] == kNoKey) failed.insert(tm.triangle[i]);
  }
  return born;
}

// Calls f(n) for each of chart texel i's 8 neighbours in the same chart.
template <class F>
static void for_each_chart_neighbour(const RasterContext& ctx, uint32_t i, F&& f) {
  const TexelMap& tm = ctx.atlas.texels;
  const int chart = ctx.atlas.chart_of_triangle[tm.triangle[i]];
  for_each_neighbour(ctx, i, [&](uint32_t n) {
    if (ctx.atlas.chart_of_triangle[tm.triangle[n]] == chart) f(int32_t(n));
  });
}

static void mark_extrapolated(RasterContext& ctx, uint32_t i) {
  if (ctx.extrapolated.empty()) ctx.extrapolated.assign(ctx.keys.size(), 0);
  ctx.extrapolated[i] = 1;
}

std::size_t close_held_texels(RasterContext& ctx, const PatchSet& patches) {
  if (!ctx.hold) return 0;
  const TexelMap& tm = ctx.atlas.texels;
  const int N = ctx.N;
  std::size_t closed = 0;
  // Jacobi sweeps: a held point at most two texel layers into a hole; deeper
  // only for a patch at rest, whose closed regions are held too (resolve),
  // so that a region held still stays with its patch however wide it grew.
  // A patch the flow moves keeps only the two layers: its erosion goes on.
  constexpr int kAnySweeps = 2, kMaxSweeps = 64;
  std::vector<uint32_t> open = uncovered_texels(ctx, [](std::size_t) { return true; });
  std::vector<uint64_t> next;
  std::vector<uint32_t> still;
  for (int sweep = 0; sweep < kMaxSweeps && !open.empty(); ++sweep) {
    const bool rest_only = sweep >= kAnySweeps;
    next.assign(open.size(), kNoKey);
    parallel_for(open.size(), [&](std::size_t b, std::size_t e) {
      std::vector<uint64_t> tried;
      // winner_pixels by (key, texel triangle): neighbouring open texels ask
      // for the same few (a pure function, so a hit changes no result).
      struct Cached {
        uint64_t key = kNoKey;
        int tri = -1;
        bool ok = false;
        Vec2 P[3];
      };
      constexpr int kCacheBits = 6;
      std::array<Cached, std::size_t(1) << kCacheBits> cache;
      for (std::size_t j = b; j < e; ++j) {
        const uint32_t i = open[j];
        const int tri = tm.triangle[i];
        const int x = int(tm.texel[i] % uint32_t(N)), y = int(tm.texel[i] / uint32_t(N));
        tried.clear();
        uint64_t best = kNoKey;
        for_each_chart_neighbour(ctx, i, [&](int32_t n) {
          const uint64_t key = ctx.keys[n];
          if (key == kNoKey || key >= best || std::find(tried.begin(), tried.end(), key) != tried.end()) return;
          tried.push_back(key);
          const Patch& patch = patches.patches[std::size_t(key >> 32)];
          if (patch.held.empty() || (rest_only && !patch.at_rest)) return;
          const int ti = int(key & 0xffffffffu);
          Cached& c = cache[((key ^ uint64_t(uint32_t(tri)) << 20) * 0x9E3779B97F4A7C15ull) >> (64 - kCacheBits)];
          if (c.key != key || c.tri != tri) c.key = key, c.tri = tri, c.ok = winner_pixels(ctx, patch, ti, tri, c.P);
          if (!c.ok) return;
          const Vec2* P = c.P;
          const Vec2 e1 = P[1] - P[0], e2 = P[2] - P[0];
          const double a = cross(e1, e2);
          if (!(std::abs(a) > 1e-12)) return;
          const Vec2 d{x - P[0].x, y - P[0].y};
          const double l1 = cross(d, e2) / a, l2 = cross(e1, d) / a, l0 = 1 - l1 - l2;
          const Tri& t = patch.triangles[ti];
          const double u = l0 * patch.rest_uv[t[0]].x + l1 * patch.rest_uv[t[1]].x + l2 * patch.rest_uv[t[2]].x;
          const double v = l0 * patch.rest_uv[t[0]].y + l1 * patch.rest_uv[t[1]].y + l2 * patch.rest_uv[t[2]].y;
          if (held_at(patch.held, u, v)) best = key;
        });
        next[j] = best;
      }
    }, 256);
    std::size_t changed = 0;
    still.clear();
    for (std::size_t j = 0; j < open.size(); ++j) {
      if (next[j] == kNoKey) {
        still.push_back(open[j]);
        continue;
      }
      ctx.keys[open[j]] = next[j], mark_extrapolated(ctx, open[j]), ++changed;
    }
    closed += changed;
    if (changed == 0) break;
    open.swap(still);
  }
  return closed;
}

std::size_t propagate_keys(RasterContext& ctx, std::vector<uint32_t>* left) {
  std::vector<uint32_t> open = uncovered_texels(ctx, [](std::size_t) { return true; });
  std::size_t filled = 0;
  std::vector<uint64_t> next(open.size());
  while (!open.empty()) {
    next.resize(open.size());
    // Jacobi sweep: read the keys of the previous sweep only.
    parallel_for(open.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t j = b; j < e; ++j) {
        uint64_t best = kNoKey;
        for_each_chart_neighbour(ctx, open[j], [&](int32_t n) { best = std::min(best, ctx.keys[n]); });
        next[j] = best;
      }
    }, 1024);
    std::vector<uint32_t> still;
    std::size_t changed = 0;
    for (std::size_t j = 0; j < open.size(); ++j) {
      if (next[j] == kNoKey) {
        still.push_back(open[j]);
      } else {
        ctx.keys[open[j]] = next[j];
        mark_extrapolated(ctx, open[j]);
        ++changed;
      }
    }
    filled += changed;
    open.swap(still);
    if (changed == 0) break;  // charts no patch reaches at all
  }
  if (left) *left = std::move(open);
  return filled;
}

std::size_t cover_from_nearest_patch(RasterContext& ctx, const PatchSet& patches, const std::vector<uint32_t>& open) {
  const TexelMap& tm = ctx.atlas.texels;
  if (open.empty() || patches.patches.empty()) return 0;
  // Bounding boxes of the patches: most are skipped on one box distance.
  const std::size_t np = patches.patches.size();
  std::vector<Vec3> lo(np, Vec3{INFINITY, INFINITY, INFINITY}), hi(np, Vec3{-INFINITY, -INFINITY, -INFINITY});
  parallel_for(np, [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p)
      for (const Vec3& q : patches.patches[p].positions) {
        lo[p] = {std::min(lo[p].x, q.x), std::min(lo[p].y, q.y), std::min(lo[p].z, q.z)};
        hi[p] = {std::max(hi[p].x, q.x), std::max(hi[p].y, q.y), std::max(hi[p].z, q.z)};
      }
  }, 64);
  std::vector<uint64_t> found(open.size(), kNoKey);
  parallel_for(open.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t j = b; j < e; ++j) {
      const uint32_t i = open[j];
      const Vec3 x = texel_surface_point(ctx, i).position;
      const int F = tm.triangle[i];
      double best = INFINITY;
      uint64_t best_key = kNoKey;
      for (std::size_t p = 0; p < np; ++p) {
        const Vec3 d{std::max({lo[p].x - x.x, 0.0, x.x - hi[p].x}), std::max({lo[p].y - x.y, 0.0, x.y - hi[p].y}),
                     std::max({lo[p].z - x.z, 0.0, x.z - hi[p].z})};
        if (norm2(d) > best) continue;
        const Patch& patch = patches.patches[p];
        if (patch.rest_uv.size() != patch.positions.size()) continue;
        for (std::size_t t = 0; t < patch.triangles.size(); ++t) {
          const Tri& T = patch.triangles[t];
          const double d2 =
              norm2(closest_point_on_triangle(x, patch.positions[T[0]], patch.positions[T[1]], patch.positions[T[2]])
                        .point - x);
          const uint64_t key = make_key(p, t);
          if (d2 > best || (d2 == best && key >= best_key)) continue;
          // Only a triangle whose map extends to this texel (non-degenerate
          // through its fluid triangle), so the resolve gives it (u, v).
          Vec2 P[3];
          if (!winner_pixels(ctx, patch, int(t), F, P)) continue;
          if (!(std::abs(cross(P[1] - P[0], P[2] - P[0])) > 1e-12)) continue;
          best = d2, best_key = key;
        }
      }
      found[j] = best_key;
    }
  }, 1);
  std::size_t filled = 0;
  for (std::size_t j = 0; j < open.size(); ++j)
    if (found[j] != kNoKey) ctx.keys[open[j]] = found[j], mark_extrapolated(ctx, open[j]), ++filled;
  return filled;
}

}  // namespace lapflow::detail

namespace lapflow {

using namespace detail;

namespace {

/// fill_holes, and close_holes when `make_patch` is empty: then `patches`
/// is only read.
void fill_or_close_holes(RasterBuffers& r, PatchSet& patches, int frame, const PatchMaker& make_patch) {
  RasterContext& ctx = *r.context;
  RasterStats& st = r.stats;
  const RasterOptions& options = ctx.options;
  const bool blend = options.mode == RasterMode::Blend;
  if (blend) blend_mark_coverage(ctx);
  std::size_t closed = 0;
  // A hole texel whose neighbour's patch held that very point before (its
  // map extended to the texel lands in a held cell) goes back to that patch:
  // the hold where the sample fell just past the patch's triangles or its
  // test. It marks nothing in Patch::held, so the held region cannot creep.
  if (options.fill_holes) st.held_texels = close_held_texels(ctx, patches);
  ctx.newborn_from = patches.patches.size();
  // A render has no birth to make and no hole to measure: it closes whatever
  // the tracking's decisions left open (below), and skips the hole labelling
  // (an int per chart texel) altogether.
  if (options.fill_holes && make_patch)
    st.patches_born += create_hole_patches(ctx, patches, frame, make_patch, options.max_hole_patches, closed);
  if (blend) {
    // The AOV winners (largest weight, ties to the oldest): a second raster
    // pass now that every texel's maximum is known.
    std::fill(ctx.keys.begin(), ctx.keys.end(), kNoKey);
    ctx.blend.phase = 2;
    parallel_for(patches.patches.size(), [&](std::size_t b, std::size_t e) {
      RasterCounters unused;
      for (std::size_t p = b; p < e; ++p) rasterize_patch(ctx, patches.patches[p], p, unused);
    }, 1);
  }
  // Texels hole filling could not reach (create_patch failed there, or the
  // newborn does not keep its own centre) still need a patch: they take a
  // covered neighbour's winner within their chart, and in charts with none,
  // the nearest patch triangle in 3D. Counted in forced_texels. Without hole
  // filling the holes are left visible (alpha 0).
  if (options.fill_holes) {
    // The small holes left to their neighbours are closed here too (an
    // island of a chart's texels that no covered texel touches, by the
    // nearest patch in 3D); whatever else is filled is forced.
    std::vector<uint32_t> left;
    const std::size_t propagated = propagate_keys(ctx, &left);
    const std::size_t nearest = cover_from_nearest_patch(ctx, patches, left);
    // A render (no maker) has no birth to wait for: whatever its neighbours
    // close is closed, wherever the tracking's decisions left it open.
    if (!make_patch) closed = propagated;
    const std::size_t filled = make_patch ? propagated + nearest : propagated;
    st.closed_texels += std::min(closed, filled);
    st.forced_texels += propagated + nearest - std::min(closed, filled);
  }
}

}  // namespace

void fill_holes(RasterBuffers& r, PatchSet& patches, int frame, const PatchMaker& make_patch) {
  fill_or_close_holes(r, patches, frame, make_patch);
}

void close_holes(RasterBuffers& r, const PatchSet& patches) {
  // Without a maker nothing is appended and no field of `patches` written.
  fill_or_close_holes(r, const_cast<PatchSet&>(patches), 0, {});
}

}  // namespace lapflow
