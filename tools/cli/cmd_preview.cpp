// `lapflow preview`: ray-traced pictures (and an MP4) of baked frames, one
// bake or several side by side.
#include <ctime>
#include <filesystem>
#include <sstream>

#include "cli_common.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/addons/preview.hpp"

namespace lapflow::cli {
namespace {
namespace fs = std::filesystem;

struct PreviewCli {
  std::string dir, frames, out, camera, up = "z", show = "color";
  std::vector<std::string> compare, labels;
  bool turntable = false, no_video = false, no_labels = false, no_ground = false;
  int width = 0, height = 0, samples = 4, views = 48;
  double azimuth = -35, elevation = 28, fov = 30, bump = 0.05, fps = 0;
};

std::vector<double> parse_numbers(const std::string& text, const std::string& option) {
  std::vector<double> v;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    try {
      std::size_t used = 0;
      v.push_back(std::stod(item, &used));
      if (used != item.size()) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      throw UsageError(option + " '" + text + "': '" + item + "' is not a number");
    }
  }
  return v;
}

std::string frame_digits(int n) { return fmt::format("{:04d}", n); }

void run_preview(PreviewCli& c) {
  apply_global_options();
  std::vector<BakeManifest> bakes{read_bake_manifest(c.dir)};
  for (const std::string& d : c.compare) bakes.push_back(read_bake_manifest(d));
  const bool comparing = bakes.size() > 1;
  const BakeManifest& main = bakes.front();

  std::optional<FrameRange> range;
  if (!c.frames.empty()) range = parse_frame_range(c.frames);
  std::vector<int> missing;
  const std::vector<int> frames = preview_frames(main, range, &missing);
  if (!missing.empty())
    warn("{}: {} of the bake's frames are not on disk (first: {}); previewing the {} that are", main.dir,
         missing.size(), missing.front(), frames.size());
  require_compared_frames(bakes, frames);

  PreviewOptions o;
  o.width = c.width > 0 ? c.width : (comparing ? 640 : 1280);
  o.height = c.height > 0 ? c.height : (comparing ? 480 : 720);
  o.samples = c.samples;
  const std::optional<Vec3> up = parse_up_axis(c.up);
  if (!up) throw UsageError("--up '" + c.up + "': expected x, y, z, -x, -y, -z or a vector X,Y,Z");
  o.look.up = *up;
  o.look.bump = c.bump;
  o.look.ground = !c.no_ground;
  const PreviewShow show = *parse_preview_show(c.show);  // CLI::IsMember checked it

  // One camera for the whole sequence: the bounding box of every frame of every bake.
  info("lapflow preview: {} frame{} of {} ({}){}", frames.size(), frames.size() == 1 ? "" : "s", main.name,
       main.dir, comparing ? fmt::format(", {} bakes side by side", bakes.size()) : "");
  const PreviewExtent extent = preview_extent(bakes, frames);
  const Box3& bounds = extent.box;
  const double aspect = double(o.width) / o.height;
  std::optional<PreviewCamera> fixed;
  if (!c.camera.empty()) {
    const std::vector<double> v = parse_numbers(c.camera, "--camera");
    if (v.size() != 6 && v.size() != 7)
      throw UsageError("--camera '" + c.camera + "': expected EX,EY,EZ,TX,TY,TZ[,FOV]");
    PreviewCamera cam;
    cam.eye = {v[0], v[1], v[2]};
    cam.target = {v[3], v[4], v[5]};
    cam.fov = v.size() == 7 ? v[6] : c.fov;
    cam.up = o.look.up;
    if (norm(cam.target - cam.eye) == 0) throw UsageError("--camera: the eye and the target are the same point");
    fixed = cam;
  }

  // Turntable over one frame: N views of it; otherwise one picture per frame.
  const bool spin_one = c.turntable && frames.size() == 1;
  const int pictures = spin_one ? c.views : int(frames.size());
  const std::string kind = spin_one ? "turntable" : (comparing ? "compare" : "preview");

  PreviewFraming framing;
  framing.fixed = fixed;
  framing.turntable = c.turntable;
  framing.azimuth = c.azimuth, framing.elevation = c.elevation, framing.fov = c.fov;
  framing.up = o.look.up;
  framing.aspect = aspect;
  const std::vector<PreviewCamera> cameras = preview_cameras(extent.points, framing, pictures);
  const std::string out_dir = c.out.empty() ? (fs::path(main.dir) / "preview").string() : c.out;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw OutputError(out_dir + ": cannot create the output folder: " + ec.message());

  const std::vector<std::string> labels = c.labels.empty() ? panel_labels(bakes) : c.labels;
  if (comparing && labels.size() != bakes.size())
    throw UsageError("--labels: " + std::to_string(labels.size()) + " labels for " + std::to_string(bakes.size()) +
                     " bakes");
  const std::string font = default_label_font();
  const int label_size = std::max(12, o.height / 22);
  bool font_warned = false;
  auto label = [&](Image& img, int x, int y, const std::string& text, bool right) {
    if (c.no_labels || font_warned) return;
    if (!draw_label(img, x, y, text, label_size, font, right)) {
      warn("cannot load the label font {} (Debian package fonts-dejavu-core, or set LAPFLOW_FONT): pictures "
           "without labels", font);
      font_warned = true;
    }
  };

  info("  {}x{}{} | {} samples/pixel | {} threads | into {}", o.width, o.height,
       comparing ? fmt::format(" per panel ({} wide)", bakes.size() * o.width) : "", o.samples, thread_count_label(),
       out_dir);
  Progress progress(kind, std::size_t(pictures));
  std::vector<std::string> written;
  std::vector<PreviewFrame> loaded;  // the single turntable frame, loaded once
  double seconds = 0;
  for (int i = 0; i < pictures; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const int frame = spin_one ? frames.front() : frames[std::size_t(i)];
    const PreviewCamera& cam = cameras[std::size_t(i)];
    if (loaded.empty() || !spin_one) {
      loaded.clear();
      for (const BakeManifest& b : bakes) loaded.push_back(load_preview_frame(b, frame, show));
    }
    const auto loaded_at = std::chrono::steady_clock::now();
    const std::clock_t cpu_start = std::clock();  // process CPU time, all threads
    std::vector<Image> panels;
    for (std::size_t b = 0; b < bakes.size(); ++b) {
      panels.push_back(render_preview(loaded[b], cam, bounds, o));
      if (comparing) label(panels.back(), label_size / 2, label_size / 2, labels[b], false);
      if (show == PreviewShow::Layers && !c.no_labels && !font_warned) {
        std::vector<std::string> names;
        for (const ExemplarLayer& l : bakes[b].options.layers) names.push_back(l.name);
        draw_layer_legend(panels.back(), names, label_size, font);  // a missing font: label() warns below
      }
    }
    const auto rendered_at = std::chrono::steady_clock::now();
    const double render_cpu = double(std::clock() - cpu_start) / CLOCKS_PER_SEC;
    Image picture = comparing ? side_by_side(panels, 2) : std::move(panels.front());
    label(picture, picture.width - label_size / 2, label_size / 2,
          spin_one ? fmt::format("frame {}  view {}/{}", frame, i + 1, pictures) : fmt::format("frame {}", frame),
          true);
    const std::string path =
        (fs::path(out_dir) / (main.name + "." + kind + "." + frame_digits(spin_one ? i + 1 : frame) + ".png")).string();
    write_png(path, picture, true);
    written.push_back(path);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    seconds += s;
    std::size_t triangles = 0;
    for (const PreviewFrame& p : loaded) triangles += p.mesh.mesh.triangle_count();
    progress.step(fmt::format("{}: {} triangles, read {:.2f} s, render {:.2f} s ({:.2f} cpu-s), total {:.2f} s",
                              fs::path(path).filename().string(), triangles,
                              std::chrono::duration<double>(loaded_at - start).count(),
                              std::chrono::duration<double>(rendered_at - loaded_at).count(), render_cpu, s));
  }
  progress.finish();
  info("done: {} picture{} in {:.1f} s ({:.2f} s each) in {}", pictures, pictures == 1 ? "" : "s", seconds,
       seconds / pictures, out_dir);

  if (c.no_video || pictures < 2) return;
  if (!ffmpeg_available()) {
    warn("no ffmpeg on PATH (Debian package ffmpeg): pictures only, no MP4");
    return;
  }
  const std::string mp4 = (fs::path(out_dir) / (main.name + "." + kind + ".mp4")).string();
  encode_video(written, mp4, c.fps > 0 ? c.fps : (main.options.fps > 0 ? main.options.fps : 24));
  info("video: {}", mp4);
}

}  // namespace

void preview_bake(const std::string& dir, int width, int height) {
  PreviewCli c;
  c.dir = dir;
  c.width = width;
  c.height = height;
  run_preview(c);
}

void add_preview_command(CLI::App& app) {
  static PreviewCli c;
  CLI::App* cmd = app.add_subcommand("preview", "Ray-traced pictures (and an MP4) of baked frames");
  cmd->description(
      "Ray-traced pictures (and an MP4) of baked frames: the first look at a bake.\n\n"
      "Reads DIR's NAME.bake.json and, per frame, NAME.N.obj, NAME.color.N.exr and NAME.disp.N.exr, and renders\n"
      "the liquid with Embree: colour atlas (mip-mapped), displacement atlas as bump, a key light with soft\n"
      "ray-traced shadows, a sky fill, a little specular and Fresnel sky reflection, smooth shading, a ground\n"
      "plane under the sequence, jittered antialiasing. The camera is framed once, from the vertices of every\n"
      "frame (a 3/4 elevated view), so the picture does not jitter. Writes, in --out:\n"
      "  NAME.preview.N.png       one per frame (NAME.compare.N.png with --compare)\n"
      "  NAME.preview.mp4         H.264 of those, when ffmpeg is on PATH (Debian package ffmpeg)\n"
      "  NAME.turntable.V.png     --turntable of a single frame: V = 1..--views around it\n"
      "--compare puts other bakes of the same sequence beside DIR's, each panel labelled with its mode\n"
      "(erosion, blend, advect) or its folder name. --show layers tints the liquid by each texel's exemplar\n"
      "layer (the layer channel of NAME.aov.N.exr: a bake with --layer and --aov), one colour per layer over\n"
      "the texture's luminance, with a legend. Every file is written atomically. Pictures do not depend\n"
      "on --threads.\n\n"
      "Exit codes: 0 ok, 2 bad input or usage (the message names the file), 1 internal error.");
  cmd->add_option("dir", c.dir, "Bake folder (holding NAME.bake.json)")->required();
  cmd->add_option("--frames", c.frames, "Frame range A-B or one frame A (default: every baked frame on disk)");
  cmd->add_option("--out", c.out, "Output folder (default: DIR/preview)");
  cmd->add_option("--compare", c.compare, "Other bakes of the same frames, side by side (DIR's panel first)")
      ->expected(1, -1);
  cmd->add_option("--labels", c.labels, "Panel labels, comma-separated (default: the modes, or the folder names)")
      ->delimiter(',');
  cmd->add_flag("--turntable", c.turntable,
                "The camera orbits the scene once over the frames (or over --views views of a single frame)");
  cmd->add_option("--views", c.views, "Views of a single-frame turntable")->check(CLI::Range(2, 3600))
      ->capture_default_str();
  cmd->add_option("--width", c.width, "Picture (panel) width in pixels (default 1280, 640 per panel with --compare)")
      ->check(CLI::Range(16, 16384));
  cmd->add_option("--height", c.height, "Picture height in pixels (default 720, 480 with --compare)")
      ->check(CLI::Range(16, 16384));
  cmd->add_option("--samples", c.samples, "Jittered samples per pixel (4, 9, 16: stratified)")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();
  cmd->add_option("--camera", c.camera, "Camera EX,EY,EZ,TX,TY,TZ[,FOV]: eye, target, vertical field of view (deg)");
  cmd->add_option("--azimuth", c.azimuth, "Automatic camera: degrees about the up axis (0 = from -Y for Z-up)")
      ->capture_default_str();
  cmd->add_option("--elevation", c.elevation, "Automatic camera: degrees above the horizon")->capture_default_str();
  cmd->add_option("--fov", c.fov, "Vertical field of view, degrees")->check(CLI::Range(1.0, 170.0))
      ->capture_default_str();
  cmd->add_option("--up", c.up, "World up axis: z (Blender, Mantaflow), y (Houdini, Maya), -z, x, ... or X,Y,Z")
      ->capture_default_str();
  cmd->add_option("--bump", c.bump, "Bump height: displacement 1 = BUMP x the bake's radius; 0 = no bump")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  cmd->add_option("--show", c.show,
                  "What the liquid shows: color (the colour atlas) or layers (each exemplar layer in its own colour "
                  "over the texture's luminance, with a legend; needs a bake with --layer and --aov)")
      ->check(CLI::IsMember({"color", "layers"}))
      ->capture_default_str();
  cmd->add_flag("--no-ground", c.no_ground, "No ground plane (sky gradient all around)");
  cmd->add_flag("--no-labels", c.no_labels, "No text on the pictures");
  cmd->add_flag("--no-video", c.no_video, "Do not write the MP4");
  cmd->add_option("--fps", c.fps, "Video frame rate (default: the bake's)")->check(CLI::PositiveNumber);
  add_global_options(*cmd);
  cmd->callback([] { run_preview(c); });
}

}  // namespace lapflow::cli
