// The production entry point of the rasterizer: hole-filling patches from
// create_patch and vertex location by closest point on the frame's surface.
// Kept apart from the rasterizer so its tests link without Embree or CGAL.
#include "lapflow/raster/raster.hpp"
#include "lapflow/surface/surface_query.hpp"

namespace lapflow {

FrameTextures rasterize_atlas(const SurfaceQuery& surface, const SurfaceAtlas& atlas, const RasterExemplar& exemplar,
                              const RasterOptions& options, const PatchOptions& patch_options,
                              const WeightOptions& weights, int frame, PatchSet& patches) {
  // Built once per frame: the plain create_patch overload builds it per call,
  // which made hole filling O(patches x mesh).
  const SurfaceAdjacency adjacency = build_surface_adjacency(surface.mesh());
  const PatchMaker maker = [&](const SurfacePoint& at, uint32_t id) {
    return create_patch(surface, adjacency, at, id, frame, patch_options, weights);
  };
  // A vertex whose fluid triangle is unknown is looked up within r / 4 (the
  // advection's projection limit): farther, it is not on this surface.
  const double reach = 0.25 * options.radius;
  const TriangleLocator locate = [&](const Vec3& p) {
    const ClosestHit hit = surface.closest(p, reach);
    return hit.found ? hit.triangle : -1;
  };
  return rasterize_atlas(surface.mesh(), atlas, exemplar, options, weights, frame, maker, locate, patches);
}

}  // namespace lapflow
