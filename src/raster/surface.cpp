// The rasterizer on a frame's surface: hole-filling patches from create_patch
// and vertex location by closest point.
// Kept apart from the rasterizer so its tests link without Embree or CGAL.
#include "lapflow/raster/raster.hpp"
#include "lapflow/surface/surface_query.hpp"

namespace lapflow {

PatchMaker surface_patch_maker(const SurfaceQuery& surface, const SurfaceAdjacency& adjacency,
                               const PatchOptions& patch_options, const WeightOptions& weights, int frame) {
  return [&surface, &adjacency, patch_options, weights, frame](const SurfacePoint& at, uint32_t id) {
    return create_patch(surface, adjacency, at, id, frame, patch_options, weights);
  };
}

TriangleLocator surface_triangle_locator(const SurfaceQuery& surface, double radius) {
  const double reach = 0.25 * radius;
  return [&surface, reach](const Vec3& p) {
    const ClosestHit hit = surface.closest(p, reach);
    return hit.found ? hit.triangle : -1;
  };
}

}  // namespace lapflow
