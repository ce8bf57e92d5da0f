// Benchmark of the patch stages (issue 3). Targets on the 2-core machine:
// advect + project 1M patch vertices < 0.5 s; create + remesh + flatten a
// ~200-triangle patch < 1 ms; seed a 100k-triangle frame with ~5k patches < 1 s.
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <string>
#include <filesystem>
#include <memory>

#include "bench.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow::bench {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Wall and CPU seconds: on a shared machine the CPU time (all threads) tells
// what the code costs when the wall clock is inflated by other processes.
struct Timer {
  std::chrono::steady_clock::time_point wall = std::chrono::steady_clock::now();
  std::clock_t cpu = std::clock();
  std::string text() const {
    return fmt::format("{:.3f} s wall, {:.3f} s cpu", seconds_since(wall), double(std::clock() - cpu) / CLOCKS_PER_SEC);
  }
};

// Latitude-longitude sphere of 2 * n * n triangles (about 100k for n = 224),
// turned by `angle` about a tilted axis so that two calls with different
// angles give two meshings of the same sphere.
TriMesh uv_sphere(int n, double angle) {
  TriMesh m;
  const Vec3 axis = normalized(Vec3{0.3, 0.2, 1});
  auto turn = [&](const Vec3& v) {
    const double c = std::cos(angle), s = std::sin(angle);
    return v * c + cross(axis, v) * s + axis * (dot(axis, v) * (1 - c));
  };
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i < n; ++i) {
      const double th = M_PI * j / n, ph = 2 * M_PI * (i + 0.5 * (j % 2)) / n;
      m.positions.push_back(turn({std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)}));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * n + i, b = j * n + (i + 1) % n, c = (j + 1) * n + i, d = (j + 1) * n + (i + 1) % n;
      m.triangles.push_back({a, c, d});
      m.triangles.push_back({a, d, b});
    }
  return m;
}

std::size_t vertex_total(const PatchSet& s) {
  std::size_t n = 0;
  for (const Patch& p : s.patches) n += p.positions.size();
  return n;
}

// Seeding/creation variants: no remeshing, then each remesher, then the
// tangent-plane resampling (falling back to the isotropic remesher).
struct CreateVariant {
  bool remesh;
  Remesher remesher;
  const char* label;
};
constexpr CreateVariant kCreateVariants[] = {
    {false, Remesher::Isotropic, " (no remesh)"}, {true, Remesher::CgalIsotropic, " + cgal remesh"}, {true, Remesher::Isotropic, " + isotropic remesh"},
    {true, Remesher::Lattice, " + lattice"}};

void bench_create(const SurfaceQuery& q, double r, const CreateVariant& variant) {
  PatchOptions po;
  po.radius = r;
  po.remesh = variant.remesh;
  po.remesher = variant.remesher;
  const SurfaceAdjacency adj = build_surface_adjacency(q.mesh());
  const auto points = seed_points(q.mesh(), 4 * r, 3);
  const std::size_t n = std::min<std::size_t>(points.size(), 300);
  std::size_t tris = 0;
  const std::clock_t c0 = std::clock();
  for (std::size_t i = 0; i < n; ++i)
    if (auto p = create_patch(q, adj, points[i], uint32_t(i), 0, po, {})) tris += p->triangles.size();
  const double t = double(std::clock() - c0) / CLOCKS_PER_SEC;
  fmt::print("  create_patch{:<15} {:.3f} ms cpu per patch, {:.0f} triangles per patch ({} patches)\n",
             variant.label, 1e3 * t / double(n), double(tris) / double(n), n);
}

void bench_sphere() {
  const TriMesh a = uv_sphere(224, 0.0), b = uv_sphere(224, 0.37);
  const SurfaceQuery qa(a), qb(b);
  fmt::print("synthetic unit sphere, {} triangles, {} threads\n", a.triangles.size(), thread_count());
  const double r = 0.042;  // ~5k patches on the unit sphere
  {
    const Timer t;
    const auto pts = seed_points(a, r, 1);
    fmt::print("  seed_points                 {}, {} samples\n", t.text(), pts.size());
  }
  PatchSet set;
  for (const CreateVariant& variant : kCreateVariants) {
    PatchOptions po;
    po.radius = r;
    po.remesh = variant.remesh;
    po.remesher = variant.remesher;
    PatchSet s;
    const Timer t;
    seed_patches(qa, 0, po, {}, {}, s);
    fmt::print("  seed_patches{:<15} {}, {} patches, {} vertices\n", variant.label, t.text(), s.patches.size(),
               vertex_total(s));
    if (variant.remesh && variant.remesher == PatchOptions{}.remesher) set = std::move(s);  // the default
  }
  set_thread_count(1);
  for (const CreateVariant& variant : kCreateVariants) bench_create(qa, 0.1, variant);
  set_thread_count(0);
  // Advect: rigid spin, frame b is the same sphere meshed differently.
  // Duplicate the patch set until it holds about 1M vertices.
  PatchSet big;
  while (vertex_total(big) < 1000000)
    for (const Patch& p : set.patches) {
      big.patches.push_back(p);
      if (vertex_total(big) >= 1000000) break;
    }
  const Vec3 omega{0, 0, 1.0};
  const VelocityField spin = [omega](const Vec3& x) { return cross(omega, x); };
  PatchOptions po;
  po.radius = r;
  AdvectOptions ao;
  {
    PatchSet s = big;
    const std::size_t nv = vertex_total(s);
    const Timer t;
    const AdvectStats st = advect_patches(qb, spin, spin, po, ao, s);
    update_weights(qb.mesh(), r, {}, s);
    fmt::print("  advect+project (analytic v) {} for {} vertices, {} removed\n", t.text(), nv, st.vertices_removed);
  }
  {
    TriMesh a2 = a, b2 = b;
    a2.velocities.resize(a2.positions.size());
    b2.velocities.resize(b2.positions.size());
    for (std::size_t i = 0; i < a2.positions.size(); ++i) a2.velocities[i] = cross(omega, a2.positions[i]);
    for (std::size_t i = 0; i < b2.positions.size(); ++i) b2.velocities[i] = cross(omega, b2.positions[i]);
    const SurfaceQuery qa2(a2), qb2(b2);
    PatchSet s = big;
    const std::size_t nv = vertex_total(s);
    const Timer t;
    const AdvectStats st = advect_patches(qb2, vertex_velocity_field(qa2), vertex_velocity_field(qb2), po, ao, s);
    update_weights(qb2.mesh(), r, {}, s);
    fmt::print("  advect+project (vertex v)   {} for {} vertices, {} removed\n", t.text(), nv, st.vertices_removed);
    // The bake's default: per-vertex velocities sampled on a band of voxels
    // (BakeOptions::velocity_voxel = 2 mean edges, velocity_band = 6), built
    // as pipeline.cpp's load_frame builds it (on the read-ahead thread there,
    // so the band's construction is timed apart from the advection).
    const BakeOptions bake;
    const Timer tb;
    const VelocityField va = banded_velocity_field(vertex_velocity_field(qa2), a2,
                                                   bake.velocity_voxel * mean_edge_length(a2), bake.velocity_band);
    const VelocityField vb = banded_velocity_field(vertex_velocity_field(qb2), b2,
                                                   bake.velocity_voxel * mean_edge_length(b2), bake.velocity_band);
    const std::string built = tb.text();
    PatchSet s2 = big;
    const Timer t2;
    const AdvectStats st2 = advect_patches(qb2, va, vb, po, ao, s2);
    update_weights(qb2.mesh(), r, {}, s2);
    fmt::print("  advect+project (banded v)   {} for {} vertices, {} removed (2 bands built in {})\n", t2.text(), nv,
               st2.vertices_removed, built);
  }
}

void bench_dam_break(const std::string& data_dir) {
  FrameSource source;  // the bake's velocity rules, exact per-vertex sampling
  source.mesh_pattern = data_dir + "/dam_break/dam_break.%04d.ply";
  source.velocity_band = 0;
  const FramePattern pattern(source.mesh_pattern);
  if (!std::filesystem::exists(pattern.path(1)) || !std::filesystem::exists(pattern.path(2))) {
    fmt::print("dam_break: not found under {}, skipped\n", data_dir);
    return;
  }
  const std::unique_ptr<Frame> a = load_frame(source, 1), b = load_frame(source, 2);
  const SurfaceQuery &qa = *a->surface, &qb = *b->surface;
  fmt::print("dam_break frames 1-2, {} triangles\n", a->mesh.triangles.size());
  for (double r : {0.08, 0.02}) {
    PatchOptions po;
    po.radius = r;
    PatchSet s;
    const Timer t_seed;
    seed_patches(qa, 1, po, {}, {}, s);
    const std::string seeded = t_seed.text();
    const std::size_t nv = vertex_total(s);
    const Timer t;
    const AdvectStats st =
        advect_patches(qb, a->velocity, b->velocity, po, {}, s);
    update_weights(qb.mesh(), r, {}, s);
    fmt::print("  r = {:.2f}: seed_patches {} ({} patches, {} vertices); advect+project {} ({} removed)\n", r, seeded,
               s.patches.size(), nv, t.text(), st.vertices_removed);
  }
}

}  // namespace

// The seeding a bake runs every frame for its stats' `fresh_seeding` (on the
// read-ahead thread): its acceptance is serial. One shared frame of each of
// three scenes, each at a fixed radius (splash at bake-data's 0.028); the
// best of three runs.
void bench_fresh_seeding(const std::string& data_dir) {
  struct Case {
    const char* scene;
    int frame;
    double radius;
  };
  for (const Case& c : {Case{"splash", 10, 0.028}, Case{"dam_break", 20, 0.028}, Case{"channel", 50, 0.044}}) {
    const std::string path = fmt::format("{}/{}/{}.{:04d}.ply", data_dir, c.scene, c.scene, c.frame);
    if (!std::filesystem::exists(path)) {
      fmt::print("fresh seeding: {} not found, skipped\n", path);
      continue;
    }
    const TriMesh mesh = read_mesh(path);
    PatchOptions po;
    po.radius = c.radius;
    double best = INFINITY;
    std::size_t count = 0;
    for (int k = 0; k < 3; ++k) {
      const auto t0 = std::chrono::steady_clock::now();
      count = fresh_seeding_count(mesh, c.frame, po, {});
      best = std::min(best, seconds_since(t0));
    }
    fmt::print("fresh seeding, {} frame {} ({} triangles), r = {}: {} samples in {:.3f} s (best of 3)\n", c.scene,
               c.frame, mesh.triangles.size(), c.radius, count, best);
  }
}

void bench_patches(const std::string& data_dir) {
  bench_sphere();
  bench_dam_break(data_dir);
  bench_fresh_seeding(data_dir);
}

}  // namespace lapflow::bench
