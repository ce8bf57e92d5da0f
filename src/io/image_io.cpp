// Images in and out. OpenImageIO lives here and nowhere else; the rest of
// lapflow sees only lapflow::Image (interleaved linear float, row 0 on top).
#include <Imath/half.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <immintrin.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstdlib>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <system_error>

#include <fmt/format.h>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/direct_file.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/memory.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow {
namespace {

// OIIO error messages may span several lines; lapflow errors are one line.
std::string one_line(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  std::string out;
  for (char c : s) {
    if (c == '\n')
      out += "; ";
    else
      out += c;
  }
  return out.empty() ? std::string("unknown OpenImageIO error") : out;
}

// libpng's own chatter. OIIO 2.4's PNG plugin gives libpng an error handler
// that records the message for geterror() and returns; libpng then calls its
// default handler, which prints "libpng error: MESSAGE" to stderr before it
// longjmps (png_error in pngerror.c). OIIO has no attribute for it and never
// lets us at the png_struct, so while libpng works, file descriptor 2 goes
// to a temporary file: the "libpng ..." lines are dropped or folded into
// lapflow's own one-line message (OIIO's text already holds the same
// message), anything else is printed as it came. One capture at a time, and
// only around PNG files.
class LibpngChatter {
 public:
  explicit LibpngChatter(bool png) {
    if (!png) return;
    lock_ = std::unique_lock(mutex());
    std::fflush(stderr);
    file_ = std::tmpfile();
    saved_ = file_ ? ::dup(STDERR_FILENO) : -1;
    if (saved_ < 0 || ::dup2(::fileno(file_), STDERR_FILENO) < 0) restore();
  }
  ~LibpngChatter() { finish(); }
  LibpngChatter(const LibpngChatter&) = delete;
  LibpngChatter& operator=(const LibpngChatter&) = delete;

  /// Stops capturing; returns libpng's lines joined by "; " (and prints
  /// whatever else was written meanwhile).
  std::string finish() {
    if (!file_) return "";
    std::fflush(stderr);
    restore();
    std::string text, chatter, other;
    char buf[4096];
    std::rewind(file_);
    for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, file_)) > 0;) text.append(buf, n);
    std::fclose(file_);
    file_ = nullptr;
    for (std::size_t b = 0; b < text.size();) {
      std::size_t e = text.find('\n', b);
      if (e == std::string::npos) e = text.size();
      const std::string line = text.substr(b, e - b);
      if (line.rfind("libpng ", 0) == 0)
        chatter += (chatter.empty() ? "" : "; ") + line;
      else if (!line.empty())
        other += line + "\n";
      b = e + 1;
    }
    if (!other.empty()) std::fputs(other.c_str(), stderr);
    if (lock_.owns_lock()) lock_.unlock();
    return chatter;
  }

 private:
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  void restore() {
    if (saved_ >= 0) {
      ::dup2(saved_, STDERR_FILENO);
      ::close(saved_);
      saved_ = -1;
    }
  }

  std::unique_lock<std::mutex> lock_;
  std::FILE* file_ = nullptr;
  int saved_ = -1;
};

// Whether the file at `path` is a PNG (the 8-byte signature): the only
// reader whose library prints on its own (LibpngChatter).
bool is_png_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char sig[8] = {};
  return f.read(sig, 8) && std::string_view(sig, 8) == std::string_view("\x89PNG\r\n\x1a\n", 8);
}

// OIIO's message for a failed read, with libpng's own line when it says
// something OIIO's does not.
std::string read_failure(const std::string& library_text, const std::string& chatter) {
  std::string text = one_line(library_text);
  const std::string prefix = "libpng error: ";
  const std::string said = chatter.rfind(prefix, 0) == 0 ? chatter.substr(prefix.size()) : chatter;
  if (!said.empty() && text.find(said) == std::string::npos) text += " (" + chatter + ")";
  return text;
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

float srgb_to_linear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}
float linear_to_srgb(float c) {
  return c <= 0.0031308f ? c * 12.92f : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

// Whether a file read with ColorSpace::Auto holds sRGB-encoded values. Integer
// files are display-referred in practice (PNG/JPEG from paint programs), so
// they are decoded unless explicitly tagged linear; float files are linear
// unless explicitly tagged sRGB.
bool auto_is_srgb(const OIIO::ImageSpec& spec) {
  const std::string tag = lower(spec.get_string_attribute("oiio:ColorSpace"));
  if (tag.find("srgb") != std::string::npos) return true;
  if (tag == "linear" || tag == "scene_linear" || tag.find("lin_") == 0) return false;
  const auto base = OIIO::TypeDesc::BASETYPE(spec.format.basetype);
  return !(base == OIIO::TypeDesc::HALF || base == OIIO::TypeDesc::FLOAT || base == OIIO::TypeDesc::DOUBLE);
}

// Index of the alpha channel (never colour-decoded), or -1.
int alpha_channel(const OIIO::ImageSpec& spec) {
  if (spec.alpha_channel >= 0) return spec.alpha_channel;
  if (spec.nchannels == 2 || spec.nchannels == 4) return spec.nchannels - 1;
  return -1;
}

/// 1D resampling weights: for output i, contributions (source index, weight).
struct Taps {
  std::vector<std::size_t> offset;  // CSR offsets, size n_out + 1
  std::vector<int> index;
  std::vector<float> weight;
};

Taps make_taps(int n_in, int n_out) {
  Taps t;
  t.offset.push_back(0);
  const double scale = double(n_in) / double(n_out);
  for (int i = 0; i < n_out; ++i) {
    if (scale > 1.0) {
      // Shrinking: exact box filter (area average over the footprint).
      const double a = i * scale, b = (i + 1) * scale;
      const int j0 = int(std::floor(a)), j1 = std::min(n_in - 1, int(std::ceil(b)) - 1);
      for (int j = j0; j <= j1; ++j) {
        const double cover = std::min(b, double(j + 1)) - std::max(a, double(j));
        if (cover <= 0) continue;
        t.index.push_back(j);
        t.weight.push_back(float(cover / scale));
      }
    } else {
      // Enlarging (or same size): bilinear between pixel centres, clamped.
      const double s = (i + 0.5) * scale - 0.5;
      const int j0 = int(std::floor(s));
      const double f = s - j0;
      t.index.push_back(std::clamp(j0, 0, n_in - 1));
      t.weight.push_back(float(1.0 - f));
      t.index.push_back(std::clamp(j0 + 1, 0, n_in - 1));
      t.weight.push_back(float(f));
    }
    t.offset.push_back(t.index.size());
  }
  return t;
}

void check_channels(const std::string& path, const Image& img) {
  if (img.width <= 0 || img.height <= 0 || img.channels <= 0 ||
      img.pixels.size() != std::size_t(img.width) * img.height * img.channels)
    throw OutputError(path + ": cannot write an empty or inconsistent image");
}

// A failed write through OIIO: OpenEXR says only "File output failed", so
// the reason is looked up (full disk, file-size limit), and the temporary
// name in the library's text becomes the file's own.
OutputError write_failure(const std::string& path, const std::string& tmp, std::string library_text) {
  const std::string name = std::filesystem::path(path).filename().string();
  for (std::size_t at; (at = library_text.find(tmp)) != std::string::npos;) library_text.replace(at, tmp.size(), name);
  const std::string reason = write_failure_reason(tmp);
  return OutputError(path + ": write failed: " + (reason.empty() ? library_text : reason + " (" + library_text + ")"));
}

// OIIO's output through a DirectFile (around the page cache). OIIO's OpenEXR
// writer only writes, seeks and tells, one call at a time.
class DirectProxy final : public OIIO::Filesystem::IOProxy {
 public:
  explicit DirectProxy(const std::string& path) : IOProxy(path, Write), file_(path) {
    if (!file_.ok()) m_mode = Closed;
  }
  const char* proxytype() const override { return "lapflow-direct"; }
  void close() override {
    if (m_mode == Closed) return;
    file_.close();
    m_mode = Closed;
  }
  bool seek(int64_t offset) override {
    if (offset < 0) return false;
    m_pos = offset;
    return true;
  }
  size_t read(void*, size_t) override { return 0; }
  size_t pread(void*, size_t, int64_t) override { return 0; }
  size_t write(const void* buf, size_t size) override {
    const size_t n = pwrite(buf, size, m_pos);
    m_pos += int64_t(n);
    return n;
  }
  size_t pwrite(const void* buf, size_t size, int64_t offset) override {
    const std::lock_guard<std::mutex> lock(mutex_);
    return offset >= 0 && file_.write_at(buf, size, uint64_t(offset)) ? size : 0;
  }
  size_t size() const override { return size_t(file_.size()); }
  const DirectFile& file() const { return file_; }

 private:
  DirectFile file_;
  std::mutex mutex_;
};

// Writes `data` (already in the file's value range) through OIIO to tmp:
// an EXR through a DirectProxy, unless LAPFLOW_DIRECT_IO=0.
void write_oiio(const std::string& path, const std::string& tmp, const OIIO::ImageSpec& spec,
                OIIO::TypeDesc data_type, const void* data) {
  std::unique_ptr<DirectProxy> proxy;  // outlives `out`, which may use it until destroyed
  auto out = OIIO::ImageOutput::create(tmp);
  if (!out) throw OutputError(path + ": " + one_line(OIIO::geterror()));
  out->threads(thread_count());
  if (direct_io_enabled() && std::string(out->format_name()) == "openexr" && out->supports("ioproxy")) {
    proxy = std::make_unique<DirectProxy>(tmp);
    if (!proxy->file().ok())
      throw OutputError(path + ": cannot open for writing: " + std::generic_category().message(proxy->file().error()));
    if (!out->set_ioproxy(proxy.get())) throw OutputError(path + ": " + one_line(out->geterror()));
  }
  // The proxy's own errno, when it has one, is the reason a write failed.
  auto failure = [&](std::string library_text) {
    if (proxy && proxy->file().error() != 0)
      return OutputError(path + ": write failed: " + std::generic_category().message(proxy->file().error()));
    return write_failure(path, tmp, std::move(library_text));
  };
  // libpng prints "libpng error: Write Error" on a full disk, as when reading.
  LibpngChatter chatter(std::string(out->format_name()) == "png");
  if (!out->open(tmp, spec)) throw OutputError(path + ": cannot open for writing: " + one_line(out->geterror()));
  if (!out->write_image(data_type, data)) {
    const std::string err = one_line(out->geterror());
    out->close();
    chatter.finish();
    throw failure(err);
  }
  bool closed = out->close();
  chatter.finish();
  // OIIO leaves a proxy it did not open to its owner: the last block and
  // the file's size are written here.
  if (proxy) {
    proxy->close();
    closed = closed && proxy->file().error() == 0;
  }
  if (!closed) throw failure(one_line(out->geterror()));
}

// float -> half, round to nearest even (what Imath::half and OIIO's own
// conversion do), eight at a time with F16C where the CPU has it.
__attribute__((target("avx,f16c"))) void to_half_f16c(const float* in, uint16_t* out, std::size_t n) {
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8)
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i),
                     _mm256_cvtps_ph(_mm256_loadu_ps(in + i), _MM_FROUND_TO_NEAREST_INT));
  for (; i < n; ++i) out[i] = Imath::half(in[i]).bits();
}

void to_half_portable(const float* in, uint16_t* out, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) out[i] = Imath::half(in[i]).bits();
}

// OIIO converts a whole image to half on one thread before OpenEXR
// compresses it on its pool; converting here first, on all threads, takes
// that serial step out of every frame's write.
std::vector<uint16_t> to_half(const std::vector<float>& in) {
  std::vector<uint16_t> out(in.size());
  parallel_for(in.size(), [&](std::size_t b, std::size_t e) { lapflow::to_half(in.data() + b, out.data() + b, e - b); },
               1 << 16);
  return out;
}

}  // namespace

void to_half(const float* in, uint16_t* out, std::size_t n) {
  static const bool f16c = __builtin_cpu_supports("f16c") && __builtin_cpu_supports("avx");
  if (f16c)
    to_half_f16c(in, out, n);
  else
    to_half_portable(in, out, n);
}

namespace {

// Opens an image for reading its header (no pixel is decoded yet) and checks
// that it has a plain 2D size.
std::unique_ptr<OIIO::ImageInput> open_image(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(path, "cannot read image: file does not exist");
  // Keep colour and alpha as stored (no premultiplication of PNG/TIFF
  // colour): exemplars drop alpha, and sRGB decoding needs the unscaled value.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  LibpngChatter chatter(is_png_file(path));
  auto in = OIIO::ImageInput::open(path, &config);
  const std::string said = chatter.finish();
  if (!in) throw InputError(path, "cannot read image: " + read_failure(OIIO::geterror(), said));
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
    throw InputError(path, "image has no pixels");
  if (spec.depth > 1) throw InputError(path, "volume images are not supported");
  return in;
}

}  // namespace

ImageHeader read_image_header(const std::string& path) {
  const auto in = open_image(path);
  const OIIO::ImageSpec& spec = in->spec();
  ImageHeader h{spec.width, spec.height, spec.nchannels};
  h.tile_width = spec.tile_width;
  h.tile_height = spec.tile_height;
  // Each MIP level's header is known without reading a pixel.
  while (in->seek_subimage(0, h.mip_levels)) ++h.mip_levels;
  return h;
}

Image read_image(const std::string& path, ColorSpace space, std::size_t max_bytes) {
  auto in = open_image(path);
  const OIIO::ImageSpec spec = in->spec();
  // Before any pixel is decoded: a corrupt or hostile header (a 1 KB PNG
  // that claims 100000x100000) is refused, never an allocation that fails.
  const ImageHeader header{spec.width, spec.height, spec.nchannels};
  const std::size_t limit = max_bytes > 0 ? max_bytes : physical_memory();
  if (limit > 0 && header.decoded_bytes() > double(limit))
    throw InputError(path, fmt::format("the header says {}x{} pixels x {} channels: decoding needs {}, more than {}",
                                       spec.width, spec.height, spec.nchannels,
                                       format_bytes(header.decoded_bytes()),
                                       max_bytes > 0 ? "the memory budget (--max-memory) of " + format_bytes(double(limit))
                                                     : "this machine's " + format_bytes(double(limit))));
  Image img(spec.width, spec.height, spec.nchannels);
  LibpngChatter chatter(is_png_file(path));
  const bool read = in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, img.pixels.data());
  const std::string said = chatter.finish();
  if (!read) throw InputError(path, "cannot read image: " + read_failure(in->geterror(), said));
  in->close();
  for (float v : img.pixels)
    if (!std::isfinite(v)) throw InputError(path, "image contains NaN or infinite values");

  const bool decode = space == ColorSpace::sRGB || (space == ColorSpace::Auto && auto_is_srgb(spec));
  if (decode) {
    const int alpha = alpha_channel(spec);
    const int ch = img.channels;
    parallel_for(std::size_t(img.width) * img.height, [&](std::size_t b, std::size_t e) {
      for (std::size_t p = b; p < e; ++p)
        for (int c = 0; c < ch; ++c)
          if (c != alpha) img.pixels[p * ch + c] = srgb_to_linear(img.pixels[p * ch + c]);
    }, 4096);
  }
  return img;
}

std::vector<std::string> image_channel_names(const std::string& path) {
  LibpngChatter chatter(is_png_file(path));
  auto in = OIIO::ImageInput::open(path);
  const std::string said = chatter.finish();
  if (!in) throw InputError(path, "cannot read image: " + read_failure(OIIO::geterror(), said));
  return in->spec().channelnames;
}

Image resize_image(const Image& img, int width, int height) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("resize_image: size must be positive");
  if (img.empty()) throw std::invalid_argument("resize_image: empty image");
  if (width == img.width && height == img.height) return img;
  const int ch = img.channels;
  // Separable: horizontal pass into tmp (width x img.height), then vertical.
  const Taps tx = make_taps(img.width, width), ty = make_taps(img.height, height);
  Image tmp(width, img.height, ch);
  parallel_for(std::size_t(img.height), [&](std::size_t b, std::size_t e) {
    for (std::size_t y = b; y < e; ++y)
      for (int x = 0; x < width; ++x)
        for (int c = 0; c < ch; ++c) {
          float acc = 0;
          for (std::size_t k = tx.offset[x]; k < tx.offset[x + 1]; ++k)
            acc += tx.weight[k] * img.at(tx.index[k], int(y), c);
          tmp.at(x, int(y), c) = acc;
        }
  }, 8);
  Image out(width, height, ch);
  parallel_for(std::size_t(height), [&](std::size_t b, std::size_t e) {
    for (std::size_t y = b; y < e; ++y)
      for (int x = 0; x < width; ++x)
        for (int c = 0; c < ch; ++c) {
          float acc = 0;
          for (std::size_t k = ty.offset[y]; k < ty.offset[y + 1]; ++k)
            acc += ty.weight[k] * tmp.at(x, ty.index[k], c);
          out.at(x, int(y), c) = acc;
        }
  }, 8);
  return out;
}

void sample_bilinear(const Image& img, double u, double v, float* out) {
  // Pixel centres sit at (i + 0.5) / size; v = 0 is the bottom row (row h-1).
  const double fx = u * img.width - 0.5;
  const double fy = (1.0 - v) * img.height - 0.5;
  const double cx = std::clamp(fx, 0.0, double(img.width - 1));
  const double cy = std::clamp(fy, 0.0, double(img.height - 1));
  const int x0 = int(cx), y0 = int(cy);
  const int x1 = std::min(x0 + 1, img.width - 1), y1 = std::min(y0 + 1, img.height - 1);
  const float ax = float(cx - x0), ay = float(cy - y0);
  for (int c = 0; c < img.channels; ++c) {
    const float top = img.at(x0, y0, c) * (1 - ax) + img.at(x1, y0, c) * ax;
    const float bottom = img.at(x0, y1, c) * (1 - ax) + img.at(x1, y1, c) * ax;
    out[c] = top * (1 - ay) + bottom * ay;
  }
}

namespace {

OIIO::ImageSpec exr_spec(const std::string& path, int width, int height, int channels,
                         const std::vector<std::string>& channel_names, ExrPixelType type,
                         ExrCompression compression_type) {
  if (int(channel_names.size()) != channels)
    throw std::invalid_argument(path + ": write_exr needs one channel name per channel");
  OIIO::ImageSpec spec(width, height, channels, type == ExrPixelType::Half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
  spec.channelnames = channel_names;
  spec.alpha_channel = -1;
  for (int c = 0; c < channels; ++c)
    if (channel_names[c] == "A") spec.alpha_channel = c;
  const char* compression = "rle";
  switch (compression_type) {
    case ExrCompression::Piz: compression = "piz"; break;
    case ExrCompression::Zip: compression = "zip"; break;
    case ExrCompression::Dwaa: compression = "dwaa"; break;
    case ExrCompression::None: compression = "none"; break;
    case ExrCompression::Rle: compression = "rle"; break;
  }
  spec.attribute("compression", compression);
  spec.attribute("oiio:ColorSpace", "Linear");
  spec.attribute("Software", "lapflow");
  // No date in the header, so the same image always gives the same bytes (a
  // digest can check a farm's or a re-run's frames). OIIO stamps the time
  // as DateTime unless the spec has one; one that is not a string is
  // dropped when the header is written, since EXR's capDate is a string.
  // Debian's OIIO prints a debug line about each such drop unless told
  // otherwise (OPENIMAGEIO_DEBUG still turns its debug output on).
  static const bool quiet_oiio = [] { return std::getenv("OPENIMAGEIO_DEBUG") || OIIO::attribute("debug", 0); }();
  (void)quiet_oiio;
  spec.attribute("DateTime", 0);
  // OpenEXR keeps its own thread pool, separate from OIIO's "threads".
  OIIO::attribute("exr_threads", thread_count());
  return spec;
}

// Whether the channels are colour: R, G, B with or without A.
bool colour_channels(const std::vector<std::string>& names) {
  return names == std::vector<std::string>{"R", "G", "B"} || names == std::vector<std::string>{"R", "G", "B", "A"};
}

// OIIO's text about a failed texture names its own temporary file,
// TMPSTEM.XXXXXXXX.temp.EXT beside ours (TMPSTEM.EXT): both become the
// file's own name.
std::string texture_failure_text(std::string text, const std::string& path, const std::string& tmp) {
  const std::string name = std::filesystem::path(path).filename().string();
  const std::string ext = std::filesystem::path(tmp).extension().string();
  const std::string stem = tmp.substr(0, tmp.size() - ext.size());
  const std::string inner_tail = ".temp" + ext;
  for (std::size_t at = 0; (at = text.find(stem, at)) != std::string::npos;) {
    std::size_t end = at + stem.size();
    if (end + 9 + inner_tail.size() <= text.size() && text[end] == '.' &&
        text.compare(end + 9, inner_tail.size(), inner_tail) == 0)
      end += 9 + inner_tail.size();  // OIIO's: TMPSTEM.XXXXXXXX.temp.EXT
    else if (text.compare(end, ext.size(), ext) == 0)
      end += ext.size();  // ours
    text.replace(at, end - at, name);
    at += name.size();
  }
  return text;
}

// Writes a float image (`pixels`, spec's size and channels) as a tiled,
// MIP-mapped OpenEXR texture in spec.format (half or float) to tmp, with
// OIIO's make_texture (ExrLayout::TiledMipmap). make_texture works in
// float: given float pixels, it takes them as level 0 (no copy; it only
// reads them), where it would copy any other type to float itself, on one
// thread.
void write_texture(const std::string& path, const std::string& tmp, const OIIO::ImageSpec& spec, const float* pixels,
                   ExrContent content) {
  OIIO::ImageSpec float_spec = spec;
  float_spec.set_format(OIIO::TypeDesc::FLOAT);
  const OIIO::ImageBuf src(float_spec, const_cast<float*>(pixels));
  OIIO::ImageSpec config;
  config.format = spec.format;
  config.tile_width = 64;
  config.tile_height = 64;
  config.tile_depth = 1;
  // Attributes in `config` override make_texture's own: compression (it
  // would use zip), the date (it stamps the time unless given one; one that
  // is not a string is dropped when the header is written, as exr_spec's).
  config.attribute("compression", spec.get_string_attribute("compression"));
  config.attribute("DateTime", 0);
  config.attribute("wrapmodes", "clamp,clamp");
  if (content == ExrContent::Auto) content = colour_channels(spec.channelnames) ? ExrContent::Color : ExrContent::Data;
  config.attribute("colorInteropID", content == ExrContent::Color ? "lin_rec709_scene" : "data");
  // Instructions (never written to the file).
  config.attribute("maketx:fileformatname", "openexr");
  config.attribute("maketx:filtername", "box");
  config.attribute("maketx:resize", 0);
  config.attribute("maketx:nomipmap", 0);
  config.attribute("maketx:constant_color_detect", 0);
  config.attribute("maketx:opaque_detect", 0);
  config.attribute("maketx:monochrome_detect", 0);
  // The average colour is a sum over threads merged in the order they
  // finish: its last digits would change from one write to the next.
  config.attribute("maketx:compute_average", 0);
  // No SHA-1 of the pixels: OIIO's texture cache uses it only to share
  // identical files (no two frames' atlases are), and it costs a second
  // pass over level 0.
  config.attribute("maketx:hash", 0);
  // make_texture runs on OIIO's own pool (OpenEXR on its own, exr_threads):
  // lapflow's thread count, as for every other step.
  if (int threads = 0; !OIIO::getattribute("threads", threads) || threads != thread_count())
    OIIO::attribute("threads", thread_count());
  OIIO::geterror();  // nothing left from an earlier call
  if (!OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, src, tmp, config))
    throw write_failure(path, tmp, texture_failure_text(one_line(OIIO::geterror()), path, tmp));
}

}  // namespace

namespace {

// Half bits to float, eight at a time with F16C where the CPU has it
// (exact: every half is a float).
__attribute__((target("avx,f16c"))) void to_float_f16c(const uint16_t* in, float* out, std::size_t n) {
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8)
    _mm256_storeu_ps(out + i, _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(in + i))));
  for (Imath::half h; i < n; ++i) {
    h.setBits(in[i]);
    out[i] = float(h);
  }
}

void to_float_portable(const uint16_t* in, float* out, std::size_t n) {
  for (Imath::half h; n-- > 0;) {
    h.setBits(*in++);
    *out++ = float(h);
  }
}

// A HalfImage's pixels in float, converted on all threads into memory that
// is not zeroed first (a 6144^2 RGBA atlas: 600 MB, whose first touch is
// what costs; each thread touches its own part).
std::unique_ptr<float[]> to_float(const std::vector<uint16_t>& bits) {
  static const bool f16c = __builtin_cpu_supports("f16c") && __builtin_cpu_supports("avx");
  std::unique_ptr<float[]> out(new float[bits.size()]);
  parallel_for(bits.size(), [&](std::size_t b, std::size_t e) {
    if (f16c)
      to_float_f16c(bits.data() + b, out.get() + b, e - b);
    else
      to_float_portable(bits.data() + b, out.get() + b, e - b);
  }, 1 << 16);
  return out;
}

}  // namespace

HalfImage to_half_image(const Image& img) {
  HalfImage h;
  h.width = img.width, h.height = img.height, h.channels = img.channels;
  h.bits = to_half(img.pixels);
  return h;
}

void write_exr(const std::string& path, const HalfImage& img, const std::vector<std::string>& channel_names,
               const ExrOptions& options, StagedFiles* staged) {
  if (img.width <= 0 || img.height <= 0 || img.channels <= 0 ||
      img.bits.size() != std::size_t(img.width) * img.height * img.channels)
    throw OutputError(path + ": cannot write an empty or inconsistent image");
  const OIIO::ImageSpec spec =
      exr_spec(path, img.width, img.height, img.channels, channel_names, ExrPixelType::Half, options.compression);
  if (options.layout == ExrLayout::TiledMipmap) {
    const std::unique_ptr<float[]> pixels = to_float(img.bits);
    write_atomically(path, [&](const std::string& tmp) { write_texture(path, tmp, spec, pixels.get(), options.content); },
                     staged);
    return;
  }
  write_atomically(path, [&](const std::string& tmp) {
    write_oiio(path, tmp, spec, OIIO::TypeDesc::HALF, img.bits.data());
  }, staged);
}

void write_exr(const std::string& path, const Image& img, const std::vector<std::string>& channel_names,
               const ExrOptions& options, StagedFiles* staged) {
  check_channels(path, img);
  // Half: converted first, whatever the layout (a texture's MIP levels are
  // then made from the half values level 0 holds, as from a HalfImage).
  if (options.type == ExrPixelType::Half) {
    write_exr(path, to_half_image(img), channel_names, options, staged);
    return;
  }
  const OIIO::ImageSpec spec =
      exr_spec(path, img.width, img.height, img.channels, channel_names, options.type, options.compression);
  write_atomically(path, [&](const std::string& tmp) {
    if (options.layout == ExrLayout::TiledMipmap)
      write_texture(path, tmp, spec, img.pixels.data(), options.content);
    else
      write_oiio(path, tmp, spec, OIIO::TypeDesc::FLOAT, img.pixels.data());
  }, staged);
}

void write_png(const std::string& path, const Image& img, bool to_srgb, int bits) {
  check_channels(path, img);
  if (bits != 8 && bits != 16) throw std::invalid_argument(path + ": write_png supports 8 or 16 bits");
  const int ch = img.channels;
  const int alpha = (ch == 2 || ch == 4) ? ch - 1 : -1;
  const float maxv = bits == 8 ? 255.f : 65535.f;
  std::vector<uint16_t> data(img.pixels.size());
  parallel_for(std::size_t(img.width) * img.height, [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p)
      for (int c = 0; c < ch; ++c) {
        float x = std::clamp(img.pixels[p * ch + c], 0.f, 1.f);
        if (to_srgb && c != alpha) x = linear_to_srgb(x);
        data[p * ch + c] = uint16_t(std::lround(x * maxv));
      }
  }, 4096);
  OIIO::ImageSpec spec(img.width, img.height, ch, bits == 8 ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::UINT16);
  spec.alpha_channel = alpha;
  // Our colour is not premultiplied: store it as is, as PNG expects.
  spec.attribute("oiio:UnassociatedAlpha", 1);
  spec.attribute("oiio:ColorSpace", to_srgb ? "sRGB" : "Linear");
  spec.attribute("Software", "lapflow");
  if (bits == 8) {
    std::vector<uint8_t> data8(data.begin(), data.end());
    write_atomically(path, [&](const std::string& tmp) {
      write_oiio(path, tmp, spec, OIIO::TypeDesc::UINT8, data8.data());
    });
  } else {
    write_atomically(path, [&](const std::string& tmp) {
      write_oiio(path, tmp, spec, OIIO::TypeDesc::UINT16, data.data());
    });
  }
}

}  // namespace lapflow
