// `lapflow inspect`: what a user checks before a long bake. The library reads
// every frame (inspect_sequence, addons/inspect.hpp); this prints its
// topology problems and the velocity each frame would be advected with, then
// a one-screen summary or JSON.
#include <fmt/ranges.h>

#include <algorithm>
#include <exception>
#include <optional>

#include "cli_common.hpp"
#include "lapflow/addons/inspect.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow::cli {
namespace {

/// The command's options: the library's, and how to print.
struct InspectCommandOptions : InspectOptions {
  bool json = false;
};

/// "3, 7-9, 12"
std::string frame_list(const std::vector<int>& frames) {
  std::string s;
  for (std::size_t i = 0; i < frames.size();) {
    std::size_t j = i;
    while (j + 1 < frames.size() && frames[j + 1] == frames[j] + 1) ++j;
    if (!s.empty()) s += ", ";
    s += j == i ? std::to_string(frames[i]) : fmt::format("{}-{}", frames[i], frames[j]);
    i = j + 1;
  }
  return s;
}

std::string box_text(const Box3& b) {
  if (b.empty()) return "(empty)";
  if (!(std::max(norm(b.lo), norm(b.hi)) < 1e6))  // 3e38 in full is 39 digits
    return fmt::format("({:.3g}, {:.3g}, {:.3g}) - ({:.3g}, {:.3g}, {:.3g}) m", b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y,
                       b.hi.z);
  return fmt::format("({:.3f}, {:.3f}, {:.3f}) - ({:.3f}, {:.3f}, {:.3f}) m", b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y,
                     b.hi.z);
}

/// Totals over the readable frames (serial, in frame order).
void print_table(const std::vector<FrameInspection>& results, bool with_grid) {
  fmt::print("{:>6} {:>9} {:>9} {:>5} {:>7} {:>7} {:>6} {:>8}  {:<24} {:<10} {}\n", "frame", "triangles", "vertices",
             "comps", "nm-edge", "nm-vert", "degen", "boundary", "speed min/mean/max m/s", "source",
             with_grid ? "grid-vs-vertex  bounding box" : "bounding box");
  for (const FrameInspection& r : results) {
    if (r.error) {
      fmt::print("{:>6} unreadable: {}\n", r.frame, r.error_text);
      continue;
    }
    const MeshReport& m = r.report;
    const SpeedStats& sp = used_speed(r);
    const std::string speed = sp.present ? fmt::format("{:.3f} / {:.3f} / {:.3f}", sp.min, sp.mean, sp.max) : "-";
    std::string diff;
    if (with_grid) diff = r.grid_difference >= 0 ? fmt::format("{:>13.1f}%  ", 100 * r.grid_difference) : fmt::format("{:>14}  ", "-");
    fmt::print("{:>6} {:>9} {:>9} {:>5} {:>7} {:>7} {:>6} {:>8}  {:<24} {:<10} {}{}{}\n", r.frame, m.triangles,
               m.vertices, m.components, m.non_manifold_edges, m.non_manifold_vertices, m.degenerate_triangles,
               m.boundary_edges, speed, r.grid_speed.present ? "vdb" : (r.vertex_speed.present ? "vertex" : "none"),
               diff, box_text(m.bounds), m.triangles == 0 ? "  EMPTY" : "");
  }
}

void print_summary(const InspectCommandOptions& o, const std::vector<FrameInspection>& results, const InspectSummary& s) {
  const int first = results.front().frame, last = results.back().frame;
  fmt::print("\nSummary of {}\n", o.mesh_pattern);
  fmt::print("  frames            {} ({}-{}), {} readable\n", results.size(), first, last, s.readable);
  if (!s.unreadable.empty()) fmt::print("  UNREADABLE        frames {} (see the errors)\n", frame_list(s.unreadable));
  fmt::print("  triangles         min {} (frame {}), mean {:.0f}, max {} (frame {})\n", s.tri_min, s.tri_min_frame,
             s.tri_mean, s.tri_max, s.tri_max_frame);
  fmt::print("  empty frames      {}\n", s.empty.empty() ? "none" : frame_list(s.empty) + " (legal: nothing to texture)");
  fmt::print("  non-manifold      {} edges, {} vertices{}\n", s.non_manifold_edges, s.non_manifold_vertices,
             s.frames_with_non_manifold.empty() ? "" : " in frames " + frame_list(s.frames_with_non_manifold));
  fmt::print("  boundary edges    {}{}\n", s.boundary,
             s.frames_with_boundary.empty() ? " (all surfaces closed)" : " in frames " + frame_list(s.frames_with_boundary));
  fmt::print("  degenerate tris   {} (legal)\n", s.degenerate);
  fmt::print("  isolated vertices {}\n", s.isolated);
  fmt::print("  bounding box      {}\n", box_text(s.bounds));
  const bool any_grid = std::any_of(results.begin(), results.end(), [](const FrameInspection& r) { return r.grid_speed.present; });
  const bool any_vertex = std::any_of(results.begin(), results.end(), [](const FrameInspection& r) { return r.vertex_speed.present; });
  std::string source = "none";
  if (any_grid) source = fmt::format("OpenVDB grid '{}' ({})", results.front().grid_name, o.vdb_pattern);
  else if (any_vertex) source = "per-vertex PLY properties";
  fmt::print("  velocity source   {}{}\n", source,
             o.min_speed > 0 ? fmt::format(", speeds below {} m/s treated as 0", o.min_speed) : "");
  if (any_grid || any_vertex) fmt::print("  peak speed        {:.3f} m/s (frame {})\n", s.peak_speed, s.peak_frame);
  if (!s.frames_without_velocity.empty())
    fmt::print("  NO VELOCITY       frames {}: a bake needs --allow-zero-velocity or --velocity-vdb\n",
               frame_list(s.frames_without_velocity));
  fmt::print("  rule attributes   speed, curvature{}{} (docs/layers.md)\n", s.attributes.empty() ? "" : ", ",
             fmt::format("{}", fmt::join(s.attributes, ", ")));
  if (s.mean_difference >= 0)
    fmt::print("  grid vs vertex    {:.1f}% mean relative difference (worst frame {}: {:.1f}%)\n",
               100 * s.mean_difference, s.worst_difference_frame, 100 * s.worst_difference);
  fmt::print("  units             {}\n",
             s.frames_with_warnings.empty()
                 ? std::string("no size, speed or property type a liquid in metres could not have")
                 : "WARNING in frames " + frame_list(s.frames_with_warnings) +
                       " (see the warnings): a bake refuses them unless --units-ok");
}

/// The units warnings on stderr, the first frames' in full: a sequence whose
/// every frame is in millimetres must not bury the summary.
void print_warnings(const std::vector<FrameInspection>& results) {
  constexpr std::size_t kFramesShown = 5;
  std::size_t shown = 0, more = 0;
  for (const FrameInspection& r : results) {
    if (r.warnings.empty()) continue;
    if (shown == kFramesShown) {
      ++more;
      continue;
    }
    ++shown;
    for (const std::string& w : r.warnings) warn("{}", inspection_warning(r, w));
  }
  if (more > 0) warn("{} more frames have such warnings (--json lists them all)", more);
}

void run_inspect(const InspectCommandOptions& o) {
  apply_global_options();
  std::optional<Progress> progress;
  const std::vector<FrameInspection> results = inspect_sequence(o, [&](int frame, std::size_t total) {
    if (!progress) progress.emplace("inspect", total);
    progress->step(fmt::format("frame {}", frame));
  });
  if (progress) progress->finish();
  const bool with_grid = !o.vdb_pattern.empty();

  const InspectSummary s = summarize(results);
  if (o.json) {
    fmt::print("{}\n", inspection_json(o, results, s));
  } else {
    print_table(results, with_grid);
    print_summary(o, results, s);
  }
  // Warnings do not change the exit code: inspect reports, the bake refuses.
  print_warnings(results);
  // Exit code 2 when any frame is unreadable: print every error, in frame
  // order; main prints the last one as it propagates.
  std::vector<const FrameInspection*> bad;
  for (const FrameInspection& r : results)
    if (r.error) bad.push_back(&r);
  for (std::size_t i = 0; i + 1 < bad.size(); ++i) print_error(bad[i]->error_text);
  if (!bad.empty()) std::rethrow_exception(bad.back()->error);
}

}  // namespace

void add_inspect_command(CLI::App& app) {
  static InspectCommandOptions o;
  auto* cmd = app.add_subcommand("inspect", "Check a fluid mesh sequence (and its velocities) before a bake");
  cmd->description(
      "Reads every frame of a liquid surface sequence and reports, per frame: triangles, vertices, connected\n"
      "components, non-manifold edges and vertices, boundary edges, degenerate triangles, the bounding box, and\n"
      "the velocity (min / mean / max speed over the surface) with where it comes from. Then a one-screen\n"
      "summary: frame range, triangle counts, totals of problems, empty frames, overall bounding box, peak speed.\n"
      "It warns about frames no liquid in metres has (see UNITS below), which a bake refuses. Run it before a\n"
      "long bake. Nothing is written.");
  cmd->add_option("mesh", o.mesh_pattern,
                  "Mesh sequence pattern: name.%04d.ply, name.%d.ply, name.####.ply (one # per digit), "
                  "name.$F4.ply, name.$F.ply; or one file")
      ->required();
  cmd->add_option("--frames", o.frames, "Frame range A-B (or one frame A); every frame in it must exist. "
                                        "Default: all frames found on disk");
  cmd->add_option("--velocity-vdb", o.vdb_pattern,
                  "OpenVDB velocity sequence (same pattern forms); sampled trilinearly at the vertices and "
                  "compared with the vertex velocities when the mesh has them");
  cmd->add_option("--velocity-grid", o.grid_name, "Vector grid to read from the VDB files (default: tries vel, v, velocity)");
  cmd->add_option("--min-speed", o.min_speed, "Speeds below S (m/s) count as 0, as in the bake")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--json", o.json, "Print one JSON document (per-frame reports and the summary) instead of the table");
  add_global_options(*cmd);
  cmd->footer(
      "UNITS\n"
      "  A warning (on stderr, 'warning: FILE (frame N): ...', and in the JSON's 'warnings' lists) for\n"
      "  " + units_thresholds_text() + ":\n"
      "  a mesh in millimetres, a corrupt file or a float written as an integer. The exit code stays 0;\n"
      "  `lapflow bake` refuses such a frame (exit 2) unless --units-ok, and coordinates beyond " +
      fmt::format("{:g} km", kMaxMeshCoordinate / 1000) + "\n"
      "  even with it.\n"
      "\n"
      "INPUT FORMATS\n"
      "  PLY (binary little or big endian, ASCII) and OBJ, one file per frame. Polygons are split into\n"
      "  triangles. Velocity per vertex from PLY properties vx vy vz, velocity_x/_y/_z or v_x/_y/_z (float or\n"
      "  double). Non-manifold geometry, degenerate triangles, isolated vertices, many components and empty\n"
      "  frames are legal and reported. OpenVDB velocity: a Vec3S or Vec3D grid, world-space transform.\n"
      "\n"
      "OUTPUT\n"
      "  A table (one line per frame) and a summary on stdout; with --json one JSON document\n"
      "  {mesh_pattern, velocity_vdb, frames: [...], summary: {...}} instead. Progress goes to stderr.\n"
      "  'grid-vs-vertex' is sum|v_vdb - v_vertex| / sum|v_vertex| over the frame's vertices.\n"
      "\n"
      "EXIT CODES\n"
      "  0  every frame was read (empty frames and frames with warnings included)\n"
      "  2  bad input or usage: a missing frame in --frames, a malformed file (one line per file naming\n"
      "     the frame, the element and what is wrong), a VDB without the grid; all frames are still reported\n"
      "  1  internal error\n"
      "\n"
      "EXAMPLES\n"
      "  lapflow inspect sim/fluid.%04d.ply\n"
      "  lapflow inspect sim/fluid.####.ply --frames 1-100 --velocity-vdb sim/fluid.####.vdb --json > report.json");
  cmd->callback([] { run_inspect(o); });
}

}  // namespace lapflow::cli
