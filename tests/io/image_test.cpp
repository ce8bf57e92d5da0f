// Image I/O: EXR and PNG round trips through OpenImageIO, colour spaces,
// bilinear sampling conventions, resampling, exemplar loading and its errors,
// atomic writes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "io_test_helpers.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/image.hpp"

namespace lapflow {
namespace {
namespace fs = std::filesystem;
using test::TempDir;
using test::exr_header_compression;

float srgb_to_linear(float c) { return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f); }

/// Deterministic test pattern with values outside [0,1] too (EXR is HDR).
Image pattern(int w, int h, int c, float lo = -2.f, float hi = 40.f) {
  Image img(w, h, c);
  for (std::size_t i = 0; i < img.pixels.size(); ++i)
    img.pixels[i] = lo + (hi - lo) * float((i * 7919) % 1000) / 999.f;
  return img;
}

std::vector<std::string> files_in(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

TEST(ImageIo, ExrHalfRoundTripWithinHalfPrecision) {
  TempDir dir("image");
  const Image img = pattern(13, 7, 4);
  for (ExrCompression comp : {ExrCompression::Piz, ExrCompression::Zip, ExrCompression::Rle, ExrCompression::None}) {
    const std::string path = dir / "rgba.exr";
    write_exr(path, img, {"R", "G", "B", "A"}, {ExrPixelType::Half, comp});
    const Image back = read_image(path);  // float files: never sRGB-decoded
    ASSERT_EQ(back.width, 13);
    ASSERT_EQ(back.height, 7);
    ASSERT_EQ(back.channels, 4);
    for (std::size_t i = 0; i < img.pixels.size(); ++i)
      EXPECT_NEAR(back.pixels[i], img.pixels[i], std::abs(img.pixels[i]) * 1e-3 + 1e-4) << "index " << i;
  }
}


TEST(ImageIo, ExrCompressionIsTheOneAskedForAndRleByDefault) {
  // The default (README, --compression) is RLE; each option must reach the file.
  TempDir dir("image");
  const Image img = pattern(64, 32, 4);
  write_exr(dir / "default.exr", img, {"R", "G", "B", "A"});
  EXPECT_EQ(exr_header_compression(dir / "default.exr"), 1);
  const std::pair<ExrCompression, int> cases[] = {
      {ExrCompression::None, 0}, {ExrCompression::Rle, 1}, {ExrCompression::Zip, 3}, {ExrCompression::Piz, 4}};
  for (const auto& [comp, code] : cases) {
    write_exr(dir / "c.exr", img, {"R", "G", "B", "A"}, {ExrPixelType::Half, comp});
    EXPECT_EQ(exr_header_compression(dir / "c.exr"), code) << code;
  }
}

TEST(ImageIo, ExrHalfIsRoundedToNearestEven) {
  // write_exr converts to half itself (F16C where the CPU has it, on all
  // threads): every value must be the IEEE round-to-nearest-even half, the
  // conversion OIIO and Imath do, including ties, subnormals, the top of the
  // half range and negative zero (read_image refuses infinities).
  TempDir dir("image");
  std::vector<float> values = {0.f, -0.f, 1.f, -1.f, 65504.f, 65519.f, -65519.f, 6.1e-5f, 5.96e-8f, 2.98e-8f,
                               1e-9f, 0.1f, 1.f / 3.f, 1.00048828125f /* a tie: 1 + 2^-11 */,
                               1.00146484375f /* a tie rounding up: 1 + 3 * 2^-11 */, 3.14159f, 2047.5f};
  for (int i = 0; i < 2000; ++i) values.push_back(std::ldexp(float((i * 7919) % 4093) / 4093.f, (i % 40) - 24) * (i % 3 ? 1 : -1));
  Image img(int(values.size()), 1, 1);
  img.pixels = values;
  write_exr(dir / "h.exr", img, {"Y"}, {ExrPixelType::Half, ExrCompression::Piz});
  const Image back = read_image(dir / "h.exr");
  ASSERT_EQ(back.pixels.size(), values.size());
  for (std::size_t i = 0; i < values.size(); ++i) {
    const float expect = float(static_cast<_Float16>(values[i]));  // GCC: IEEE binary16, round to nearest even
    EXPECT_TRUE(back.pixels[i] == expect && std::signbit(back.pixels[i]) == std::signbit(expect))
        << "value " << values[i] << " read back as " << back.pixels[i] << ", expected " << expect;
  }
}

TEST(ImageIo, ExrFloatIsExactAndDwaaIsClose) {
  TempDir dir("image");
  const Image img = pattern(64, 32, 3, 0.f, 1.f);
  write_exr(dir / "f.exr", img, {"R", "G", "B"}, {ExrPixelType::Float, ExrCompression::Zip});
  EXPECT_EQ(read_image(dir / "f.exr").pixels, img.pixels);
  write_exr(dir / "d.exr", img, {"R", "G", "B"}, {ExrPixelType::Half, ExrCompression::Dwaa});
  const Image lossy = read_image(dir / "d.exr");
  double err = 0;
  for (std::size_t i = 0; i < img.pixels.size(); ++i) err += std::abs(lossy.pixels[i] - img.pixels[i]);
  EXPECT_LT(err / double(img.pixels.size()), 0.05);  // lossy, but the same image
}

TEST(ImageIo, ExrChannelNamesAndOrderPreserved) {
  TempDir dir("image");
  // The AOV layout of the bake: float ids and coordinates, not colour.
  Image aov = pattern(9, 5, 4, -1.f, 5000.f);
  write_exr(dir / "aov.exr", aov, {"patch_id", "u", "v", "w"}, {ExrPixelType::Float, ExrCompression::Piz});
  EXPECT_EQ(image_channel_names(dir / "aov.exr"), (std::vector<std::string>{"patch_id", "u", "v", "w"}));
  EXPECT_EQ(read_image(dir / "aov.exr").pixels, aov.pixels);

  Image disp = pattern(9, 5, 1);
  write_exr(dir / "disp.exr", disp, {"Y"});
  EXPECT_EQ(image_channel_names(dir / "disp.exr"), std::vector<std::string>{"Y"});
  EXPECT_EQ(read_image(dir / "disp.exr").channels, 1);
}

TEST(ImageIo, PngSrgbRoundTrip) {
  TempDir dir("image");
  // Linear values that are exact 8-bit sRGB codes survive encode + decode.
  Image img(256, 1, 3);
  for (int x = 0; x < 256; ++x)
    for (int c = 0; c < 3; ++c) img.at(x, 0, c) = srgb_to_linear(float((x + 85 * c) % 256) / 255.f);
  write_png(dir / "c.png", img, true);
  const Image back = read_image(dir / "c.png");  // 8-bit, tagged sRGB: decoded
  ASSERT_EQ(back.channels, 3);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) EXPECT_NEAR(back.pixels[i], img.pixels[i], 1e-5) << i;

  // Known answer: linear 0.5 is sRGB code 188; Linear reading returns the code.
  Image grey(1, 1, 1, 0.5f);
  write_png(dir / "g.png", grey, true);
  EXPECT_NEAR(read_image(dir / "g.png", ColorSpace::Linear).pixels[0], 188.f / 255.f, 1e-6);
  EXPECT_NEAR(read_image(dir / "g.png", ColorSpace::Auto).pixels[0], srgb_to_linear(188.f / 255.f), 1e-6);
}

TEST(ImageIo, Png16BitDataMapsStayLinear) {
  TempDir dir("image");
  Image map(40, 3, 1);
  for (int x = 0; x < 40; ++x)
    for (int y = 0; y < 3; ++y) map.at(x, y, 0) = float(x * 3 + y) / 119.f;
  write_png(dir / "f.png", map, false, 16);
  // Tagged linear by the writer, so even Auto does not decode it.
  for (ColorSpace cs : {ColorSpace::Linear, ColorSpace::Auto}) {
    const Image back = read_image(dir / "f.png", cs);
    for (std::size_t i = 0; i < map.pixels.size(); ++i) EXPECT_NEAR(back.pixels[i], map.pixels[i], 1.0 / 65535) << i;
  }
}

TEST(ImageIo, JpegTiffAndExrReadAlike) {
  // Other formats and bit depths, written by OpenImageIO's own oiiotool: an
  // sRGB file decodes to the same linear values whatever its container.
  if (std::system("oiiotool --help >/dev/null 2>&1") != 0) GTEST_SKIP() << "oiiotool is not installed";
  TempDir dir("formats");
  Image img(32, 16, 3);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 32; ++x)
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = srgb_to_linear(float(x * 8 + c * 2) / 255.f);
  write_png(dir / "src.png", img, true);
  const std::string src = dir / "src.png";
  struct Case {
    std::string name, args;
    float tolerance;
  };
  for (const Case& c : {Case{"u16.tif", "-d uint16", 1e-5f}, Case{"f32.tif", "-d float", 1e-5f},
                        Case{"q.jpg", "--attrib Compression jpeg:100", 0.02f},
                        Case{"lin.exr", "--colorconvert sRGB linear -d float", 1e-4f}}) {
    const std::string out = dir / c.name;
    ASSERT_EQ(std::system(("oiiotool '" + src + "' " + c.args + " -o '" + out + "' >/dev/null 2>&1").c_str()), 0)
        << c.name;
    const Image back = read_image(out);
    ASSERT_EQ(back.width, 32);
    ASSERT_EQ(back.channels, 3);
    for (std::size_t i = 0; i < img.pixels.size(); ++i)
      ASSERT_NEAR(back.pixels[i], img.pixels[i], c.tolerance) << c.name << " index " << i;
  }
}

TEST(ImageIo, SampleBilinearHasVZeroAtTheBottomRow) {
  Image img(2, 2, 1);
  img.at(0, 0, 0) = 0;  // top left
  img.at(1, 0, 0) = 1;  // top right
  img.at(0, 1, 0) = 2;  // bottom left
  img.at(1, 1, 0) = 3;  // bottom right
  float v = 0;
  sample_bilinear(img, 0.25, 0.25, &v);  // bottom-left pixel centre
  EXPECT_FLOAT_EQ(v, 2);
  sample_bilinear(img, 0.75, 0.75, &v);  // top-right pixel centre
  EXPECT_FLOAT_EQ(v, 1);
  sample_bilinear(img, 0.5, 0.5, &v);
  EXPECT_FLOAT_EQ(v, 1.5);
  sample_bilinear(img, 0.5, 0.25, &v);  // halfway along the bottom row
  EXPECT_FLOAT_EQ(v, 2.5);
  sample_bilinear(img, -3, -3, &v);  // clamped to the bottom-left corner
  EXPECT_FLOAT_EQ(v, 2);
  sample_bilinear(img, 2, 2, &v);
  EXPECT_FLOAT_EQ(v, 1);
}

TEST(ImageIo, ResizeKnownAnswers) {
  // Halving is an exact 2x2 box average.
  Image img(4, 2, 1);
  for (int x = 0; x < 4; ++x) {
    img.at(x, 0, 0) = float(x);
    img.at(x, 1, 0) = float(10 + x);
  }
  const Image half = resize_image(img, 2, 1);
  EXPECT_FLOAT_EQ(half.at(0, 0, 0), (0 + 1 + 10 + 11) / 4.f);
  EXPECT_FLOAT_EQ(half.at(1, 0, 0), (2 + 3 + 12 + 13) / 4.f);
  // Enlarging a constant stays constant; a ramp stays monotone with the same mean.
  const Image flat = resize_image(Image(3, 3, 2, 0.25f), 7, 5);
  for (float p : flat.pixels) EXPECT_FLOAT_EQ(p, 0.25f);
  Image ramp(4, 1, 1);
  for (int x = 0; x < 4; ++x) ramp.at(x, 0, 0) = float(x);
  const Image big = resize_image(ramp, 16, 1);
  double mean = 0;
  for (int x = 0; x < 16; ++x) {
    mean += big.at(x, 0, 0) / 16.0;
    if (x > 0) {
      EXPECT_GE(big.at(x, 0, 0), big.at(x - 1, 0, 0));
    }
  }
  EXPECT_NEAR(mean, 1.5, 1e-6);
}

TEST(Exemplar, LoadsAndResamplesMapsOfTheSameAspect) {
  TempDir dir("exemplar");
  Image color(64, 32, 4, 0.5f);  // RGBA colour: alpha dropped
  for (int x = 0; x < 64; ++x) color.at(x, 3, 0) = 1.f;
  write_png(dir / "rock.color.png", color, true);
  Image feature(32, 16, 1);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 32; ++x) feature.at(x, y, 0) = float(x) / 31.f;
  write_png(dir / "rock.feature.png", feature, false, 16);
  testing::internal::CaptureStderr();
  const Exemplar ex = load_exemplar(dir / "rock.color.png", dir / "rock.feature.png");
  const std::string warning = testing::internal::GetCapturedStderr();
  EXPECT_NE(warning.find("warning"), std::string::npos);
  EXPECT_NE(warning.find("resampled"), std::string::npos);
  EXPECT_EQ(ex.name, "rock");
  EXPECT_EQ(ex.color.channels, 3);
  EXPECT_EQ(ex.feature.width, 64);
  EXPECT_EQ(ex.feature.height, 32);
  EXPECT_EQ(ex.feature.channels, 1);
  EXPECT_EQ(ex.displacement.pixels, ex.feature.pixels);  // defaults to the feature map
  EXPECT_NEAR(ex.color.at(5, 3, 0), 1.f, 1e-5);
  EXPECT_NEAR(ex.color.at(5, 4, 0), 0.5f, 0.003);
  // Still a left-to-right ramp in [0,1] after resampling.
  EXPECT_LT(ex.feature.at(0, 10, 0), 0.02f);
  EXPECT_GT(ex.feature.at(63, 10, 0), 0.98f);
  for (float f : ex.feature.pixels) {
    EXPECT_GE(f, 0.f);
    EXPECT_LE(f, 1.f);
  }
}

TEST(Exemplar, GreyColourBecomesRgbAndDisplacementIsItsOwn) {
  TempDir dir("exemplar");
  write_png(dir / "g.png", Image(8, 8, 1, 0.25f), true);
  write_png(dir / "f.png", Image(8, 8, 1, 0.5f), false, 16);
  write_png(dir / "d.png", Image(16, 16, 1, 0.75f), false, 16);
  testing::internal::CaptureStderr();
  const Exemplar ex = load_exemplar(dir / "g.png", dir / "f.png", dir / "d.png");
  testing::internal::GetCapturedStderr();
  ASSERT_EQ(ex.color.channels, 3);
  EXPECT_NEAR(ex.color.at(2, 2, 1), 0.25f, 0.003);
  EXPECT_EQ(ex.displacement.width, 8);
  EXPECT_NEAR(ex.displacement.at(3, 3, 0), 0.75f, 1e-4);
}

TEST(Exemplar, DifferentAspectIsAnInputErrorNamingBothFiles) {
  TempDir dir("exemplar");
  write_png(dir / "c.png", Image(64, 32, 3, 0.5f), true);
  write_png(dir / "f.png", Image(32, 32, 1, 0.5f), false, 16);
  try {
    load_exemplar(dir / "c.png", dir / "f.png");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("f.png"), std::string::npos) << what;
    EXPECT_NE(what.find("c.png"), std::string::npos) << what;
    EXPECT_NE(what.find("32x32"), std::string::npos) << what;
    EXPECT_NE(what.find("64x32"), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
}

TEST(Exemplar, FeatureOutsideUnitRangeIsAnInputError) {
  TempDir dir("exemplar");
  write_png(dir / "c.png", Image(8, 8, 3, 0.5f), true);
  Image feature(8, 8, 1, 0.5f);
  feature.at(2, 5, 0) = 1.5f;
  write_exr(dir / "f.exr", feature, {"Y"}, {ExrPixelType::Float});
  try {
    load_exemplar(dir / "c.png", dir / "f.exr");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), dir / "f.exr");
    EXPECT_NE(std::string(e.what()).find("(2, 5)"), std::string::npos) << e.what();
  }
}

TEST(Exemplar, UnreadableImagesAreInputErrorsNamingTheFile) {
  TempDir dir("exemplar");
  write_png(dir / "f.png", Image(8, 8, 1, 0.5f), false, 16);
  test::write_bytes(dir / "broken.png", "\x89PNG\r\n\x1a\n this is not a png");
  test::write_bytes(dir / "text.jpg", "hello");
  for (const std::string& bad : {dir / "broken.png", dir / "text.jpg", dir / "missing.png"}) {
    try {
      load_exemplar(bad, dir / "f.png");
      FAIL() << "expected InputError for " << bad;
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), bad);
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(load_exemplar(dir / "f.png", dir / "broken.png"), InputError);
}

TEST(ImageIo, WritesAreAtomic) {
  TempDir dir("atomic");
  const Image img = pattern(16, 16, 3, 0.f, 1.f);
  write_exr(dir / "a.exr", img, {"R", "G", "B"});
  write_png(dir / "a.png", img, true);
  EXPECT_EQ(files_in(dir.str()), (std::vector<std::string>{"a.exr", "a.png"}));  // no temporary left
  const std::string before = test::read_bytes(dir / "a.exr");

  // A failing write (empty image) leaves the earlier file as it was.
  EXPECT_THROW(write_exr(dir / "a.exr", Image(), {}), OutputError);
  // A format OIIO cannot write fails before anything exists.
  test::write_bytes(dir / "keep.nosuchformat", "precious");
  EXPECT_THROW(write_exr(dir / "keep.nosuchformat", img, {"R", "G", "B"}), OutputError);
  // The final rename fails: the target is a folder.
  fs::create_directories(dir / "folder.exr");
  EXPECT_THROW(write_exr(dir / "folder.exr", img, {"R", "G", "B"}), OutputError);

  EXPECT_EQ(test::read_bytes(dir / "a.exr"), before);
  EXPECT_EQ(test::read_bytes(dir / "keep.nosuchformat"), "precious");
  EXPECT_TRUE(fs::is_directory(dir / "folder.exr"));
  EXPECT_EQ(files_in(dir.str()), (std::vector<std::string>{"a.exr", "a.png", "folder.exr", "keep.nosuchformat"}));
}

// ---- ExrLayout::TiledMipmap ------------------------------------------------

/// An OpenEXR header attribute: its type name and raw value.
struct ExrAttribute {
  std::string type, value;
  std::string str() const { return value; }
};

/// The attributes of a single-part OpenEXR file's header, by name.
std::map<std::string, ExrAttribute> exr_attributes(const std::string& path) {
  const std::string bytes = test::read_bytes(path);
  std::map<std::string, ExrAttribute> out;
  std::size_t at = 8;  // magic number and version
  auto cstring = [&] {
    const std::size_t end = bytes.find('\0', at);
    std::string s = bytes.substr(at, end - at);
    at = end + 1;
    return s;
  };
  while (at < bytes.size()) {
    const std::string name = cstring();
    if (name.empty()) break;
    ExrAttribute a;
    a.type = cstring();
    int32_t size = 0;
    std::memcpy(&size, bytes.data() + at, 4);
    at += 4;
    a.value = bytes.substr(at, std::size_t(size));
    at += std::size_t(size);
    out[name] = a;
  }
  return out;
}

/// Level count of a MIP map rounded down: floor(log2(max(w, h))) + 1.
int mip_levels_of(int w, int h) {
  int n = 1;
  for (int s = std::max(w, h); s > 1; s /= 2) ++n;
  return n;
}

/// The pixel type OpenEXR stores for every channel (1 half, 2 float; -1
/// when they differ).
int exr_pixel_type(const std::string& path) {
  const std::string list = exr_attributes(path).at("channels").value;
  int type = -2;
  for (std::size_t at = 0; at < list.size() && list[at] != '\0';) {
    at = list.find('\0', at) + 1;  // the name
    int32_t t = 0;
    std::memcpy(&t, list.data() + at, 4);
    type = type == -2 || type == t ? t : -1;
    at += 16;  // pixel type, pLinear + reserved, xSampling, ySampling
  }
  return type;
}

TEST(ImageIo, TiledExrHasTheScanlinePixelsTilesAndEveryMipLevel) {
  // Any size: a power of two, an odd side, a non-square one; RGBA colour and
  // one-channel displacement, half and float, from an Image and a HalfImage.
  TempDir dir("tiled");
  struct Size {
    int w, h;
  };
  for (const Size size : {Size{128, 128}, Size{300, 300}, Size{100, 37}})
    for (const int channels : {4, 1})
      for (const ExrPixelType type : {ExrPixelType::Half, ExrPixelType::Float}) {
        const std::string what = std::to_string(size.w) + "x" + std::to_string(size.h) + " c" +
                                 std::to_string(channels) + (type == ExrPixelType::Half ? " half" : " float");
        SCOPED_TRACE(what);
        Image img = pattern(size.w, size.h, channels, -1.f, 4.f);
        if (channels == 4)  // coverage, as a bake's alpha
          for (std::size_t p = 0; p < img.pixels.size(); p += 4) img.pixels[p + 3] = float(p % 17) / 16.f;
        const std::vector<std::string> names =
            channels == 4 ? std::vector<std::string>{"R", "G", "B", "A"} : std::vector<std::string>{"Y"};
        ExrOptions scan{type, ExrCompression::Rle};
        ExrOptions tiled = scan;
        tiled.layout = ExrLayout::TiledMipmap;
        write_exr(dir / "scan.exr", img, names, scan);
        write_exr(dir / "tiled.exr", img, names, tiled);
        const Image want = read_image(dir / "scan.exr");
        EXPECT_EQ(read_image(dir / "tiled.exr").pixels, want.pixels);
        EXPECT_EQ(image_channel_names(dir / "tiled.exr"), names);
        EXPECT_EQ(exr_pixel_type(dir / "tiled.exr"), type == ExrPixelType::Half ? 1 : 2);
        EXPECT_EQ(exr_header_compression(dir / "tiled.exr"), 1);  // RLE kept, not maketx's zip

        const ImageHeader h = read_image_header(dir / "tiled.exr");
        EXPECT_EQ(h.width, size.w);
        EXPECT_EQ(h.height, size.h);
        EXPECT_EQ(h.channels, channels);
        EXPECT_EQ(h.tile_width, 64);
        EXPECT_EQ(h.tile_height, 64);
        EXPECT_EQ(h.mip_levels, mip_levels_of(size.w, size.h));  // down to 1x1, never resized
        const ImageHeader s = read_image_header(dir / "scan.exr");
        EXPECT_EQ(s.tile_width, 0);
        EXPECT_EQ(s.mip_levels, 1);

        if (type == ExrPixelType::Half) {  // a bake's HalfImage: the same file
          write_exr(dir / "from_half.exr", to_half_image(img), names, tiled);
          EXPECT_EQ(test::read_bytes(dir / "from_half.exr"), test::read_bytes(dir / "tiled.exr"));
        }
      }
}

TEST(ImageIo, TiledExrInHalfClampsAlphaToTheUnitRange) {
  // make_texture clamps a half texture to the half range and its alpha to
  // [0, 1] (a bake's alpha is coverage: always inside); float is kept.
  TempDir dir("tiled");
  Image img(8, 8, 4, 0.5f);
  img.at(1, 1, 3) = 1.5f;
  img.at(2, 2, 3) = -0.25f;
  img.at(3, 3, 0) = 2.5f;
  ExrOptions tiled;
  tiled.layout = ExrLayout::TiledMipmap;
  write_exr(dir / "h.exr", img, {"R", "G", "B", "A"}, tiled);
  const Image h = read_image(dir / "h.exr");
  EXPECT_EQ(h.at(1, 1, 3), 1.f);
  EXPECT_EQ(h.at(2, 2, 3), 0.f);
  EXPECT_EQ(h.at(3, 3, 0), 2.5f);
  tiled.type = ExrPixelType::Float;
  write_exr(dir / "f.exr", img, {"R", "G", "B", "A"}, tiled);
  EXPECT_EQ(read_image(dir / "f.exr").pixels, img.pixels);
}

TEST(ImageIo, TiledExrMetadataHasTheWrapModeAndColourSpaceAndNoDate) {
  TempDir dir("tiled");
  ExrOptions tiled;
  tiled.layout = ExrLayout::TiledMipmap;
  tiled.compression = ExrCompression::Zip;
  write_exr(dir / "color.exr", pattern(70, 70, 4, 0.f, 1.f), {"R", "G", "B", "A"}, tiled);
  write_exr(dir / "disp.exr", pattern(70, 70, 1), {"Y"}, tiled);
  write_exr(dir / "rgb.exr", pattern(70, 70, 3, 0.f, 1.f), {"R", "G", "B"}, tiled);
  ExrOptions data = tiled;
  data.content = ExrContent::Data;  // e.g. a normal map stored as RGB
  write_exr(dir / "data.exr", pattern(70, 70, 3, 0.f, 1.f), {"R", "G", "B"}, data);

  const auto color = exr_attributes(dir / "color.exr");
  EXPECT_EQ(color.at("wrapmodes").str(), "clamp,clamp");
  EXPECT_EQ(color.at("colorInteropID").str(), "lin_rec709_scene");
  EXPECT_EQ(color.at("textureformat").str(), "Plain Texture");
  EXPECT_EQ(color.at("Software").str(), "lapflow");
  EXPECT_EQ(exr_header_compression(dir / "color.exr"), 3);  // ZIP
  // tiledesc: 64 x 64, MIPMAP_LEVELS (1) rounded down (0 << 4).
  const std::string tiles = color.at("tiles").value;
  ASSERT_EQ(tiles.size(), 9u);
  uint32_t tile[2];
  std::memcpy(tile, tiles.data(), 8);
  EXPECT_EQ(tile[0], 64u);
  EXPECT_EQ(tile[1], 64u);
  EXPECT_EQ(int(static_cast<unsigned char>(tiles[8])), 1);
  for (const auto& [name, a] : color) {
    // No date (capDate), average colour or command line: nothing that
    // changes from one write of the same image to the next.
    EXPECT_NE(name, "capDate");
    EXPECT_NE(name, "oiio:AverageColor");
    EXPECT_NE(name, "oiio:ConstantColor");
    EXPECT_NE(name, "oiio:SHA-1");
    EXPECT_EQ(name.find("History"), std::string::npos) << name;
  }
  EXPECT_EQ(exr_attributes(dir / "disp.exr").at("colorInteropID").str(), "data");
  EXPECT_EQ(exr_attributes(dir / "disp.exr").at("wrapmodes").str(), "clamp,clamp");
  EXPECT_EQ(exr_attributes(dir / "rgb.exr").at("colorInteropID").str(), "lin_rec709_scene");
  EXPECT_EQ(exr_attributes(dir / "data.exr").at("colorInteropID").str(), "data");

  // The scanline file's header is as it was: no texture metadata.
  write_exr(dir / "scan.exr", pattern(70, 70, 4, 0.f, 1.f), {"R", "G", "B", "A"});
  const auto scan = exr_attributes(dir / "scan.exr");
  for (const char* name : {"wrapmodes", "colorInteropID", "textureformat", "tiles", "capDate", "oiio:SHA-1"})
    EXPECT_EQ(scan.count(name), 0u) << name;
}

TEST(ImageIo, TiledExrMipLevelsAreBoxFiltered) {
  // Level k of a power-of-two texture is the mean of 2^k x 2^k texels (in
  // float); the last one, 1x1, the mean of the whole image. Read with
  // OpenImageIO's own oiiotool (lapflow reads level 0 only).
  if (std::system("oiiotool --help >/dev/null 2>&1") != 0) GTEST_SKIP() << "oiiotool is not installed";
  TempDir dir("tiled");
  const Image img = pattern(32, 16, 4, 0.f, 1.f);
  ExrOptions tiled{ExrPixelType::Float, ExrCompression::Rle};
  tiled.layout = ExrLayout::TiledMipmap;
  write_exr(dir / "t.exr", img, {"R", "G", "B", "A"}, tiled);
  ASSERT_EQ(read_image_header(dir / "t.exr").mip_levels, 6);  // 32x16 ... 2x1, 1x1
  for (const int level : {1, 5}) {
    const std::string out = dir / ("level" + std::to_string(level) + ".exr");
    ASSERT_EQ(std::system(("oiiotool '" + (dir / "t.exr") + "' --selectmip " + std::to_string(level) + " -o '" + out +
                           "' >/dev/null 2>&1")
                              .c_str()),
              0);
    const Image got = read_image(out);
    const int w = std::max(1, img.width >> level), h = std::max(1, img.height >> level);
    ASSERT_EQ(got.width, w);
    ASSERT_EQ(got.height, h);
    const int bx = img.width / w, by = img.height / h;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 4; ++c) {
          double sum = 0;
          for (int j = 0; j < by; ++j)
            for (int i = 0; i < bx; ++i) sum += img.at(x * bx + i, y * by + j, c);
          EXPECT_NEAR(got.at(x, y, c), sum / (bx * by), 1e-5) << "level " << level << " at " << x << "," << y;
        }
  }
}

TEST(ImageIo, TiledExrIsTheSameBytesAtAnyThreadCount) {
  // make_texture filters and hashes on OpenImageIO's threads and OpenEXR
  // compresses tiles on its own: the file must not depend on either.
  TempDir dir("tiled");
  const Image img = pattern(333, 200, 4, -1.f, 3.f);
  ExrOptions tiled;
  tiled.layout = ExrLayout::TiledMipmap;
  const int before = thread_count();
  std::string first;
  for (const int threads : {1, 2, 4, 1}) {
    set_thread_count(threads);
    write_exr(dir / "t.exr", img, {"R", "G", "B", "A"}, tiled);
    const std::string bytes = test::read_bytes(dir / "t.exr");
    if (first.empty())
      first = bytes;
    else
      EXPECT_TRUE(bytes == first) << threads << " threads";
  }
  set_thread_count(before);
}

TEST(ImageIo, TiledExrWritesAreAtomicAndStaged) {
  TempDir dir("tiled");
  const Image img = pattern(80, 80, 4, 0.f, 1.f);
  ExrOptions tiled;
  tiled.layout = ExrLayout::TiledMipmap;
  write_exr(dir / "a.exr", img, {"R", "G", "B", "A"}, tiled);
  EXPECT_EQ(files_in(dir.str()), std::vector<std::string>{"a.exr"});  // no temporary left (ours or OIIO's)
  const std::string before = test::read_bytes(dir / "a.exr");

  // Staged: only the temporary exists until the group commits.
  {
    StagedFiles staged;
    write_exr(dir / "b.exr", to_half_image(img), {"R", "G", "B", "A"}, tiled, &staged);
    write_exr(dir / "c.exr", Image(80, 80, 1, 0.25f), {"Y"}, tiled, &staged);
    EXPECT_EQ(files_in(dir.str()).size(), 3u);
    EXPECT_FALSE(fs::exists(dir / "b.exr"));
    staged.commit(dir / "c.exr");
  }
  EXPECT_EQ(files_in(dir.str()), (std::vector<std::string>{"a.exr", "b.exr", "c.exr"}));
  EXPECT_EQ(test::read_bytes(dir / "b.exr"), before);
  {
    StagedFiles abandoned;
    write_exr(dir / "d.exr", img, {"R", "G", "B", "A"}, tiled, &abandoned);
  }
  EXPECT_EQ(files_in(dir.str()), (std::vector<std::string>{"a.exr", "b.exr", "c.exr"}));

  // make_texture cannot write (no such folder): an OutputError naming the
  // file, never a temporary name.
  try {
    write_exr(dir / "missing/e.exr", img, {"R", "G", "B", "A"}, tiled);
    FAIL() << "expected OutputError";
  } catch (const OutputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("e.exr"), std::string::npos) << what;
    EXPECT_EQ(what.find(".tmp"), std::string::npos) << what;
    EXPECT_EQ(what.find(".temp"), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
  // The final rename fails (the target is a folder): a.exr's neighbours
  // untouched, nothing left behind.
  fs::create_directories(dir / "folder.exr");
  EXPECT_THROW(write_exr(dir / "folder.exr", img, {"R", "G", "B", "A"}, tiled), OutputError);
  EXPECT_THROW(write_exr(dir / "f.exr", Image(), {}, tiled), OutputError);
  EXPECT_EQ(test::read_bytes(dir / "a.exr"), before);
  EXPECT_EQ(files_in(dir.str()), (std::vector<std::string>{"a.exr", "b.exr", "c.exr", "folder.exr"}));
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

TEST(Exemplar, ShippedExemplarsLoadWithFullRangeFeatureMaps) {
  const std::string dir = LAPFLOW_SOURCE_DIR "/exemplars/";
  for (const char* name : {"pebbles", "lava", "squares", "scales", "foam"}) {
    const std::string base = dir + name;
    const Exemplar ex = load_exemplar(base + ".color.png", base + ".feature.png", base + ".disp.png");
    EXPECT_EQ(ex.name, name);
    EXPECT_GE(ex.color.width, 512) << name;
    EXPECT_LE(ex.color.width, 1024) << name;
    EXPECT_EQ(ex.feature.width, ex.color.width) << name;
    EXPECT_EQ(ex.displacement.height, ex.color.height) << name;
    // Erosion needs both ends: element centres near 1, borders near 0.
    const auto [lo, hi] = std::minmax_element(ex.feature.pixels.begin(), ex.feature.pixels.end());
    EXPECT_LT(*lo, 0.05f) << name;
    EXPECT_GT(*hi, 0.95f) << name;
  }
}

}  // namespace
}  // namespace lapflow
