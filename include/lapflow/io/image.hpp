#pragma once
/// \file image.hpp Float images, exemplars and EXR/PNG writing (OIIO behind it).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace lapflow {

class StagedFiles;  // lapflow/io/atomic_file.hpp

/// Interleaved float image, row 0 at the top, linear values.
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;  ///< width*height*channels

  Image() = default;
  Image(int w, int h, int c, float fill = 0.f)
      : width(w), height(h), channels(c), pixels(std::size_t(w) * h * c, fill) {}
  float& at(int x, int y, int c) { return pixels[(std::size_t(y) * width + x) * channels + c]; }
  float at(int x, int y, int c) const { return pixels[(std::size_t(y) * width + x) * channels + c]; }
  bool empty() const { return pixels.empty(); }
};

enum class ColorSpace { Auto, sRGB, Linear };

/// What an image file's header says, read without decoding any pixel.
struct ImageHeader {
  int width = 0, height = 0, channels = 0;
  /// Tile size of a tiled file; 0 for a scanline file.
  int tile_width = 0, tile_height = 0;
  /// Resolution levels: 1, or a MIP-mapped texture's levels (level 0 is
  /// width x height; read_image reads level 0).
  int mip_levels = 1;
  /// Bytes of the decoded image (float per channel), what read_image allocates.
  double decoded_bytes() const { return double(width) * double(height) * double(channels) * 4.0; }
};
/// Reads the header only (OIIO opens the file without reading its pixels).
/// Throws InputError for an unreadable file or an image with no pixels.
ImageHeader read_image_header(const std::string& path);

/// Reads any image OIIO can (PNG, JPEG, TIFF, EXR; 8/16/32 bit) into linear
/// float. With Auto, 8/16-bit integer files (unless tagged linear, as
/// write_png(to_srgb = false) tags them) and files tagged sRGB are decoded
/// from sRGB; float files are taken as linear; alpha is never decoded. Data maps (feature, height)
/// should be read with ColorSpace::Linear. The header is checked before any
/// pixel is decoded: an image whose float pixels would take more than
/// `max_bytes` (0 = this machine's physical memory) is an InputError naming
/// the file and its size. Throws InputError.
Image read_image(const std::string& path, ColorSpace space = ColorSpace::Auto, std::size_t max_bytes = 0);

/// Resamples to a new size (bilinear, box-filtered when shrinking; separable,
/// so each axis is treated on its own). Deterministic for any thread count.
Image resize_image(const Image& img, int width, int height);

/// Bilinear sample at (u, v) in [0,1]^2, v = 0 at the image's bottom row (uv
/// convention of the patches and the atlas), clamped at the borders.
void sample_bilinear(const Image& img, double u, double v, float* out);

enum class ExrPixelType { Half, Float };
/// Rle (the default): lossless run lengths, cheap to write and read. Piz:
/// lossless wavelet + Huffman, smaller files but its Huffman coder costs far
/// more CPU to write and read, so it is not the default
/// (docs/performance.md). Zip: lossless zlib, smallest and slowest. Dwaa:
/// lossy. None.
enum class ExrCompression { Piz, Zip, Dwaa, None, Rle };
/// How an EXR's pixels are laid out.
enum class ExrLayout {
  /// Scanlines, one resolution (the default): the smallest and fastest file.
  Scanline,
  /// A texture, as OpenImageIO's `maketx` makes it (ImageBufAlgo::make_texture,
  /// MakeTxTexture): 64x64 tiles and every MIP level down to 1x1, each half
  /// the size of the one above, rounded down (OpenEXR MIPMAP_LEVELS,
  /// ROUND_DOWN; any size, no resizing to a power of two). Levels below 0 are
  /// box-filtered (maketx's "box": the mean of 2x2 texels; along an odd
  /// side, the bilinear value at the centre of the texel's footprint) and
  /// computed in float, then stored in ExrOptions::type. Level 0 holds the
  /// scanline file's pixels, except that in half make_texture clamps every
  /// channel to the half range (+-65504, never infinity) and alpha ("A") to
  /// [0, 1] (a bake's alpha is coverage: always inside). Its header holds,
  /// besides the scanline file's:
  /// `wrapmodes` "clamp,clamp" (an atlas's border texels are gutter or
  /// background, never a chart: a filter that reaches past the border sees
  /// them again, not black, nor the far side of the atlas),
  /// `colorInteropID` (ExrContent), `textureformat` "Plain Texture" and
  /// `fovcot` (width / height). Not maketx's date, average colour
  /// (OpenImageIO sums it in an order that depends on its threads) nor
  /// `oiio:SHA-1` (a second pass over level 0, only used to share identical
  /// files): the same image gives the same bytes at any thread count. DWAA
  /// on one channel becomes ZIP (maketx's rule).
  TiledMipmap,
};
/// What a texture's channels hold, for its colour-space metadata
/// (`colorInteropID`, the Color Interop Forum's name for the space, which
/// OpenImageIO reads as the file's colour space since 3.1.10 and writes
/// itself since 3.2; OpenImageIO 2.4 writes no colour space into an EXR).
enum class ExrContent {
  /// Color when the channels are R, G, B or R, G, B, A, Data otherwise
  /// (displacement "Y", the AOV).
  Auto,
  /// Scene-linear Rec.709 colour: "lin_rec709_scene".
  Color,
  /// Not colour (displacement, ids, coordinates): "data", never
  /// colour-converted.
  Data,
};
struct ExrOptions {
  ExrPixelType type = ExrPixelType::Half;
  ExrCompression compression = ExrCompression::Rle;
  ExrLayout layout = ExrLayout::Scanline;
  /// Used by ExrLayout::TiledMipmap (a scanline file's header is unchanged).
  ExrContent content = ExrContent::Auto;
};
/// Writes an EXR with the given channel names (size == img.channels),
/// atomically (temporary file, then rename), or into the group `staged`.
/// The header holds no date, time or host: the same image gives the same
/// bytes. With ExrLayout::TiledMipmap, make_texture writes the texture
/// under a name of its own beside the temporary file and renames it to that
/// (a process killed meanwhile may leave `.STEM.tmpHOST-PID_K.XXXXXXXX.temp.EXT`,
/// XXXXXXXX hex digits), through the page cache (it opens the file itself:
/// LAPFLOW_DIRECT_IO does not apply), and, for a half file, it holds level 0
/// twice in float while it writes (a 6144^2 RGBA half atlas: 1.3 GiB more
/// than the image; its one-channel displacement: 0.32 GiB). Throws
/// OutputError.
void write_exr(const std::string& path, const Image& img, const std::vector<std::string>& channel_names,
               const ExrOptions& options = {}, StagedFiles* staged = nullptr);
/// An image converted to EXR half (IEEE binary16 bits, round to nearest
/// even), the same pixels write_exr writes for ExrPixelType::Half: a bake
/// converts its colour and displacement as soon as they are done, so the
/// frame waiting for the writer holds half the bytes.
struct HalfImage {
  int width = 0, height = 0, channels = 0;
  std::vector<uint16_t> bits;  ///< width*height*channels
};
HalfImage to_half_image(const Image& img);
/// n floats to half bits on this thread, as to_half_image converts them
/// (the same bits: IEEE binary16, round to nearest even).
void to_half(const float* in, uint16_t* out, std::size_t n);
/// write_exr of an image already in half (options.type is ignored).
void write_exr(const std::string& path, const HalfImage& img, const std::vector<std::string>& channel_names,
               const ExrOptions& options = {}, StagedFiles* staged = nullptr);
/// Writes a PNG (values clamped to [0,1], encoded to sRGB when `to_srgb`;
/// alpha, the last of 2 or 4 channels, is never encoded), atomically.
/// `bits` is 8 or 16 (16 for data maps: feature, displacement).
void write_png(const std::string& path, const Image& img, bool to_srgb, int bits = 8);

/// Channel names stored in an image file (e.g. {"R","G","B","A"} or
/// {"patch_id","u","v","w"}), in the order read_image returns the channels.
/// Throws InputError.
std::vector<std::string> image_channel_names(const std::string& path);

/// The texture an artist supplies: colour E, feature map F_m in [0,1],
/// displacement H. All three have the same size.
struct Exemplar {
  Image color;         ///< 3 channels, linear
  Image feature;       ///< 1 channel in [0,1]
  Image displacement;  ///< 1 channel; the feature map when none was given
  std::string name;
};

/// Loads an exemplar. The feature and displacement maps are resampled to the
/// colour image's size with a warning when their size differs; a different
/// aspect ratio is an InputError. Values of the feature map outside [0,1] are
/// an InputError.
Exemplar load_exemplar(const std::string& color_path, const std::string& feature_path,
                       const std::string& displacement_path = "");

/// The most frames an animated exemplar may have.
inline constexpr std::size_t kMaxExemplarFrames = 1000;

/// True when `path` names an animated exemplar: a frame pattern
/// (`lava.color.%04d.png`, `lava.color.####.png`, `$F4`) that is not itself
/// a file.
bool is_exemplar_sequence(const std::string& path);
/// The files of an animated exemplar's frames on disk, in order (`path`
/// alone for one image). Throws InputError naming a pattern with no frame
/// on disk.
std::vector<std::string> exemplar_frame_files(const std::string& path);

/// An animated exemplar's frames (docs/layers.md, "Animated exemplars"), or
/// the one frame of a still one. `color_path` is a frame pattern whose
/// frames on disk run without a gap; a feature or displacement path is a
/// pattern with the same frames, or one image for every frame. Every frame
/// has the first one's size. Throws InputError naming the file.
std::vector<Exemplar> load_exemplar_frames(const std::string& color_path, const std::string& feature_path,
                                           const std::string& displacement_path = "");

}  // namespace lapflow
