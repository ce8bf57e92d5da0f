// Text labels on preview pictures: OpenImageIO's render_text (FreeType) with a
// TrueType font, drawn straight into the linear float picture.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>

#include "lapflow/addons/preview.hpp"

namespace lapflow {

std::string default_label_font() {
  if (const char* env = std::getenv("LAPFLOW_FONT"); env && *env) return env;
  return "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
}

bool draw_label(Image& img, int x, int y, const std::string& text, int size, const std::string& font_path,
                bool align_right) {
  namespace OIIO = OIIO_NAMESPACE;
  if (img.empty() || img.channels < 3 || text.empty()) return false;
  std::error_code ec;
  // OIIO would fall back to some other font for a missing path: refuse instead.
  if (!std::filesystem::is_regular_file(font_path, ec)) return false;
  const OIIO::ROI extent = OIIO::ImageBufAlgo::text_size(text, size, font_path);
  if (!extent.defined()) {
    (void)OIIO::geterror();
    return false;
  }
  // The box: the text's extent (relative to its baseline origin) plus a margin.
  const int pad = std::max(2, size / 4);
  const int box_w = extent.width() + 2 * pad, box_h = size + 2 * pad;
  const int bx0 = align_right ? x - box_w : x, by0 = y;
  for (int py = std::max(0, by0); py < std::min(img.height, by0 + box_h); ++py)
    for (int px = std::max(0, bx0); px < std::min(img.width, bx0 + box_w); ++px)
      for (int c = 0; c < 3; ++c) img.at(px, py, c) *= 0.3f;

  OIIO::ImageSpec spec(img.width, img.height, img.channels, OIIO::TypeDesc::FLOAT);
  OIIO::ImageBuf buf(spec, img.pixels.data());
  std::vector<float> white(std::size_t(img.channels), 1.f);
  // Baseline at the box's top + pad + the font's ascent (about 0.8 of its size).
  const int baseline = by0 + pad + int(std::lround(0.8 * size));
  const bool ok = OIIO::ImageBufAlgo::render_text(buf, bx0 + pad - extent.xbegin, baseline, text, size, font_path,
                                                   white);
  if (!ok) (void)buf.geterror();
  return ok;
}

bool draw_layer_legend(Image& img, const std::vector<std::string>& names, int size, const std::string& font_path) {
  if (img.empty() || img.channels < 3 || names.empty()) return false;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(font_path, ec)) return false;
  // Lines as tall as draw_label's box, a swatch as wide, from the bottom-left corner.
  const int pad = std::max(2, size / 4), line = size + 2 * pad, gap = std::max(2, size / 4), margin = size / 2;
  const int n = int(names.size());
  for (int i = 0; i < n; ++i) {
    const int y = img.height - margin - (n - i) * line - (n - i - 1) * gap;
    if (!draw_label(img, margin + line + gap, y, names[std::size_t(i)], size, font_path)) return false;
    const Vec3 c = preview_layer_color(i);
    for (int py = std::max(0, y); py < std::min(img.height, y + line); ++py)
      for (int px = std::max(0, margin); px < std::min(img.width, margin + line); ++px) {
        // A dark rim of one pixel keeps light swatches apart from a light ground.
        const bool rim = py == y || px == margin || py == y + line - 1 || px == margin + line - 1;
        for (int k = 0; k < 3; ++k) img.at(px, py, k) = rim ? 0.02f : float(c[k]);
      }
  }
  return true;
}

}  // namespace lapflow
