// `lapflow feature-map`: a feature map F_m for an exemplar that has none.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>

#include "cli_common.hpp"
#include "lapflow/bake/budget.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/memory.hpp"
#include "lapflow/addons/feature_map.hpp"
#include "lapflow/io/image.hpp"

namespace lapflow::cli {
namespace {

struct FeatureMapCli {
  std::string input, output, method = "distance", compare;
  FeatureMapOptions o;
  bool eight_bit = false;
  std::size_t max_memory = 0;  ///< bytes; 0 = default_memory_budget()
};

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

// A reference map as one channel of the given size.
Image reference_map(const std::string& path, int width, int height) {
  Image ref = read_image(path, ColorSpace::Linear);
  if (ref.channels > 1) ref = luminance(ref);
  if (double(ref.width) * height != double(ref.height) * width)
    throw InputError(path, "aspect ratio differs from the input image's");
  if (ref.width != width || ref.height != height) ref = resize_image(ref, width, height);
  return ref;
}

void run_feature_map(FeatureMapCli& c) {
  apply_global_options();
  c.o.method = parse_feature_method(c.method);
  const std::string ext = lower_extension(c.output);
  if (ext != ".png" && ext != ".exr" && ext != ".tif" && ext != ".tiff")
    throw UsageError("-o " + c.output + ": the output must end in .png, .exr, .tif or .tiff");
  // The header against the budget before any pixel is decoded: the decoded
  // float image plus the method's working images (blurred copies, gradient,
  // distance grids in double, the output): 52 bytes a pixel in all on a
  // 4096² RGB input (docs/robustness.md), with margin.
  constexpr double kWorkBytesPerPixel = 64;
  const std::size_t budget = c.max_memory > 0 ? c.max_memory : default_memory_budget();
  const ImageHeader header = read_image_header(c.input);
  check_image_budget(c.input, header, 4.0 * header.channels + kWorkBytesPerPixel, budget);
  const Image color = read_image(c.input, ColorSpace::Auto, budget);
  const Image f = make_feature_map(color, c.o);

  if (ext == ".exr") {
    write_exr(c.output, f, {"Y"}, {ExrPixelType::Float, ExrCompression::Zip});
  } else {
    // write_png writes through OpenImageIO, which picks the format from the
    // extension: a .tif gets the same 8/16-bit linear grey data.
    write_png(c.output, f, false, c.eight_bit ? 8 : 16);
  }
  double mean = 0;
  for (float x : f.pixels) mean += x;
  mean /= double(f.pixels.size());
  info("lapflow feature-map: {} ({}x{}) -> {} [{}], mean {:.3f}", c.input, color.width, color.height, c.output,
       c.method, mean);
  if (!c.compare.empty()) {
    const double r = image_correlation(f, reference_map(c.compare, f.width, f.height));
    // Printed on stdout: the one result a script may want to read.
    fmt::print("correlation with {}: {:.3f}\n", c.compare, r);
  }
}

}  // namespace

void add_feature_map_command(CLI::App& app) {
  static FeatureMapCli c;
  CLI::App* cmd = app.add_subcommand("feature-map", "Make a feature map F_m for an exemplar that has none");
  cmd->description(
      "Make a feature map F_m for an exemplar that has none.\n\n"
      "The feature map tells erosion where to eat a distorted patch first: high values are the texture's\n"
      "elements (kept longest), low values their borders. Methods:\n"
      "  luminance  Rec. 709 luminance, stretched to [0,1]: bright elements on a dark ground\n"
      "             (use --invert for dark elements on a bright ground, or glowing cracks)\n"
      "  edges      1 - colour gradient strength (Sobel): low on every edge, high on flat areas\n"
      "  distance   distance to the nearest strong edge (Lefebvre & Hoppe 2006 feature distance):\n"
      "             0 on the edges, rising to 1 in the middle of each element (default; works for any\n"
      "             texture made of distinct elements)\n"
      "Reads any image OpenImageIO reads; writes .png (16-bit grey, linear), .exr (float Y) or .tif.\n"
      "Use the result with: lapflow bake --exemplar IMG --feature OUT ...");
  cmd->add_option("input", c.input, "Colour exemplar (PNG, JPEG, TIFF, EXR, ...)")->required();
  cmd->add_option("-o,--out", c.output, "Output feature map: .png, .exr, .tif or .tiff")->required();
  cmd->add_option("--method", c.method, "luminance, edges or distance")
      ->check(CLI::IsMember({"luminance", "edges", "distance"}))
      ->capture_default_str();
  cmd->add_option("--blur", c.o.blur_sigma, "Gaussian blur of the result, in pixels (softer erosion fronts)")
      ->check(CLI::Range(0.0, 256.0))
      ->capture_default_str();
  cmd->add_flag("--invert", c.o.invert, "Output 1 - F: when the texture's elements are dark or are the lines");
  cmd->add_option("--edge-sigma", c.o.edge_sigma, "Blur before the gradient, in pixels (edges, distance)")
      ->check(CLI::Range(0.0, 64.0))
      ->capture_default_str();
  cmd->add_option("--edge-threshold", c.o.edge_threshold,
                  "distance: gradient strength (share of its 99th percentile) that counts as an edge")
      ->check(CLI::Range(0.001, 1.0))
      ->capture_default_str();
  cmd->add_option("--distance-max", c.o.distance_max,
                  "distance: distance in pixels that maps to 1 (0 = the 99th percentile of the distances)")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  cmd->add_flag("--8bit", c.eight_bit, "Write 8-bit PNG/TIFF instead of 16-bit");
  cmd->add_option("--compare", c.compare,
                  "A reference feature map: print the correlation of the result with it (on stdout)");
  add_max_memory_option(*cmd, c.max_memory,
                        "An input whose header promises more pixels than fit (about 76 bytes a pixel for RGB) is refused "
                        "(exit 2) before it is decoded.");
  add_global_options(*cmd);
  cmd->callback([] { run_feature_map(c); });
}

}  // namespace lapflow::cli
