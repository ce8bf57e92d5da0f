#pragma once
/// \file raster.hpp Lapped rasterization of the patches into the surface atlas
/// (ALGORITHM.md steps 7-9), one function per step: draw with feature-map
/// erosion, fill holes, resolve the atlas images (colour, displacement, AOV),
/// retire, dilate the gutter.
///
/// Design (speed is the point): no per-texel patch search. Every patch
/// triangle is rasterized in atlas space (its vertices' fluid triangles give
/// their atlas positions); the erosion test is the discard and age is the
/// depth: each chart texel keeps the smallest 64-bit key
/// `patch index << 32 | patch triangle index` through an atomic min, so the
/// result does not depend on the order or the thread count. A resolve pass
/// then samples the exemplar for each texel's winner.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/patches/patches.hpp"

namespace lapflow {

/// How an animated exemplar plays past its last frame (docs/layers.md).
enum class ExemplarLoop : uint8_t {
  Loop,      ///< back to the first frame
  PingPong,  ///< backwards to the first, then forwards again
  Hold,      ///< stays on the last frame
};

/// Which frame of an animated exemplar a patch shows (docs/layers.md,
/// "Animated exemplars"): a patch plays the sequence from its birth, at
/// `rate` exemplar frames a bake frame, from a phase of its own (a hash of
/// the seed and its id) so that neighbours do not pulse in step. In Hold
/// mode there is no phase: the frame is the patch's age, so every patch
/// starts at the first frame and stays on the last.
struct ExemplarClock {
  int frame = 0;     ///< the bake frame drawn
  double rate = 1;   ///< exemplar frames per bake frame (--exemplar-fps / --fps)
  ExemplarLoop loop = ExemplarLoop::Loop;
  uint64_t seed = 1; ///< the bake's seed
  /// The frame in [0, count) `patch` shows at `frame`; 0 when count <= 1.
  int frame_of(const Patch& patch, int count) const;
};

/// How patches compose into a texel.
enum class RasterMode {
  Erosion,  ///< the paper (2021): oldest non-eroded patch wins, no blending
  Blend,    ///< 2019 baseline: every covering patch with w > 0 contributes, colour = sum w c / sum w (ghosts)
  NoErosion,  ///< `--mode advect`: patches are only advected, no erosion, no retirement (oldest covering
              ///< patch wins); holes still filled
};

struct RasterOptions {
  double radius = 0.1;   ///< r in metres: the exemplar spans 2r on the surface
  double epsilon = 0.1;  ///< erosion bias of the paper (eq. 2)
  RasterMode mode = RasterMode::Erosion;
  bool fill_holes = true;     ///< step 8
  bool retire = true;         ///< step 9 (Erosion and Blend only; never in Advect mode)
  bool mipmap = true;         ///< exemplar lookups at the mip level of the atlas texel footprint (antialiasing)
  bool trilinear = true;      ///< blend the two nearest mip levels (false: nearest level, ~half the lookup cost)
  bool aov = true;            ///< fill FrameTextures::aov
  /// Fill FrameTextures::color and displacement (false: resolve_texels only
  /// counts the texels each patch won and marks Patch::held, as the
  /// tracking raster needs; the images stay empty).
  bool images = true;
  /// With `images`: fill FrameTextures::color_half and displacement_half
  /// (EXR half bits, what a bake writes) instead of color and displacement,
  /// so the floats are never made (docs/performance.md, "EXR writing and
  /// compression").
  bool half_images = false;
  /// Mark the cells each patch won for Patch::held (read by retire_patches).
  /// false: an output drawn from a tracked state, which retires nothing
  /// (render_frame); the hold's test still reads the cells the tracking
  /// marked.
  bool mark_held = true;
  bool dilate = true;         ///< fill texels outside charts from the nearest chart texel
  int gutter = 4;             ///< texels dilated by 8-neighbour passes; farther texels take a row/column nearest fill
  std::size_t max_hole_patches = 200000;  ///< guard on patches born per frame
  /// Holes no wider than this times r are closed by the patches around them
  /// instead of a new patch (0 = every hole gets a patch, as in the paper).
  /// docs/temporal.md says why, and why 0.25 is the default.
  double small_hole = 0.25;
  /// The same for a hole whose rim is held only by patches at rest, up to
  /// this times r (0 = small_hole there too): where a still liquid spreads
  /// slowly (below --min-speed), the strip it uncovers at its rim is
  /// continued by the patches that held the rim instead of a new patch
  /// popping in once the strip has outgrown small_hole. docs/temporal.md.
  double rest_hole = 2.0;
  /// Hysteresis of the erosion test in patch space (docs/temporal.md): where
  /// a patch has won texels (Patch::held), the test reads the feature map's
  /// maximum and w's within one atlas texel and lowers the bar by
  /// hold_margin (in the units of w), so a texel does not change hands when
  /// only the atlas's sampling of the surface moved. An unchanged mesh still
  /// gives bit-identical frames. false = the paper's memoryless test.
  bool hold = true;
  double hold_margin = 0.05;
  /// The hold's other half: a patch at rest (Patch::at_rest), and in a
  /// render (mark_held false) every patch, wins no texel farther than
  /// rest_reach_cells(held_texel) from the cells it held (Patch::held), but
  /// next to a chart's border; such texels go to other patches or are
  /// closed by the ones around them. Where a still liquid's rim spreads, the
  /// new strip then continues the patch beside it rather than whichever
  /// patch's far edge happens to reach over the rim (a hand-over between
  /// resting patches, seen as popping), and a render shows a patch only
  /// where the tracking did, so a still liquid stays still from its first
  /// frame. Needs `hold`. false = a patch wins wherever its erosion test
  /// passes. docs/temporal.md.
  bool rest_bound = true;
  /// Size in r of the texels that marked Patch::held (the tracking atlas's,
  /// BakeOptions::track_texel); 0 = this atlas's own texels.
  double held_texel = 0;
  /// Retire ("merge") a patch that won fewer texels than this fraction of
  /// pi r^2 (in texels) when other patches pass the erosion test on every one
  /// of them, so they take them over on the next frame. 0 = off (the paper
  /// retires only patches that won nothing). docs/temporal.md.
  double merge = 0.1;
  /// The bake frame, for animated exemplars (unused with still ones).
  ExemplarClock clock;
  /// The paper's erosion, hole filling and retirement (2021) as published:
  /// every hole gets a new patch, no hysteresis, only patches that won
  /// nothing retire. For comparisons (`--paper`); the defaults above bound
  /// the population and hold a still liquid still (docs/temporal.md).
  void use_paper_hole_filling() {
    small_hole = 0.0;
    rest_hole = 0.0;
    hold = false;
    rest_bound = false;
    merge = 0.0;
  }
};

/// Box-filtered mip pyramid of the exemplar's colour and displacement,
/// interleaved as 4 channels (R, G, B, H). Level 0 is the exemplar itself.
struct ExemplarMips {
  std::vector<Image> levels;
};

/// The erosion test of ALGORITHM.md step 7, precomputed per bake.
/// A patch keeps a texel with patch coordinates (u, v) and weight w iff
/// (u, v) is in [0,1]^2 and `sqrt(F(u,v) + D(u,v)) * inv_max - epsilon >= 1 - w`,
/// i.e. `w >= T(u,v) = 1 + epsilon - sqrt(F + D) / M`. F is the feature map
/// sampled bilinearly (sample_bilinear's convention, v = 0 at the bottom row),
/// D(u,v) = max(0, 1 - |(u,v) - (0.5,0.5)| / 0.5) is evaluated exactly, M is
/// the maximum of sqrt(F + D) over the exemplar's pixel centres, and w is the
/// patch triangle's vertex weights w_V interpolated linearly (barycentric).
struct ErosionMap {
  Image feature;          ///< F_m, 1 channel in [0,1]
  double inv_max = 1.0;   ///< 1 / M
  double epsilon = 0.1;
};

/// Tables the raster derives from one exemplar frame's feature map (its
/// minima, and the held test's maxima per window; raster/internal.hpp),
/// built on first use and kept across the bake's frames.
struct ExemplarTables;

/// What the rasterizer needs from the exemplar, built once per bake.
struct RasterExemplar {
  ExemplarMips mips;
  ErosionMap erosion;
  /// An animated exemplar's frames after this, the first (docs/layers.md),
  /// each prepared once; empty for a still exemplar.
  std::vector<RasterExemplar> later;
  /// Shared by copies; set by prepare_raster_exemplar (a frame without
  /// one gets tables of its own for each raster pass).
  std::shared_ptr<ExemplarTables> tables;

  std::size_t frame_count() const { return 1 + later.size(); }
  const RasterExemplar& frame(std::size_t k) const { return k == 0 ? *this : later[k - 1]; }
};

/// The exemplars of a bake's layers, indexed by Patch::layer: one in a bake
/// of one exemplar.
using ExemplarLayers = std::span<const RasterExemplar>;
/// The most exemplar layers a bake may have (Patch::layer's range).
inline constexpr std::size_t kMaxLayers = 16;

/// Builds the mip pyramid and the erosion map. `epsilon` is RasterOptions::epsilon.
RasterExemplar prepare_raster_exemplar(const Exemplar& exemplar, double epsilon);
/// The same for an animated exemplar's frames (at least one), all of one size.
RasterExemplar prepare_raster_exemplar(std::span<const Exemplar> frames, double epsilon);
ExemplarMips build_exemplar_mips(const Exemplar& exemplar);
ErosionMap build_erosion_map(const Image& feature, double epsilon);

/// True when the patch keeps the texel (ALGORITHM.md step 7; see ErosionMap).
/// In Advect mode only the [0,1]^2 test applies; in Blend mode, [0,1]^2 and w > 0.
bool erosion_keeps(const ErosionMap& map, double u, double v, double w, RasterMode mode = RasterMode::Erosion);

/// Colour and displacement (R, G, B, H) at patch coordinates (u, v), clamped
/// at the borders, trilinear at level of detail `lod` (log2 of the footprint
/// in level-0 pixels; <= 0 is plain bilinear on level 0).
void sample_exemplar(const ExemplarMips& mips, double u, double v, double lod, float out[4], bool trilinear = true);

struct RasterStats {
  std::size_t chart_texels = 0;
  std::size_t covered_texels = 0;  ///< chart texels with a patch (kept, or forced); Blend: summed w above 1e-3, or forced
  std::size_t forced_texels = 0;   ///< chart texels given the patch of a neighbour because hole filling could not cover them
  std::size_t held_texels = 0;     ///< hole texels given back to the patch that held the point (RasterOptions::hold)
  std::size_t closed_texels = 0;   ///< chart texels of small holes closed by their neighbours (RasterOptions::small_hole)
  std::size_t patches_born = 0;    ///< by hole filling
  std::size_t patches_retired = 0;
  std::size_t retired_eroded = 0;  ///< of those: eroded away (no vertex w reaches epsilon, or every triangle too distorted)
  std::size_t retired_hidden = 0;  ///< of those: the rest, hidden under older patches
  std::size_t retired_merged = 0;  ///< of those: small, their texels covered by others (RasterOptions::merge)
  std::size_t seam_triangles = 0;  ///< patch triangles rasterized through the seam fallback
  /// Patch triangles the draw left out, wholly under texels older patches
  /// keep (raster/tiles.hpp, OwnedTiles): they could win nothing.
  std::size_t skipped_triangles = 0;
  std::size_t distorted_triangles = 0;  ///< patch triangles skipped because delta > delta_max
  double lod = 0;                  ///< exemplar level of detail used (log2 exemplar pixels per atlas texel)
  double texel_world_size = 0;     ///< metres per atlas texel (area-weighted mean)
  /// Chart texels won by each patch, aligned with PatchSet::patches after retirement
  /// (Blend: texels where it has the largest weight, i.e. names the AOV).
  std::vector<uint64_t> texels_per_patch;
  /// Wall seconds of the steps of track_pass / output_pass (raster: the draw).
  double seconds_setup = 0, seconds_raster = 0, seconds_holes = 0, seconds_resolve = 0, seconds_retire = 0,
         seconds_dilate = 0, seconds_total = 0;
};

/// The atlas images of one frame, resolution x resolution, row 0 at the top
/// (texel (x, y) has atlas uv ((x+0.5)/N, 1-(y+0.5)/N)).
struct FrameTextures {
  Image color;         ///< RGBA linear; A = 1 on covered chart texels (coverage), 0 elsewhere (RGB dilated there)
  Image displacement;  ///< 1 channel, H of the winning patch (dilated outside charts)
  /// RasterOptions::half_images: color and displacement as half bits
  /// instead (the same values rounded as to_half_image rounds them; the
  /// float images stay empty).
  HalfImage color_half, displacement_half;
  Image aov;           ///< patch_id (stable Patch::id as float, -1 where none), u, v, w, and with more than one
                       ///< exemplar layer the layer (-1 where none); empty unless RasterOptions::aov
                       ///< (Blend: the patch of largest w at the texel, ties to the oldest)
  RasterStats stats;
};

/// Makes a hole-filling patch at a surface point with the given id (the
/// frame's create_patch in production, something analytic in tests). Called
/// concurrently from several threads: it must be thread-safe.
using PatchMaker = std::function<std::optional<Patch>(const SurfacePoint& at, uint32_t id)>;
/// Fluid triangle under a 3D point, -1 when none (for patch vertices whose
/// surface_triangle is unknown).
using TriangleLocator = std::function<int(const Vec3& p)>;

namespace detail {
struct RasterContext;
}

/// One frame's lapped rasterization in progress (ALGORITHM.md steps 7-9):
/// for every chart texel, the patch that keeps it, and what the steps have
/// counted so far. begin_raster() makes it for one mesh and atlas (both must
/// outlive it); the steps then run in this order: draw_patches, fill_holes,
/// resolve_texels, retire_patches, dilate_gutter (which spends it). Every
/// step is deterministic at any thread count.
struct RasterBuffers {
  RasterStats stats;                         ///< counts so far (timings are the caller's)
  /// Chart texels each patch gives the frame, aligned with PatchSet::patches
  /// (set by resolve_texels, then by retire_patches for the survivors).
  std::vector<uint64_t> texels_won;
  std::shared_ptr<detail::RasterContext> context;  ///< per-texel keys and tables (src/raster/internal.hpp)
};

/// Set-up: the texel index, the per-texel keys (none yet), fluid-triangle
/// tables and the exemplar's level of detail. `locate` finds the fluid
/// triangle under a patch vertex whose surface_triangle is unknown (may be
/// empty).
RasterBuffers begin_raster(const TriMesh& mesh, const SurfaceAtlas& atlas, const RasterExemplar& exemplar,
                           const RasterOptions& options, const WeightOptions& weights, TriangleLocator locate = {});
/// The same with one exemplar per layer: each patch is drawn, eroded and
/// sampled with exemplars[Patch::layer] (the layer of every patch must be
/// below exemplars.size()); the AOV then has a fifth channel, the layer.
RasterBuffers begin_raster(const TriMesh& mesh, const SurfaceAtlas& atlas, ExemplarLayers exemplars,
                           const RasterOptions& options, const WeightOptions& weights, TriangleLocator locate = {});

/// Step 7: draws every patch triangle into the atlas (its vertices' fluid
/// triangles give their atlas positions); the erosion test is the discard
/// and age the depth: each chart texel keeps the oldest patch that is not
/// eroded there. Patch triangles with triangle_delta over weights.delta_max
/// are not drawn (Erosion and Blend modes).
void draw_patches(RasterBuffers& buffers, const PatchSet& patches);

/// Step 8: new patches from `make_patch` (none when it is empty) at the
/// centres of the holes, in rounds (docs/raster.md), appended to `patches`
/// with ids from patches.next_id and birth frame `frame`; each newborn is
/// drawn into the still-open texels. Texels still open after that take a
/// neighbour's patch (forced_texels).
void fill_holes(RasterBuffers& buffers, PatchSet& patches, int frame, const PatchMaker& make_patch);

/// Step 8 of a render of a tracked state (docs/farm.md): no patch is born.
/// Held points go back to their patch, and every other open texel takes a
/// neighbour's patch within its chart (closed_texels: the small holes the
/// tracking closed, those narrower than a tracking texel, and the output's
/// own sampling of the patches' eroded edges); only texels of a chart no
/// patch reaches take the nearest patch in 3D (forced_texels).
void close_holes(RasterBuffers& buffers, const PatchSet& patches);

/// The atlas images: each chart texel's colour, displacement and AOV from
/// the patch that keeps it, at its (u, v). Counts the texels each patch won.
FrameTextures resolve_texels(RasterBuffers& buffers, const PatchSet& patches);

/// Step 9: removes the patches that gave the frame no texel (never in
/// NoErosion mode or with RasterOptions::retire off).
void retire_patches(RasterBuffers& buffers, PatchSet& patches);

/// Fills the texels outside charts from the nearest chart texel (gutter),
/// then frees the buffers' per-texel state.
void dilate_gutter(RasterBuffers& buffers, FrameTextures& textures);

/// The tracking pass of a frame (ALGORITHM.md steps 7-9), as `bake` and
/// `lapflow track` run it at the tracking resolution: draw_patches,
/// fill_holes with births from `make_patch` (empty: no birth), resolve_texels
/// (the texels each patch won and the cells it held; no image) and
/// retire_patches. `patches` leave as they carry over to the next frame.
/// Draws no image whatever `options` say. Returns the counts and each step's
/// wall seconds (seconds_raster is the draw).
RasterStats track_pass(const TriMesh& mesh, const SurfaceAtlas& atlas, ExemplarLayers exemplars,
                       const RasterOptions& options, const WeightOptions& weights, const TriangleLocator& locate,
                       int frame, const PatchMaker& make_patch, PatchSet& patches);
inline RasterStats track_pass(const TriMesh& mesh, const SurfaceAtlas& atlas, const RasterExemplar& exemplar,
                              const RasterOptions& options, const WeightOptions& weights,
                              const TriangleLocator& locate, int frame, const PatchMaker& make_patch,
                              PatchSet& patches) {
  return track_pass(mesh, atlas, ExemplarLayers{&exemplar, 1}, options, weights, locate, frame, make_patch, patches);
}

/// The output pass of a frame, as `bake` and `lapflow render` draw the
/// patches as they leave the tracking pass (docs/farm.md): draw_patches,
/// close_holes (no birth), resolve_texels and dilate_gutter. Marks no held
/// cell (RasterOptions::mark_held is off). FrameTextures::stats holds the
/// counts and each step's wall seconds.
FrameTextures output_pass(const TriMesh& mesh, const SurfaceAtlas& atlas, ExemplarLayers exemplars,
                          const RasterOptions& options, const WeightOptions& weights, const TriangleLocator& locate,
                          const PatchSet& patches);
inline FrameTextures output_pass(const TriMesh& mesh, const SurfaceAtlas& atlas, const RasterExemplar& exemplar,
                                 const RasterOptions& options, const WeightOptions& weights,
                                 const TriangleLocator& locate, const PatchSet& patches) {
  return output_pass(mesh, atlas, ExemplarLayers{&exemplar, 1}, options, weights, locate, patches);
}

/// Hole-filling patches by create_patch on `surface` (the fluid triangle's
/// normal at the texel). `adjacency` (of surface.mesh()) must outlive it.
PatchMaker surface_patch_maker(const SurfaceQuery& surface, const SurfaceAdjacency& adjacency,
                               const PatchOptions& patch_options, const WeightOptions& weights, int frame);

/// The fluid triangle under a patch vertex by closest point within r / 4
/// (the advection's projection limit): farther, it is not on this surface.
TriangleLocator surface_triangle_locator(const SurfaceQuery& surface, double radius);

}  // namespace lapflow
