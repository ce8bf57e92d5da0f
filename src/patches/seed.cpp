// ALGORITHM.md step 1: Poisson-disk seeding of the first frame.
//
// Distance is EUCLIDEAN and measured only between samples of the same
// connected component (triangles sharing vertices): a patch never crosses to
// another component, so a droplet next to the main body needs patches of its
// own however close it is. Every component with non-zero area gets at least
// one sample.
//
// Method: dart throwing over area-weighted random surface points, candidate i
// drawn from hash64(seed, i) (about 40 candidates per expected sample, so the
// chance that a disk-sized gap gets no candidate is below e^-100), accepted in
// candidate order against a grid of cells (SampleGrid); then a
// maximal-coverage pass offers every triangle's centroid and corners in
// triangle order, which fills what chance left and gives tiny components
// their sample. Candidates are generated
// in parallel by index and accepted serially, so the result is the same at any
// thread count.
#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <unordered_map>

#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"

namespace lapflow {
namespace {

struct Candidate {
  Vec3 position;
  int triangle = -1;
};

// Accepted samples bucketed on cells of the minimum distance. Over the mesh's
// bounding box (two cells of margin) a dense array of per-cell lists: the
// accept loop is serial and asks 27 cells for each of its ~40 candidates per
// sample, which a hash map answered at about a fifth of a second per
// 80k-triangle frame. Cells outside it (a box too large for the array, or a
// point rounded past the box) go to a hash map; either way `free` answers
// the same question, so the samples do not depend on which holds a cell.
class SampleGrid {
 public:
  SampleGrid(double cell, const Box3& box) : cell_(cell), origin_(box.lo) {
    if (box.empty()) return;
    const Vec3 size = box.size();
    const double n[3] = {size.x / cell, size.y / cell, size.z / cell};
    double cells = 1;
    for (int k = 0; k < 3; ++k) {
      if (!(n[k] >= 0 && n[k] < 1e8)) return;  // NaN, or far too many cells
      dims_[k] = int64_t(n[k]) + 1 + 2 * kMargin;
      cells *= double(dims_[k]);
    }
    if (cells > double(kMaxDenseCells)) return;
    head_.assign(std::size_t(cells), -1);
  }
  // True when no accepted sample of `component` lies closer than `d` to p.
  bool free(const Vec3& p, int component, double d2, const std::vector<Vec3>& pos,
            const std::vector<int>& comp) const {
    auto close = [&](int s) { return comp[s] == component && norm2(pos[s] - p) < d2; };
    const auto c = cell_of(p);
    for (int64_t dz = -1; dz <= 1; ++dz)
      for (int64_t dy = -1; dy <= 1; ++dy)
        for (int64_t dx = -1; dx <= 1; ++dx) {
          const int64_t x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
          if (const int64_t slot = dense_slot(x, y, z); slot >= 0) {
            for (int s = head_[std::size_t(slot)]; s >= 0; s = next_[std::size_t(s)])
              if (close(s)) return false;
            continue;
          }
          auto it = cells_.find(key(x, y, z));
          if (it == cells_.end()) continue;
          if (std::any_of(it->second.begin(), it->second.end(), close)) return false;
        }
    return true;
  }
  // Samples are numbered 0, 1, 2, ... in insertion order.
  void insert(const Vec3& p, int sample) {
    const auto c = cell_of(p);
    next_.resize(std::max(next_.size(), std::size_t(sample) + 1), -1);
    if (const int64_t slot = dense_slot(c[0], c[1], c[2]); slot >= 0) {
      next_[std::size_t(sample)] = head_[std::size_t(slot)];
      head_[std::size_t(slot)] = sample;
      return;
    }
    cells_[key(c[0], c[1], c[2])].push_back(sample);
  }

 private:
  static constexpr int64_t kMargin = 2;
  static constexpr std::size_t kMaxDenseCells = std::size_t(1) << 23;  // 32 MiB of heads
  std::array<int64_t, 3> cell_of(const Vec3& p) const {
    return {int64_t(std::floor((p.x - origin_.x) / cell_)), int64_t(std::floor((p.y - origin_.y) / cell_)),
            int64_t(std::floor((p.z - origin_.z) / cell_))};
  }
  // Index into head_ of cell (x, y, z), or -1 when the array does not hold it.
  int64_t dense_slot(int64_t x, int64_t y, int64_t z) const {
    if (head_.empty()) return -1;
    x += kMargin, y += kMargin, z += kMargin;
    if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return -1;
    return (z * dims_[1] + y) * dims_[0] + x;
  }
  static uint64_t key(int64_t x, int64_t y, int64_t z) {
    return (uint64_t(x & 0x1fffff) << 42) | (uint64_t(y & 0x1fffff) << 21) | uint64_t(z & 0x1fffff);
  }
  double cell_;
  Vec3 origin_;
  int64_t dims_[3] = {0, 0, 0};
  std::vector<int> head_, next_;  // per dense cell its last sample, per sample the one inserted before it
  std::unordered_map<uint64_t, std::vector<int>> cells_;
};

}  // namespace

std::vector<SurfacePoint> seed_points(const TriMesh& mesh, double min_distance, uint64_t seed) {
  std::vector<SurfacePoint> out;
  const std::size_t nt = mesh.triangles.size();
  if (nt == 0 || !(min_distance > 0)) return out;
  std::vector<double> cdf(nt);
  double total = 0;
  for (std::size_t t = 0; t < nt; ++t) cdf[t] = total += triangle_area(mesh, int(t));
  if (!(total > 0)) return out;
  std::vector<int> component;
  triangle_components(mesh, component);

  // Dense packings hold about 1/(0.87 d^2) samples per unit area; random
  // sequential ones about half that.
  const double expected = total / (min_distance * min_distance);
  const std::size_t n_cand = std::size_t(std::min(40.0 * expected + 64, 5e8));
  std::vector<Candidate> cand(n_cand);
  parallel_for(n_cand, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const uint64_t h = hash64(seed, i, 0x5eedull);
      const double x = hash_to_unit(h) * total;
      std::size_t t = std::upper_bound(cdf.begin(), cdf.end(), x) - cdf.begin();
      if (t >= nt) t = nt - 1;
      double s = hash_to_unit(hash64(h, 1)), u = hash_to_unit(hash64(h, 2));
      if (s + u > 1) s = 1 - s, u = 1 - u;
      const Tri& f = mesh.triangles[t];
      const Vec3& a = mesh.positions[f[0]];
      cand[i] = {a + (mesh.positions[f[1]] - a) * s + (mesh.positions[f[2]] - a) * u, int(t)};
    }
  }, 4096);

  SampleGrid grid(min_distance, bounding_box(mesh));
  const double d2 = min_distance * min_distance;
  std::vector<Vec3> pos;
  std::vector<int> comp;
  auto offer = [&](const Vec3& p, int t) {
    if (!grid.free(p, component[t], d2, pos, comp)) return;
    const Vec3 n = normalized(triangle_normal_area2(mesh, t));
    grid.insert(p, int(pos.size()));
    pos.push_back(p);
    comp.push_back(component[t]);
    out.push_back({p, n, t});
  };
  for (const Candidate& c : cand) offer(c.position, c.triangle);
  for (std::size_t t = 0; t < nt; ++t) {
    if (!(triangle_area(mesh, int(t)) > 0)) continue;
    const Tri& f = mesh.triangles[t];
    offer((mesh.positions[f[0]] + mesh.positions[f[1]] + mesh.positions[f[2]]) / 3.0, int(t));
    for (int k = 0; k < 3; ++k) offer(mesh.positions[f[k]], int(t));
  }
  return out;
}

namespace {

std::vector<SurfacePoint> frame_seed_points(const TriMesh& mesh, int frame, const PatchOptions& options,
                                            const SeedOptions& seeding) {
  return seed_points(mesh, seeding.spacing * options.radius, hash64(options.seed, uint64_t(frame), 0x5eedull));
}

}  // namespace

std::size_t fresh_seeding_count(const TriMesh& mesh, int frame, const PatchOptions& options,
                                const SeedOptions& seeding) {
  return frame_seed_points(mesh, frame, options, seeding).size();
}

void seed_patches(const SurfaceQuery& surface, int frame, const PatchOptions& options, const SeedOptions& seeding,
                  const WeightOptions& weights, PatchSet& patches) {
  const TriMesh& mesh = surface.mesh();
  const std::vector<SurfacePoint> points = frame_seed_points(mesh, frame, options, seeding);
  const SurfaceAdjacency adjacency = build_surface_adjacency(mesh);
  std::vector<std::optional<Patch>> created(points.size());
  const uint32_t first_id = patches.next_id;
  parallel_for(points.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i)
      created[i] = create_patch(surface, adjacency, points[i], first_id + uint32_t(i), frame, options, weights);
  }, 4);
  patches.next_id = first_id + uint32_t(points.size());
  for (auto& p : created)
    if (p) patches.patches.push_back(std::move(*p));
}

}  // namespace lapflow
