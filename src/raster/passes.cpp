// The two raster passes of a frame, each the one sequence of steps every
// caller runs: the tracking pass (draw, fill holes with births, count the
// texels won, retire) and the output pass (draw, close holes, resolve the
// images, dilate the gutter).
#include "lapflow/core/stopwatch.hpp"
#include "lapflow/raster/raster.hpp"

namespace lapflow {

RasterStats track_pass(const TriMesh& mesh, const SurfaceAtlas& atlas, ExemplarLayers exemplar,
                       const RasterOptions& options, const WeightOptions& weights, const TriangleLocator& locate,
                       int frame, const PatchMaker& make_patch, PatchSet& patches) {
  RasterOptions tracking = options;
  tracking.images = false;
  tracking.aov = false;
  tracking.dilate = false;
  Stopwatch clock;
  RasterBuffers r = begin_raster(mesh, atlas, exemplar, tracking, weights, locate);
  RasterStats& st = r.stats;
  st.seconds_setup = clock.lap();
  draw_patches(r, patches);
  st.seconds_raster = clock.lap();
  fill_holes(r, patches, frame, make_patch);
  st.seconds_holes = clock.lap();
  resolve_texels(r, patches);
  st.seconds_resolve = clock.lap();
  retire_patches(r, patches);
  st.seconds_retire = clock.lap();
  st.seconds_total = clock.total();
  return std::move(r.stats);
}

FrameTextures output_pass(const TriMesh& mesh, const SurfaceAtlas& atlas, ExemplarLayers exemplar,
                          const RasterOptions& options, const WeightOptions& weights, const TriangleLocator& locate,
                          const PatchSet& patches) {
  RasterOptions output = options;
  output.mark_held = false;  // nothing retires here: the tracking pass marked the cells
  Stopwatch clock;
  RasterBuffers r = begin_raster(mesh, atlas, exemplar, output, weights, locate);
  r.stats.seconds_setup = clock.lap();
  draw_patches(r, patches);
  r.stats.seconds_raster = clock.lap();
  close_holes(r, patches);
  r.stats.seconds_holes = clock.lap();
  FrameTextures out = resolve_texels(r, patches);
  r.stats.seconds_resolve = clock.lap();
  dilate_gutter(r, out);
  r.stats.seconds_dilate = clock.lap();
  r.stats.seconds_total = clock.total();
  out.stats = std::move(r.stats);
  return out;
}

}  // namespace lapflow
