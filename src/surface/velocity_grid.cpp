// OpenVDB vector grids (Houdini `vel`/`v`, Mantaflow `velocity`) as velocity
// fields. OpenVDB stays in this file.
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <filesystem>
#include <mutex>

#include "lapflow/core/errors.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow {

namespace {
void init_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

template <typename GridT>
Vec3 sample_grid(const GridT& grid, const Vec3& p) {
  // A fresh accessor per call: no shared cache, so concurrent calls are safe,
  // and the 8 lookups of one trilinear sample still share its cache. The
  // unregistered kind skips a global registry lock; the grid never changes.
  const auto acc = grid.getConstUnsafeAccessor();
  typename GridT::ValueType v;
  openvdb::tools::BoxSampler::sample(acc, grid.transform().worldToIndex(openvdb::Vec3d(p.x, p.y, p.z)), v);
  return {double(v[0]), double(v[1]), double(v[2])};
}

template <typename GridT>
Box3 world_bounds(const GridT& grid) {
  Box3 b;
  const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
  if (box.empty()) return b;
  // Voxel centres sit on integer index coordinates; the voxels reach half a cell further.
  const openvdb::Vec3d lo = box.min().asVec3d() - 0.5, hi = box.max().asVec3d() + 0.5;
  for (int c = 0; c < 8; ++c) {
    const openvdb::Vec3d w =
        grid.transform().indexToWorld(openvdb::Vec3d(c & 1 ? hi.x() : lo.x(), c & 2 ? hi.y() : lo.y(), c & 4 ? hi.z() : lo.z()));
    b.extend({w.x(), w.y(), w.z()});
  }
  return b;
}
}  // namespace

struct VelocityGrid::Impl {
  std::string name;
  openvdb::Vec3SGrid::Ptr sgrid;  ///< float vectors (the usual case)
  openvdb::Vec3DGrid::Ptr dgrid;  ///< double vectors
};

VelocityGrid::VelocityGrid(const std::string& path, const std::string& grid_name) : impl_(std::make_unique<Impl>()) {
  init_openvdb();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw InputError(path, "file not found");
  try {
    openvdb::io::File file(path);
    file.open(false);  // read everything now: the file may be replaced while we run
    std::vector<std::pair<std::string, std::string>> present;  // name, value type
    const openvdb::GridPtrVecPtr meta = file.readAllGridMetadata();
    for (const auto& g : *meta) present.emplace_back(g->getName(), g->valueType());
    const std::vector<std::string> wanted =
        grid_name.empty() ? std::vector<std::string>{"vel", "v", "velocity"} : std::vector<std::string>{grid_name};
    for (const std::string& w : wanted) {
      for (const auto& [name, type] : present) {
        if (name != w || (type != "vec3s" && type != "vec3d")) continue;
        const openvdb::GridBase::Ptr base = file.readGrid(name);
        impl_->name = name;
        impl_->sgrid = openvdb::gridPtrCast<openvdb::Vec3SGrid>(base);
        if (!impl_->sgrid) impl_->dgrid = openvdb::gridPtrCast<openvdb::Vec3DGrid>(base);
        if (impl_->sgrid || impl_->dgrid) return;
      }
    }
    std::string wanted_text, present_text;
    for (const std::string& w : wanted) wanted_text += (wanted_text.empty() ? "'" : " or '") + w + "'";
    for (const auto& [name, type] : present) present_text += (present_text.empty() ? "" : ", ") + name + " (" + type + ")";
    throw InputError(path, "no vector grid named " + wanted_text + "; the file has " +
                               (present.empty() ? std::string("no grids") : present_text) +
                               " (choose one with --velocity-grid)");
  } catch (const openvdb::Exception& e) {
    throw InputError(path, std::string("cannot read OpenVDB file: ") + e.what());
  }
}

VelocityGrid::~VelocityGrid() = default;
VelocityGrid::VelocityGrid(VelocityGrid&&) noexcept = default;
VelocityGrid& VelocityGrid::operator=(VelocityGrid&&) noexcept = default;

Vec3 VelocityGrid::sample(const Vec3& p) const {
  return impl_->sgrid ? sample_grid(*impl_->sgrid, p) : sample_grid(*impl_->dgrid, p);
}

const std::string& VelocityGrid::grid_name() const { return impl_->name; }

Box3 VelocityGrid::active_bounds() const {
  return impl_->sgrid ? world_bounds(*impl_->sgrid) : world_bounds(*impl_->dgrid);
}

VelocityField grid_velocity_field(const VelocityGrid& grid) {
  return [&grid](const Vec3& p) { return grid.sample(p); };
}

}  // namespace lapflow
