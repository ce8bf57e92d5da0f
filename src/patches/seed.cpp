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
// candidate order against the kept samples (detail::SpacedPoints, grouped by
// component); then a maximal-coverage pass offers every triangle's centroid
// and corners in triangle order, which fills what chance left and gives tiny
// components their sample. Candidates are generated in parallel by index and
// accepted serially, so the result is the same at any thread count.
#include <algorithm>
#include <cmath>
#include <optional>

#include "core/spaced_points.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"

namespace lapflow {
namespace {

struct Candidate {
  Vec3 position;
  int triangle = -1;
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

  detail::SpacedPoints kept(min_distance, bounding_box(mesh));
  auto offer = [&](const Vec3& p, int t) {
    if (!kept.free(p, component[t])) return;
    kept.add(p, component[t]);
    out.push_back({p, normalized(triangle_normal_area2(mesh, t)), t});
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
