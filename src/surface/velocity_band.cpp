// A velocity field sampled once per frame on a narrow band of voxels around
// the surface, then read trilinearly. Advection samples velocities tens of
// millions of times per frame; each exact per-vertex sample is an Embree
// closest-point query, a voxel lookup is orders of magnitude cheaper
// (docs/performance.md). The band is built from the exact field, so it converges to it
// as the voxel shrinks; points outside the band fall back to the exact field.
#include <openvdb/openvdb.h>
#include <openvdb/tools/Morphology.h>

#include <array>
#include <climits>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "lapflow/core/parallel.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow {
namespace {

// The band in flat arrays: bricks of 8^3 cells, each holding the 9^3 voxel
// values at its cells' corners (a one-voxel apron shared with the next
// bricks), so the 8 corners of a trilinear sample are in one brick and a
// sample costs one index computation and 8 loads. (An OpenVDB accessor walks
// its tree per corner: several times slower per sample.)
constexpr int kBrick = 8, kSide = kBrick + 1, kBrickValues = kSide * kSide * kSide;

struct Vec3s {
  float x, y, z;
};
using BrickKey = std::array<int64_t, 3>;
struct BrickKeyHash {
  std::size_t operator()(const BrickKey& k) const { return std::size_t(hash64(uint64_t(k[0]), uint64_t(k[1]), uint64_t(k[2]))); }
};

struct Band {
  double inv_h = 1;
  VelocityField exact;
  int64_t lo[3] = {0, 0, 0};              ///< first brick coordinate
  int64_t dims[3] = {0, 0, 0};            ///< bricks along each axis
  std::vector<int32_t> brick_of;          ///< dense brick index (-1: no brick), x fastest
  std::unordered_map<BrickKey, int32_t, BrickKeyHash> sparse;  ///< instead when a dense table would be huge
  std::vector<float> values;              ///< xyz per voxel; NaN outside the band

  int32_t brick(int64_t bx, int64_t by, int64_t bz) const {
    const int64_t x = bx - lo[0], y = by - lo[1], z = bz - lo[2];
    if (x < 0 || y < 0 || z < 0 || x >= dims[0] || y >= dims[1] || z >= dims[2]) return -1;
    if (!brick_of.empty()) return brick_of[std::size_t(x + dims[0] * (y + dims[1] * z))];
    const auto it = sparse.find(BrickKey{x, y, z});
    return it == sparse.end() ? -1 : it->second;
  }
};

Vec3 sample_band(const Band& band, const Vec3& p) {
  const double x = p.x * band.inv_h, y = p.y * band.inv_h, z = p.z * band.inv_h;
  if (!(std::abs(x) < 1e9 && std::abs(y) < 1e9 && std::abs(z) < 1e9)) return band.exact(p);
  // floor() without a libm call (the baseline x86-64 build has no SSE4.1 round).
  auto floor_int = [](double t) {
    const int32_t i = int32_t(t);  // truncates toward zero
    return t < double(i) ? i - 1 : i;
  };
  const int32_t cx = floor_int(x), cy = floor_int(y), cz = floor_int(z);
  const double fx = cx, fy = cy, fz = cz;
  // Floor division by the brick size (arithmetic shift) and the remainder.
  const int32_t b = band.brick(cx >> 3, cy >> 3, cz >> 3);
  if (b < 0) return band.exact(p);
  const float* v0 = band.values.data() + 3 * (std::size_t(b) * kBrickValues +
                                              std::size_t((cx & 7) + kSide * ((cy & 7) + kSide * (cz & 7))));
  const double tx = x - fx, ty = y - fy, tz = z - fz;
  double sx = 0, sy = 0, sz = 0;
  for (int k = 0; k < 8; ++k) {
    const float* v = v0 + 3 * ((k & 1) + kSide * ((k >> 1) & 1) + kSide * kSide * ((k >> 2) & 1));
    // A corner outside the band: this point is too far from the surface
    // for the band to know its velocity.
    if (std::isnan(v[0])) return band.exact(p);
    const double w = ((k & 1) ? tx : 1 - tx) * (((k >> 1) & 1) ? ty : 1 - ty) * (((k >> 2) & 1) ? tz : 1 - tz);
    sx += double(v[0]) * w;
    sy += double(v[1]) * w;
    sz += double(v[2]) * w;
  }
  return {sx, sy, sz};
}

// The band of per-vertex velocities, ring by ring: ring 0 is the voxels
// holding a vertex, ring k the voxels the k-th one-voxel dilation adds (the
// same voxels as one dilation by the band width). Each voxel's closest point
// is searched within a radius known to hold it: half a voxel diagonal in
// ring 0 (a vertex is that close), else the distance of a neighbour in an
// earlier ring plus the distance to it (triangle inequality). The closest
// point within any radius that holds one is the closest point (ties go to the
// lowest triangle), so the values are those of `vertex(p)` bit for bit; the
// plain search tries radii from an eighth of an edge to 16 edges first,
// which wastes queries on voxels several edges off the surface.
void sample_vertex_velocity_by_rings(const VertexVelocity& vertex, const openvdb::MaskGrid& seeds, int band_voxels,
                                     double h, std::vector<openvdb::Coord>& coords, std::vector<Vec3s>& values) {
  openvdb::FloatGrid distance(std::numeric_limits<float>::infinity());
  openvdb::MaskGrid::Ptr reached = seeds.deepCopy();
  std::vector<openvdb::Coord> ring;
  for (auto it = reached->cbeginValueOn(); it; ++it) ring.push_back(it.getCoord());
  const double slack = 1 + 1e-6;
  for (int k = 0; !ring.empty(); ++k) {
    std::vector<Vec3s> v(ring.size());
    std::vector<float> d(ring.size());
    parallel_for(ring.size(), [&](std::size_t b, std::size_t e) {
      auto known = distance.getConstAccessor();
      for (std::size_t i = b; i < e; ++i) {
        const openvdb::Coord& c = ring[i];
        const Vec3 p = Vec3(c.x(), c.y(), c.z()) * h;
        double bound = 0.5 * std::sqrt(3.0) * h;
        if (k > 0) {
          bound = INFINITY;
          for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) {
                const float dq = known.getValue(c.offsetBy(dx, dy, dz));
                if (std::isfinite(dq)) bound = std::min(bound, double(dq) + h * std::sqrt(double(dx * dx + dy * dy + dz * dz)));
              }
        }
        Vec3 vel;
        double dist = bound;
        if (!vertex.within(p, bound * slack + 1e-12, vel, dist))
          vel = vertex(p);  // not expected: the bound holds a surface point
        v[i] = Vec3s{float(vel.x), float(vel.y), float(vel.z)};
        d[i] = float(dist * slack);  // rounded up: stays an upper bound
      }
    });
    {
      auto acc = distance.getAccessor();
      for (std::size_t i = 0; i < ring.size(); ++i) acc.setValue(ring[i], d[i]);
    }
    coords.insert(coords.end(), ring.begin(), ring.end());
    values.insert(values.end(), v.begin(), v.end());
    if (k == band_voxels) break;
    openvdb::MaskGrid::Ptr next = reached->deepCopy();
    openvdb::tools::dilateActiveValues(next->tree(), 1, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::IGNORE_TILES);
    next->tree().voxelizeActiveTiles();
    ring.clear();
    auto was = reached->getConstAccessor();
    for (auto it = next->cbeginValueOn(); it; ++it)
      if (!was.isValueOn(it.getCoord())) ring.push_back(it.getCoord());
    reached = next;
  }
}

}  // namespace

VelocityField banded_velocity_field(VelocityField exact, const TriMesh& mesh, double voxel_size, int band_voxels) {
  if (mesh.empty() || !(voxel_size > 0) || band_voxels < 1) return exact;
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
  auto band = std::make_shared<Band>();
  band->inv_h = 1.0 / voxel_size;
  band->exact = exact;
  // Voxel (i,j,k) holds the velocity at (i,j,k) * h: every voxel near a
  // vertex, dilated by the band width.
  openvdb::MaskGrid mask;
  {
    auto acc = mask.getAccessor();
    for (const Vec3& p : mesh.positions) {
      const openvdb::Coord c(int(std::lround(p.x * band->inv_h)), int(std::lround(p.y * band->inv_h)),
                             int(std::lround(p.z * band->inv_h)));
      acc.setValueOn(c);
    }
  }
  std::vector<openvdb::Coord> coords;
  std::vector<Vec3s> values;
  if (const VertexVelocity* vertex = exact.target<VertexVelocity>()) {
    sample_vertex_velocity_by_rings(*vertex, mask, band_voxels, voxel_size, coords, values);
  } else {
    openvdb::tools::dilateActiveValues(mask.tree(), band_voxels, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::IGNORE_TILES);
    mask.tree().voxelizeActiveTiles();
    coords.reserve(std::size_t(mask.activeVoxelCount()));
    for (auto it = mask.cbeginValueOn(); it; ++it) coords.push_back(it.getCoord());
    values.resize(coords.size());
    parallel_for(coords.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        const Vec3 v = exact(Vec3(coords[i].x(), coords[i].y(), coords[i].z()) * voxel_size);
        values[i] = Vec3s{float(v.x), float(v.y), float(v.z)};
      }
    });
  }
  if (coords.empty()) return exact;

  // Bricks: one per brick holding a band voxel (a cell whose corner voxel
  // is outside the band falls back to `exact` anyway).
  int64_t hi[3] = {INT64_MIN, INT64_MIN, INT64_MIN};
  for (int a = 0; a < 3; ++a) band->lo[a] = INT64_MAX;
  for (const openvdb::Coord& c : coords)
    for (int a = 0; a < 3; ++a) {
      band->lo[a] = std::min<int64_t>(band->lo[a], c[a] >> 3);
      hi[a] = std::max<int64_t>(hi[a], c[a] >> 3);
    }
  for (int a = 0; a < 3; ++a) band->dims[a] = hi[a] - band->lo[a] + 1;
  const double cells = double(band->dims[0]) * double(band->dims[1]) * double(band->dims[2]);
  const bool dense = cells <= double(1 << 24);  // 64 MB of indices at most
  if (dense) band->brick_of.assign(std::size_t(cells), -1);
  int32_t bricks = 0;
  auto brick_slot = [&](int64_t bx, int64_t by, int64_t bz) -> int32_t* {
    const int64_t x = bx - band->lo[0], y = by - band->lo[1], z = bz - band->lo[2];
    if (x < 0 || y < 0 || z < 0 || x >= band->dims[0] || y >= band->dims[1] || z >= band->dims[2]) return nullptr;
    if (dense) return &band->brick_of[std::size_t(x + band->dims[0] * (y + band->dims[1] * z))];
    return &band->sparse.try_emplace(BrickKey{x, y, z}, -1).first->second;
  };
  for (const openvdb::Coord& c : coords) {
    int32_t* slot = brick_slot(c.x() >> 3, c.y() >> 3, c.z() >> 3);
    if (*slot < 0) *slot = bricks++;
  }
  band->values.assign(std::size_t(bricks) * kBrickValues * 3, std::numeric_limits<float>::quiet_NaN());
  for (std::size_t i = 0; i < coords.size(); ++i) {
    const openvdb::Coord& c = coords[i];
    // The voxel's own brick, and along each axis where it is the first of
    // its brick, the previous brick's apron.
    for (int k = 0; k < 8; ++k) {
      int64_t bc[3];
      int local[3];
      bool skip = false;
      for (int a = 0; a < 3; ++a) {
        const bool apron = (k >> a) & 1;
        if (apron && (c[a] & 7) != 0) skip = true;
        bc[a] = (c[a] >> 3) - (apron ? 1 : 0);
        local[a] = apron ? kBrick : (c[a] & 7);
      }
      if (skip) continue;
      const int32_t b = band->brick(bc[0], bc[1], bc[2]);
      if (b < 0) continue;
      float* v = band->values.data() +
                 3 * (std::size_t(b) * kBrickValues + std::size_t(local[0] + kSide * (local[1] + kSide * local[2])));
      v[0] = values[i].x, v[1] = values[i].y, v[2] = values[i].z;
    }
  }
  return [band](const Vec3& p) { return sample_band(*band, p); };
}

double mean_edge_length(const TriMesh& mesh) {
  if (mesh.empty()) return 0;
  double sum = 0;
  for (const Tri& f : mesh.triangles)
    for (int k = 0; k < 3; ++k) sum += norm(mesh.positions[f[(k + 1) % 3]] - mesh.positions[f[k]]);
  return sum / (3.0 * double(mesh.triangles.size()));
}

}  // namespace lapflow
