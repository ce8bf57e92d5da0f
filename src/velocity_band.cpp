// A velocity field sampled once per frame on a narrow band of voxels around
// the surface, then read trilinearly. Advection samples velocities tens of
// millions of times per frame; each exact per-vertex sample is an Embree
// closest-point query (about a microsecond), a voxel lookup is a few dozen
// nanoseconds. The band is built from the exact field, so it converges to it
// as the voxel shrinks; points outside the band fall back to the exact field.
#include <openvdb/openvdb.h>
#include <openvdb/tools/Morphology.h>

#include <cmath>
#include <memory>
#include <mutex>
#include <vector>

#include "lapflow/parallel.hpp"
#include "lapflow/velocity.hpp"

namespace lapflow {
namespace {

struct Band {
  openvdb::Vec3SGrid::Ptr grid;
  double inv_h = 1;
  VelocityField exact;
};

Vec3 sample_band(const Band& band, const Vec3& p) {
  const double x = p.x * band.inv_h, y = p.y * band.inv_h, z = p.z * band.inv_h;
  const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
  if (!(std::abs(fx) < 1e9 && std::abs(fy) < 1e9 && std::abs(fz) < 1e9)) return band.exact(p);
  const openvdb::Coord c0{int32_t(fx), int32_t(fy), int32_t(fz)};
  const double tx = x - fx, ty = y - fy, tz = z - fz;
  // An unregistered accessor: registering one per call (OpenVDB's default)
  // costs more than the lookup.
  openvdb::tree::ValueAccessor<const openvdb::Vec3STree, false> acc(band.grid->constTree());
  openvdb::Vec3d sum(0, 0, 0);
  for (int k = 0; k < 8; ++k) {
    const openvdb::Coord c = c0.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1);
    openvdb::Vec3s v;
    // A corner outside the band: this point is too far from the surface
    // for the band to know its velocity.
    if (!acc.probeValue(c, v)) return band.exact(p);
    const double w = ((k & 1) ? tx : 1 - tx) * (((k >> 1) & 1) ? ty : 1 - ty) * (((k >> 2) & 1) ? tz : 1 - tz);
    sum += openvdb::Vec3d(v) * w;
  }
  return {sum.x(), sum.y(), sum.z()};
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
  openvdb::tools::dilateActiveValues(mask.tree(), band_voxels, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                     openvdb::tools::IGNORE_TILES);
  mask.tree().voxelizeActiveTiles();
  std::vector<openvdb::Coord> coords;
  coords.reserve(std::size_t(mask.activeVoxelCount()));
  for (auto it = mask.cbeginValueOn(); it; ++it) coords.push_back(it.getCoord());
  std::vector<openvdb::Vec3s> values(coords.size());
  parallel_for(coords.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const Vec3 v = exact(Vec3(coords[i].x(), coords[i].y(), coords[i].z()) * voxel_size);
      values[i] = openvdb::Vec3s(float(v.x), float(v.y), float(v.z));
    }
  });
  band->grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(0, 0, 0));
  auto acc = band->grid->getAccessor();
  for (std::size_t i = 0; i < coords.size(); ++i) acc.setValueOn(coords[i], values[i]);
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
