// The built-in demo scene: a shape carried by an analytic, time-reversing
// velocity field, re-meshed from its level set every frame (OpenVDB
// volumeToMesh), with exact per-vertex velocities.
//
// Both fields have the form u(x, t) = U(x) g(t) with g(t) = cos(pi t / T).
// A trajectory of such a field is a trajectory of the steady field U run for
// the pseudo-time tau(t) = integral_0^t g = (T / pi) sin(pi t / T). So the
// liquid at time t is exactly the initial shape pushed by U for tau(t), and a
// point x is liquid iff U run backward from x for tau(t) lands inside the
// initial shape. We integrate that backward trace with RK4 (steady field, so
// no time interpolation) at the voxels near the surface, and mesh the zero
// set of phi(x) = distance-like function of the start shape at X0(x). Because
// tau(T) = 0 exactly, the frame at t = T is the start shape again.
#include "lapflow/addons/demo_scene.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <tuple>
#include <stdexcept>
#include <vector>

#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Vortex: Enright et al. 2002 start shape.
constexpr Vec3 kSphereCentre{0.35, 0.35, 0.35};
constexpr double kSphereRadius = 0.15;

// Slab: LeVeque's 2D single vortex in (x, y), constant in z. A thin disk-shaped
// slab (the disk of LeVeque's test, 4 cm thick) is wound into a spiral whose
// tail thins below the voxel size and breaks off (split), then winds back and
// rejoins (merge) as the field reverses. The swirl is faster than the 3D field
// so that the spiral forms within one default period.
constexpr double kSlabSpeed = 3.0;  // m/s peak factor of the swirl
constexpr double kSlabCx = 0.5, kSlabCy = 0.75, kSlabRadius = 0.15;
constexpr double kSlabZ = 0.5, kSlabHalfThickness = 0.02;

// RK4 step of the backward trace in pseudo-time (seconds): a sixteenth of a
// metre at the peak speed. The field's wavelength is 1 m; against a much
// finer trace the surface moves by a fraction of a voxel (most on the slab,
// whose spiral tail is squeezed hard), at a fraction of the cost
// (docs/performance.md, "Figures from code comments").
double trace_step(DemoCase scene) { return 1.0 / (16 * (scene == DemoCase::Vortex ? 2.0 : kSlabSpeed)); }

double pseudo_time(double t, double period) { return period / kPi * std::sin(kPi * t / period); }

/// U(x): the field without its time factor.
Vec3 steady_velocity(DemoCase scene, const Vec3& p) {
  // sin(2a) = 2 sin(a) cos(a): three sincos calls per evaluation, not six.
  const double sx = std::sin(kPi * p.x), cx = std::cos(kPi * p.x);
  const double sy = std::sin(kPi * p.y), cy = std::cos(kPi * p.y);
  const double s2x = 2 * sx * cx, s2y = 2 * sy * cy;
  if (scene == DemoCase::Vortex) {
    const double sz = std::sin(kPi * p.z), cz = std::cos(kPi * p.z);
    const double s2z = 2 * sz * cz;
    return {2 * sx * sx * s2y * s2z, -s2x * sy * sy * s2z, -s2x * s2y * sz * sz};
  }
  return {kSlabSpeed * sx * sx * s2y, -kSlabSpeed * s2x * sy * sy, 0.0};
}

/// Runs the steady field for pseudo-time `tau` (negative = backward) with RK4.
Vec3 flow(DemoCase scene, Vec3 x, double tau) {
  if (tau == 0) return x;
  const int steps = std::max(1, int(std::ceil(std::abs(tau) / trace_step(scene))));
  const double h = tau / steps;
  for (int i = 0; i < steps; ++i) {
    const Vec3 k1 = steady_velocity(scene, x);
    const Vec3 k2 = steady_velocity(scene, x + k1 * (0.5 * h));
    const Vec3 k3 = steady_velocity(scene, x + k2 * (0.5 * h));
    const Vec3 k4 = steady_velocity(scene, x + k3 * h);
    x += (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (h / 6.0);
  }
  return x;
}

/// Signed distance (metres) to the start shape: negative inside.
double start_phi(DemoCase scene, const Vec3& x0) {
  if (scene == DemoCase::Vortex) return norm(x0 - kSphereCentre) - kSphereRadius;
  const double radial = std::hypot(x0.x - kSlabCx, x0.y - kSlabCy) - kSlabRadius;
  const double vertical = std::abs(x0.z - kSlabZ) - kSlabHalfThickness;
  return std::max(radial, vertical);
}

struct Key {
  int32_t i, j, k;
};

// The level set on the lattice of world points (i, j, k) * h, evaluated only
// where the surface can be: coarse-to-fine, a cell of side s*h is refined when
// a corner is within margin(s) * s * h of the surface or its corners disagree
// in sign. A margin m lets |grad phi| reach m / (sqrt(3)/2) before a crossing
// can hide inside a cell; |grad phi| is the squeeze of the start shape, large
// in the thin sheets and spiral tails, so coarse cells (which would lose a
// whole sheet) get a wide margin, and the finest cells (where only sub-voxel
// slivers can hide, and where nearly all the trace cost is) a narrow one.
double refine_margin(int s) { return s >= 4 ? 4.0 : 1.0; }

openvdb::FloatGrid::Ptr build_level_set(DemoCase scene, double tau, double h) {
  const int n = int(std::ceil(1.0 / h - 1e-9));  // lattice nodes 0..n span the unit box
  int s = 1;
  while (s * 16 <= n) s *= 2;  // top level: at most ~16-32 cells across
  s = std::max(s, 1);
  const double background = 3 * h;
  auto grid = openvdb::FloatGrid::create(float(background));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(h));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);

  // Values of all evaluated nodes, looked up through a sparse VDB grid of the
  // same lattice (serial writes; the costly trace is the parallel part).
  auto values = openvdb::FloatGrid::create(std::numeric_limits<float>::max());
  auto acc = values->getAccessor();
  auto phi_at = [&](const Key& q) {
    const Vec3 x{q.i * h, q.j * h, q.k * h};
    return start_phi(scene, flow(scene, x, -tau));
  };
  auto evaluate = [&](std::vector<Key>& keys) {
    std::sort(keys.begin(), keys.end(), [](const Key& a, const Key& b) {
      return std::tie(a.i, a.j, a.k) < std::tie(b.i, b.j, b.k);
    });
    keys.erase(std::unique(keys.begin(), keys.end(),
                           [](const Key& a, const Key& b) { return a.i == b.i && a.j == b.j && a.k == b.k; }),
               keys.end());
    // Drop nodes already known from a coarser level.
    std::vector<Key> todo;
    todo.reserve(keys.size());
    for (const Key& q : keys)
      if (!acc.isValueOn(openvdb::Coord(q.i, q.j, q.k))) todo.push_back(q);
    std::vector<float> phi(todo.size());
    parallel_for(todo.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) phi[i] = float(phi_at(todo[i]));
    }, 64);
    for (std::size_t i = 0; i < todo.size(); ++i)
      acc.setValueOn(openvdb::Coord(todo[i].i, todo[i].j, todo[i].k), phi[i]);
  };

  // Top level: every node at spacing s.
  std::vector<Key> cells;  // lower corners of the active cells at the current level
  {
    std::vector<Key> keys;
    for (int i = 0; i <= n; i += s)
      for (int j = 0; j <= n; j += s)
        for (int k = 0; k <= n; k += s) keys.push_back({i, j, k});
    evaluate(keys);
    for (int i = 0; i < n; i += s)
      for (int j = 0; j < n; j += s)
        for (int k = 0; k < n; k += s) cells.push_back({i, j, k});
  }
  auto corner = [&](int i, int j, int k) {
    // Nodes past the lattice edge lie outside the unit box: never liquid.
    if (i > n || j > n || k > n) return float(background);
    return acc.getValue(openvdb::Coord(i, j, k));
  };
  auto active = [&](const Key& c, int step) {
    float lo = std::numeric_limits<float>::max(), hi = -lo, closest = lo;
    for (int d = 0; d < 8; ++d) {
      const float v = corner(c.i + (d & 1) * step, c.j + ((d >> 1) & 1) * step, c.k + ((d >> 2) & 1) * step);
      lo = std::min(lo, v);
      hi = std::max(hi, v);
      closest = std::min(closest, std::abs(v));
    }
    return (lo <= 0 && hi >= 0) || closest < refine_margin(step) * step * h;
  };
  while (true) {
    // Keep the cells that may hold surface, then split them in two per axis.
    std::vector<Key> kept;
    for (const Key& c : cells)
      if (active(c, s)) kept.push_back(c);
    if (s == 1) {
      cells.swap(kept);
      break;
    }
    const int half = s / 2;
    std::vector<Key> keys, next;
    keys.reserve(kept.size() * 27);
    next.reserve(kept.size() * 8);
    for (const Key& c : kept) {
      for (int d = 0; d < 27; ++d) {
        const Key q{c.i + (d % 3) * half, c.j + (d / 3 % 3) * half, c.k + (d / 9) * half};
        if (q.i <= n && q.j <= n && q.k <= n) keys.push_back(q);
      }
      for (int d = 0; d < 8; ++d) {
        const Key q{c.i + (d & 1) * half, c.j + ((d >> 1) & 1) * half, c.k + ((d >> 2) & 1) * half};
        if (q.i < n && q.j < n && q.k < n) next.push_back(q);
      }
    }
    evaluate(keys);
    cells.swap(next);
    s = half;
  }

  // The narrow band: the corners of the finest active cells, clamped to the
  // background so that signedFloodFill can give the rest its sign.
  auto out = grid->getAccessor();
  for (const Key& c : cells)
    for (int d = 0; d < 8; ++d) {
      const openvdb::Coord q(c.i + (d & 1), c.j + ((d >> 1) & 1), c.k + ((d >> 2) & 1));
      const float v = std::clamp(corner(q.x(), q.y(), q.z()), float(-background), float(background));
      out.setValueOn(q, v);
    }
  openvdb::tools::signedFloodFill(grid->tree());

  // Where a crossing hid from the coarse levels (a sheet or tail squeezed
  // harder than the margins allow), the flood fill guesses signs, and a sign
  // change between two guessed voxels is skipped by volumeToMesh: a hole.
  // Trace every guessed voxel that sits on a sign change and fill again,
  // until every crossing lies between traced values: the mesh is closed.
  for (int pass = 0; pass < 64; ++pass) {
    std::vector<Key> missing;
    for (auto leaf = grid->tree().cbeginLeaf(); leaf; ++leaf)
      for (auto it = leaf->cbeginValueAll(); it; ++it) {
        const openvdb::Coord q = it.getCoord();
        const bool on = it.isValueOn(), inside = *it < 0;
        for (int axis = 0; axis < 3; ++axis) {
          openvdb::Coord nb = q;
          nb[axis] += 1;
          const bool nb_on = out.isValueOn(nb);
          if ((on && nb_on) || (out.getValue(nb) < 0) == inside) continue;
          if (!on && q.x() >= 0 && q.y() >= 0 && q.z() >= 0 && q.x() <= n && q.y() <= n && q.z() <= n)
            missing.push_back({q.x(), q.y(), q.z()});
          if (!nb_on && nb.x() <= n && nb.y() <= n && nb.z() <= n) missing.push_back({nb.x(), nb.y(), nb.z()});
        }
      }
    if (missing.empty()) break;
    evaluate(missing);
    for (const Key& q : missing)
      out.setValueOn(openvdb::Coord(q.i, q.j, q.k),
                     std::clamp(corner(q.i, q.j, q.k), float(-background), float(background)));
    openvdb::tools::signedFloodFill(grid->tree());
  }
  return grid;
}

double signed_volume(const TriMesh& m) {
  double v = 0;
  for (const Tri& t : m.triangles)
    v += dot(m.positions[t[0]], cross(m.positions[t[1]], m.positions[t[2]]));
  return v / 6.0;
}

}  // namespace

Vec3 demo_velocity(DemoCase scene, const Vec3& p, double t, double period) {
  return steady_velocity(scene, p) * std::cos(kPi * t / period);
}

Vec3 demo_flow_map(DemoCase scene, const Vec3& p, double t0, double t1, double period) {
  return flow(scene, p, pseudo_time(t1, period) - pseudo_time(t0, period));
}

TriMesh demo_frame(const DemoOptions& options, int frame) {
  if (!(options.voxel_size > 0 && options.voxel_size <= 0.1))
    throw std::invalid_argument("demo_frame: voxel_size must be in (0, 0.1] metres");
  if (!(options.fps > 0) || !(options.period > 0))
    throw std::invalid_argument("demo_frame: fps and period must be positive");
  static std::once_flag vdb_init;
  std::call_once(vdb_init, [] { openvdb::initialize(); });

  const double t = (frame - 1) / options.fps;
  const double tau = pseudo_time(t, options.period);
  auto grid = build_level_set(options.scene, tau, options.voxel_size);

  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> tris;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(*grid, points, tris, quads, 0.0, 0.0);

  TriMesh m;
  m.positions.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) m.positions[i] = {points[i].x(), points[i].y(), points[i].z()};
  m.triangles.reserve(tris.size() + 2 * quads.size());
  for (const auto& q : tris) m.triangles.push_back({int32_t(q[0]), int32_t(q[1]), int32_t(q[2])});
  for (const auto& q : quads) {
    // Split along the shorter diagonal: better-shaped triangles.
    const Vec3 &a = m.positions[q[0]], &b = m.positions[q[1]], &c = m.positions[q[2]], &d = m.positions[q[3]];
    if (norm2(a - c) <= norm2(b - d)) {
      m.triangles.push_back({int32_t(q[0]), int32_t(q[1]), int32_t(q[2])});
      m.triangles.push_back({int32_t(q[0]), int32_t(q[2]), int32_t(q[3])});
    } else {
      m.triangles.push_back({int32_t(q[0]), int32_t(q[1]), int32_t(q[3])});
      m.triangles.push_back({int32_t(q[1]), int32_t(q[2]), int32_t(q[3])});
    }
  }
  // lapflow wants counter-clockwise seen from outside: positive volume.
  if (signed_volume(m) < 0)
    for (Tri& tri : m.triangles) std::swap(tri[1], tri[2]);

  m.velocities.resize(m.positions.size());
  parallel_for(m.positions.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i)
      m.velocities[i] = demo_velocity(options.scene, m.positions[i], t, options.period);
  }, 1024);
  return m;
}

double demo_voxel_size_for(DemoCase scene, double triangles) {
  // Frame-1 triangles ~ density * area / h^2, the density fitted to
  // volumeToMesh at h = 1/128: 3.0 on the sphere; 2.1 on the slab, whose 4 cm
  // rim is only a few voxels high. Later frames have more area
  // (docs/demo_scene.md, "Numbers").
  const double area = scene == DemoCase::Vortex
                          ? 4 * kPi * kSphereRadius * kSphereRadius
                          : 2 * kPi * kSlabRadius * kSlabRadius + 2 * kPi * kSlabRadius * 2 * kSlabHalfThickness;
  const double density = scene == DemoCase::Vortex ? 3.0 : 2.1;
  const double h = std::sqrt(density * area / std::max(triangles, 1.0));
  return std::clamp(h, 1.0 / 2048, 0.1);
}

std::string demo_frame_path(const std::string& dir, const std::string& name, int frame) {
  return (std::filesystem::path(dir) / fmt::format("{}.{:04d}.ply", name, frame)).string();
}

DemoSequenceStats write_demo_sequence(const DemoOptions& options, const std::string& dir, const std::string& name,
                                      const std::function<void(int, const TriMesh&)>& on_frame) {
  if (options.frames < 1) throw std::invalid_argument("write_demo_sequence: frames must be at least 1");
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw OutputError(dir + ": cannot create the output folder: " + ec.message());
  DemoSequenceStats stats;
  const auto start = std::chrono::steady_clock::now();
  double total = 0;
  for (int f = 1; f <= options.frames; ++f) {
    const TriMesh m = demo_frame(options, f);
    write_ply(demo_frame_path(dir, name, f), m);
    const std::size_t n = m.triangle_count();
    stats.triangles_min = f == 1 ? n : std::min(stats.triangles_min, n);
    stats.triangles_max = std::max(stats.triangles_max, n);
    total += double(n);
    ++stats.frames;
    if (on_frame) on_frame(f, m);
  }
  stats.triangles_mean = total / stats.frames;
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

}  // namespace lapflow
