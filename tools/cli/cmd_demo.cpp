// `lapflow demo`: writes the built-in demo scene as a PLY sequence with
// velocities, so a first run needs no data. Generation lives in the library
// (write_demo_sequence) so that a bake of the demo reuses it.
#include <cmath>
#include <filesystem>

#include "cli_common.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow::cli {
namespace {

struct DemoCommandOptions {
  std::string out;
  std::string name = "demo";
  std::string scene = "vortex";
  int frames = 0;  ///< 0 = one period: round(T * fps) + 1
  double resolution = 128;
  double triangles = 0;
  double fps = 24;
  double period = 2;
  bool bake = true;
  bool preview = true;
  std::string exemplar = "pebbles";
  int atlas_resolution = 2048;
  double radius = 0.03;
};

DemoOptions to_demo_options(const DemoCommandOptions& o) {
  DemoOptions d;
  if (o.scene == "vortex")
    d.scene = DemoCase::Vortex;
  else if (o.scene == "slab")
    d.scene = DemoCase::Slab;
  else
    throw UsageError("--case must be 'vortex' or 'slab', not '" + o.scene + "'");
  d.frames = o.frames > 0 ? o.frames : int(std::lround(o.period * o.fps)) + 1;
  d.fps = o.fps;
  d.period = o.period;
  d.voxel_size = o.triangles > 0 ? demo_voxel_size_for(d.scene, o.triangles) : 1.0 / o.resolution;
  return d;
}

void run_demo(const DemoCommandOptions& o) {
  apply_global_options();
  const DemoOptions d = to_demo_options(o);
  info("demo '{}': {} frames at {} fps (t = 0 .. {:.3f} s, period T = {} s), voxel {:.4g} m ({} across 1 m), "
       "threads {}",
       o.scene, d.frames, d.fps, (d.frames - 1) / d.fps, d.period, d.voxel_size, std::lround(1.0 / d.voxel_size),
       thread_count_label());
  Progress progress("demo", std::size_t(d.frames));
  const DemoSequenceStats s = write_demo_sequence(d, o.out, o.name, [&](int f, const TriMesh& m) {
    progress.step(fmt::format("frame {}: {} triangles", f, m.triangle_count()));
  });
  progress.finish();
  info("wrote {} frames: {}", s.frames, (std::filesystem::path(o.out) / (o.name + ".%04d.ply")).string());
  info("triangles per frame: min {}, mean {:.0f}, max {}; {:.1f} s ({:.2f} s per frame)", s.triangles_min,
       s.triangles_mean, s.triangles_max, s.seconds, s.seconds / s.frames);
  if (!o.bake) return;
  // The main job: bake the sequence just written, as `lapflow bake` would.
  BakeOptions b;
  b.mesh_pattern = (std::filesystem::path(o.out) / (o.name + ".%04d.ply")).string();
  b.exemplar_color = o.exemplar;
  resolve_exemplar_paths(b.exemplar_color, b.exemplar_feature, b.exemplar_displacement);
  b.out_dir = (std::filesystem::path(o.out) / "bake").string();
  b.name = o.name;
  b.fps = o.fps;
  b.seed = globals().seed;
  b.patch.radius = o.radius;
  b.atlas.resolution = o.atlas_resolution;
  // The demo has no --resume: its states (every patch in full, every frame)
  // would only fill the disk.
  b.keep_states = 0;
  bake_with_progress(b);
  if (!o.preview) return;
  // What a user looks at first: a picture of every baked frame (and an MP4
  // when ffmpeg is installed) in OUT/bake/preview/.
  preview_bake(b.out_dir, 960, 540);
}

}  // namespace

void add_demo_command(CLI::App& app) {
  static DemoCommandOptions o;
  auto* cmd = app.add_subcommand("demo", "Write the built-in demo scene (a liquid-like sequence with velocities) and bake it");
  cmd->description(
      "Writes a liquid-like surface sequence that needs no input data, re-meshed from its level set every frame\n"
      "(a new mesh each frame, like a real simulation), with exact per-vertex velocities.\n"
      "\n"
      "  vortex  A ball of radius 0.15 m at (0.35, 0.35, 0.35) in a 1 m box, stretched into a thin swirling\n"
      "          sheet by the 3D single-vortex deformation field of Enright, Fedkiw, Ferziger and Mitchell\n"
      "          (2002), LeVeque's test: u = 2 sin^2(pi x) sin(2pi y) sin(2pi z) cos(pi t/T),\n"
      "          v = -sin(2pi x) sin^2(pi y) sin(2pi z) cos(pi t/T), w = -sin(2pi x) sin(2pi y) sin^2(pi z) cos(pi t/T).\n"
      "          The field reverses at t = T/2 and the ball is back at t = T.\n"
      "  slab    A 4 cm thin disk (radius 0.15 m at (0.5, 0.75), z = 0.5) in LeVeque's 2D single vortex, the\n"
      "          (x, y) swirl u = 3 sin^2(pi x) sin(2pi y) cos(pi t/T), v = -3 sin(2pi x) sin^2(pi y) cos(pi t/T),\n"
      "          w = 0: its top face winds into a spiral whose thin tail splits off and merges back as the\n"
      "          field reverses; back to the disk at t = T. Like the paper's 2D example.\n"
      "\n"
      "The surface at time t is exact up to the voxel: a point is liquid when the flow, traced back to t = 0\n"
      "(RK4), lands inside the start shape. Frame f is at t = (f - 1) / fps.");
  cmd->add_option("--out", o.out, "Output folder (created when missing)")->required();
  cmd->add_option("--frames", o.frames,
                  "Number of frames. Default: one period, round(T * fps) + 1 (49), so the last frame is at t = T, "
                  "the start shape again")
      ->check(CLI::Range(1, 100000));
  cmd->add_option("--resolution", o.resolution,
                  "Level-set voxels across the 1 m box. 128 gives 14k-33k triangles per vortex frame (6k-12k "
                  "slab); triangles grow with its square: 350 passes 100k on every vortex frame")
      ->check(CLI::Range(8.0, 2048.0))
      ->capture_default_str();
  cmd->add_option("--triangles", o.triangles,
                  "Pick the resolution for about N triangles at frame 1 instead (mid-period vortex frames "
                  "have up to 2.4x more)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--case", o.scene, "Scene: vortex or slab")
      ->check(CLI::IsMember({"vortex", "slab"}))
      ->capture_default_str();
  cmd->add_option("--name", o.name, "File name prefix: OUT/NAME.0001.ply, ...")->capture_default_str();
  cmd->add_option("--fps", o.fps, "Frames per second; dt = 1/fps")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--period", o.period, "Period T of the field in seconds (the shape returns at t = T; a longer T "
                                        "deforms more)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("!--no-bake", o.bake, "Only write the PLY sequence; do not bake it");
  cmd->add_flag("!--no-preview", o.preview,
                "Do not render the baked frames (by default: 960x540 PNGs and an MP4 in OUT/bake/preview/)");
  cmd->add_option("--exemplar", o.exemplar, "Exemplar for the bake: a shipped name or NAME.color.png")
      ->capture_default_str();
  cmd->add_option("--atlas-resolution", o.atlas_resolution, "Atlas width = height of the bake, in texels")
      ->check(CLI::Range(64, 16384))
      ->capture_default_str();
  cmd->add_option("--radius", o.radius, "Patch radius r of the bake in metres (0 = about 1500 patches)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  add_global_options(*cmd);
  cmd->footer(
      "OUTPUT\n"
      "  OUT/NAME.%04d.ply, frames 1..N: binary little-endian PLY, float x y z vx vy vz (metres, m/s), faces as\n"
      "  uchar/int lists, counter-clockwise seen from outside. Each file is written to a temporary name and\n"
      "  renamed. A summary (frames, triangles min/mean/max, seconds) goes to stderr.\n"
      "  Then, unless --no-bake, the sequence is baked into OUT/bake/ exactly as 'lapflow bake' does (see its\n"
      "  help for the files): NAME.N.obj/.mtl, NAME.color.N.exr, NAME.disp.N.exr, NAME.stats.jsonl.\n"
      "\n"
      "EXIT CODES\n"
      "  0 ok, 2 bad usage, 1 internal or write error\n"
      "\n"
      "EXAMPLES\n"
      "  lapflow demo --out demo_seq\n"
      "  lapflow inspect demo_seq/demo.%04d.ply\n"
      "  lapflow demo --out bench --triangles 100000 --frames 10   # benchmark size\n"
      "  lapflow demo --out slab --case slab --name slab");
  cmd->callback([] { run_demo(o); });
}

}  // namespace lapflow::cli
