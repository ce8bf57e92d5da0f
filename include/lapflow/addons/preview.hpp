#pragma once
/// \file preview.hpp `lapflow preview`: ray-traced pictures of baked frames
/// (Embree behind it), the first thing a user looks at. A frame's UV mesh is
/// shaded with its colour atlas, its displacement atlas as bump, a key light
/// with soft ray-traced shadows, a sky fill, a little liquid specular and a
/// ground plane; several bakes of one sequence can be put side by side. With
/// exemplar layers the colour may show each texel's layer instead (PreviewShow).
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "lapflow/bake/manifest.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/raster/raster.hpp"
#include "lapflow/core/vec.hpp"

namespace lapflow {

/// A pinhole camera.
struct PreviewCamera {
  Vec3 eye{0, -3, 1}, target{0, 0, 0};
  Vec3 up{0, 0, 1};  ///< world up; the picture's vertical follows it
  double fov = 30;   ///< vertical field of view, degrees
};

/// How a picture is lit and shaded. Colours are linear RGB.
///
/// A surface point with albedo a (the colour atlas), shading normal n (the
/// interpolated vertex normal bent by the bump), view direction v (towards the
/// eye) and light direction l gets, with F = 0.02 + 0.98 (1 - n.v)^5 (Schlick,
/// water) times `reflection`, s the key light's visible fraction (shadow rays)
/// and h = normalize(l + v):
///
///   a (1 - F) [ key s max(0, n.l) + ambient lerp(ground_fill, sky_fill, (1 + n.up) / 2) ]
///   + key s specular (shininess + 8) / (8 pi) max(0, n.h)^shininess  (only where n.l > 0)
///   + F env(reflect(-v, n))
///
/// The background is sky(d) = lerp(horizon, zenith, sqrt(max(0, d.up))) for a
/// ray direction d, or the ground plane (grey, lit the same way, shadowed,
/// fading into the horizon colour far away). env(d) is sky(d) above the
/// horizon and fades to the ground's unshadowed colour below it.
struct PreviewLook {
  Vec3 up{0, 0, 1};       ///< world up: sky, ambient and the ground plane's normal
  Vec3 light_dir{0, 0, 0};  ///< towards the key light; zero = from the camera's upper left (follows the camera)
  Vec3 key{1.75, 1.66, 1.52};  ///< key light irradiance on a surface facing it
  double light_angle = 2.5;     ///< angular radius of the key light, degrees (soft shadows); 0 = hard
  Vec3 sky_fill{0.36, 0.40, 0.48}, ground_fill{0.13, 0.12, 0.11};
  double ambient = 1.0;
  double specular = 0.25, shininess = 80;
  double reflection = 0.6;  ///< weight of the Fresnel sky reflection (0 = off)
  Vec3 zenith{0.16, 0.22, 0.33}, horizon{0.55, 0.58, 0.63};
  bool ground = true;       ///< a ground plane under the sequence's bounding box
  Vec3 ground_albedo{0.30, 0.30, 0.30};
  double bump = 0.05;       ///< bump height: displacement 1 = bump * radius (metres); 0 = no bump
};

struct PreviewOptions {
  int width = 1280, height = 720;
  int samples = 4;  ///< jittered samples per pixel (deterministic); a square number is stratified
  PreviewLook look;
};

/// One baked frame in memory, ready to render.
struct PreviewFrame {
  UvMesh mesh;
  std::vector<Vec3> normals;  ///< per vertex (smooth shading)
  ExemplarMips texture;       ///< mip pyramid of the atlas: R, G, B (linear) and displacement H
  bool bump = false;          ///< false when the bake had no displacement atlas
  double radius = 0;          ///< patch radius of the bake (metres), the bump's unit
};

/// What the pictures show on the liquid (`lapflow preview --show`).
enum class PreviewShow {
  Color,   ///< the colour atlas
  /// The colour atlas's luminance tinted by each texel's exemplar layer (the
  /// AOV's `layer` channel of a bake with exemplar layers, docs/layers.md).
  Layers,
};

/// "color" or "layers"; nullopt for any other text.
std::optional<PreviewShow> parse_preview_show(const std::string& text);

/// The tint of exemplar layer `layer` (its index, as the AOV holds it) in
/// PreviewShow::Layers pictures: linear RGB from a fixed palette of 8
/// distinct colours (orange, blue, green, yellow, magenta, cyan, pink,
/// brown), repeating; a neutral grey for -1 (no layer).
Vec3 preview_layer_color(int layer);

/// The colour atlas `color` (linear RGB(A)) tinted by `layers` (one channel,
/// the same size: each texel's layer, -1 where none): RGB = tint * (0.3 +
/// 0.7 min(1, sqrt(luminance))), so that the texture stays visible in every
/// layer's colour; alpha is kept. Throws std::invalid_argument when the
/// sizes differ.
Image tint_by_layer(const Image& color, const Image& layers);

/// A frame from its parts: `color` is the RGB(A) linear atlas, `displacement`
/// one channel in exemplar units (empty: no bump; resampled to the colour
/// atlas' size when it differs).
PreviewFrame make_preview_frame(UvMesh mesh, Image color, Image displacement, double radius);

/// Reads frame `frame` of a bake: NAME.N.obj, NAME.color.N.exr and
/// NAME.disp.N.exr (the latter optional: no bump when it is missing); with
/// PreviewShow::Layers also NAME.aov.N.exr, whose `layer` channel tints the
/// colour (tint_by_layer). Throws InputError naming the missing or malformed
/// file: with PreviewShow::Layers, an AOV that is missing (a bake without
/// --aov) or has no `layer` channel (a bake of one exemplar).
PreviewFrame load_preview_frame(const BakeManifest& bake, int frame, PreviewShow show = PreviewShow::Color);

/// Where a sequence's liquid goes: the bounding box of every frame and up to
/// `max_points` of its vertices (evenly strided per frame) for framing.
struct PreviewExtent {
  Box3 box;
  std::vector<Vec3> points;
};

/// The extent of the frames' meshes (reads the OBJs, in parallel). Throws
/// InputError naming a missing or malformed file.
PreviewExtent preview_extent(const BakeManifest& bake, const std::vector<int>& frames,
                             std::size_t max_points = 200000);
/// The extent of several bakes of the same frames, together (`lapflow
/// preview --compare`): their boxes joined, `max_points` shared among them.
PreviewExtent preview_extent(const std::vector<BakeManifest>& bakes, const std::vector<int>& frames,
                             std::size_t max_points = 200000);

/// A 3/4 elevated view of `points`: looking from `azimuth` degrees about `up`
/// (0 = from the -Y side for a Z-up world, from +Z for Y-up) and `elevation`
/// degrees above the horizon, at the distance and centre where every point
/// fits the picture (aspect = width / height) with a 10% margin, the tightest
/// side touching it. `min_distance` forces the camera at least that far (a
/// turntable keeps one distance for every view).
PreviewCamera frame_camera(const std::vector<Vec3>& points, const Vec3& up, double aspect, double azimuth = -35,
                           double elevation = 28, double fov = 30, double min_distance = 0);
/// The same for the 8 corners of a box.
PreviewCamera frame_camera(const Box3& box, const Vec3& up, double aspect, double azimuth = -35,
                           double elevation = 28, double fov = 30);

/// How the pictures of a preview are framed (`lapflow preview`).
struct PreviewFraming {
  /// --camera: every picture from this eye and target; a turntable orbits
  /// the eye about the target, around `up`.
  std::optional<PreviewCamera> fixed;
  bool turntable = false;  ///< `pictures` views around the liquid (azimuth + 360 i / pictures)
  double azimuth = -35, elevation = 28, fov = 30;  ///< degrees, without `fixed`
  Vec3 up{0, 0, 1};
  double aspect = 16.0 / 9;  ///< width / height
};
/// The camera of each of `pictures` pictures, framed from `points` (every
/// vertex of the sequence, PreviewExtent::points) unless fixed: one camera
/// for a sequence, and for a turntable the largest distance of its views,
/// so that the liquid does not breathe.
std::vector<PreviewCamera> preview_cameras(const std::vector<Vec3>& points, const PreviewFraming& framing,
                                           int pictures);

/// Renders one frame. `bounds` is the bounding box of the whole sequence: it
/// places the ground plane and sizes the shadow and fade distances, so that
/// they do not change from frame to frame. The result is linear RGB.
/// Deterministic: the same bytes at any thread count.
Image render_preview(const PreviewFrame& frame, const PreviewCamera& camera, const Box3& bounds,
                     const PreviewOptions& options);

/// Draws `text` (white on a translucent dark box) `size` pixels high with the
/// TrueType font `font_path` into a linear RGB image: the box's top-left
/// corner at pixel (x, y), or its top-right corner when `align_right`.
/// Returns false (and draws nothing) when the font cannot be loaded.
bool draw_label(Image& img, int x, int y, const std::string& text, int size, const std::string& font_path,
                bool align_right = false);

/// The legend of a PreviewShow::Layers picture at its bottom-left corner:
/// one line per layer, bottom line last, each a square swatch of
/// preview_layer_color(index) and the layer's name as draw_label draws it
/// `size` pixels high. Returns false (and draws nothing) when the font
/// cannot be loaded.
bool draw_layer_legend(Image& img, const std::vector<std::string>& names, int size, const std::string& font_path);

/// The font labels are drawn with: $LAPFLOW_FONT when set, else DejaVu Sans
/// (Debian's fonts-dejavu-core).
std::string default_label_font();

/// Puts equally sized panels side by side (left to right), each `gap` pixels
/// apart (filled with `gap_color`, linear).
Image side_by_side(const std::vector<Image>& panels, int gap = 0, const Vec3& gap_color = {0.05, 0.05, 0.05});

/// The frames of a bake to preview: all of `range` (each must be one of the
/// bake's frames and its OBJ must exist, else InputError naming the file), or
/// else every frame of the manifest whose OBJ is on disk (InputError when none).
/// `missing` receives the manifest's frames skipped for lack of files.
std::vector<int> preview_frames(const BakeManifest& bake, const std::optional<FrameRange>& range,
                                std::vector<int>* missing = nullptr);

/// Checks that every bake compared with `bakes.front()` has the mesh of each
/// of `frames`; throws InputError naming the first missing file.
void require_compared_frames(const std::vector<BakeManifest>& bakes, const std::vector<int>& frames);

/// The label of each bake's panel: the raster modes when they tell the bakes
/// apart, else the folder names.
std::vector<std::string> panel_labels(const std::vector<BakeManifest>& bakes);

/// A world up axis from its name (z, +z, y, -y, x, ...) or a vector `X,Y,Z`,
/// normalized; nullopt when the text is neither (or the vector is zero).
std::optional<Vec3> parse_up_axis(const std::string& text);

/// Encodes PNG pictures (in order, same size) into an H.264 MP4 (yuv420p,
/// dimensions padded to even) with the `ffmpeg` program, written atomically.
/// Throws OutputError when ffmpeg fails.
void encode_video(const std::vector<std::string>& pngs, const std::string& mp4_path, double fps);

/// True when an `ffmpeg` program is on PATH.
bool ffmpeg_available();

}  // namespace lapflow
