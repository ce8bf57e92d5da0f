// One frame's raster passes in order (raster_frame): draw, fill holes,
// resolve, retire, dilate.
#include "lapflow/core/stopwatch.hpp"
#include "lapflow/raster/raster.hpp"

namespace lapflow {

FrameTextures raster_frame(const TriMesh& mesh, const SurfaceAtlas& atlas, const RasterExemplar& exemplar,
                           const RasterOptions& options, const WeightOptions& weights, int frame,
                           const PatchMaker& make_patch, const TriangleLocator& locate, PatchSet& patches) {
  Stopwatch clock;
  RasterBuffers r = begin_raster(mesh, atlas, exemplar, options, weights, locate);
  RasterStats& st = r.stats;
  st.seconds_setup = clock.lap();
  draw_patches(r, patches);
  st.seconds_raster = clock.lap();
  fill_holes(r, patches, frame, make_patch);
  st.seconds_holes = clock.lap();
  FrameTextures out = resolve_texels(r, patches);
  st.seconds_resolve = clock.lap();
  retire_patches(r, patches);
  dilate_gutter(r, out);
  st.seconds_dilate = clock.lap();
  st.seconds_total = clock.total();
  out.stats = std::move(r.stats);
  return out;
}

}  // namespace lapflow
