// `lapflow atlas <mesh>`: the surface atlas of one mesh on its own (charts,
// LSCM, packing), written as OBJ + MTL, with its quality figures.
#include <nlohmann/json.hpp>

#include <chrono>
#include <filesystem>
#include <memory>

#include "cli_common.hpp"
#include "lapflow/atlas/atlas.hpp"
#include "lapflow/bake/budget.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/memory.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/uv_mesh.hpp"

namespace lapflow::cli {
namespace {

struct AtlasCommand {
  std::string mesh, out, texels_png;
  AtlasOptions atlas;
  std::size_t max_memory = 0;  ///< bytes; 0 = default_memory_budget()
  bool report = false, json = false, checker = false;
};

/// A checker in atlas space (cells of 32 texels at the atlas resolution) so
/// that even squares on the surface show an even texel density.
Image checker_image(int resolution) {
  const int size = std::min(resolution, 2048);
  const int cells = std::max(1, resolution / 32);
  Image img(size, size, 3);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const int cx = x * cells / size, cy = y * cells / size;
      const bool odd = (cx + cy) % 2;
      img.at(x, y, 0) = odd ? 0.9f : 0.15f;
      img.at(x, y, 1) = odd ? 0.9f : 0.3f;
      img.at(x, y, 2) = odd ? 0.9f : 0.6f;
    }
  return img;
}

/// Chart texels coloured by chart id (black elsewhere): a look at the packing.
Image texel_image(const TriMesh& mesh, const SurfaceAtlas& atlas) {
  const int n = atlas.resolution;
  Image img(n, n, 3);
  for (std::size_t i = 0; i < atlas.texels.size(); ++i) {
    const uint64_t h = hash64(uint64_t(atlas.chart_of_triangle[atlas.texels.triangle[i]]), 7);
    const uint32_t texel = atlas.texels.texel[i];
    for (int c = 0; c < 3; ++c) img.at(int(texel % n), int(texel / n), c) = 0.25f + 0.75f * float((h >> (8 * c)) & 255) / 255.f;
  }
  return img;
}

void run(const AtlasCommand& o) {
  apply_global_options();
  const auto start = std::chrono::steady_clock::now();
  const TriMesh mesh = read_mesh(o.mesh);
  const double read_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // Before the texel map exists: a resolution whose buffers do not fit is
  // refused, never an allocation that fails half-way.
  const std::size_t budget = o.max_memory > 0 ? o.max_memory : default_memory_budget();
  const double needed = estimate_atlas_memory(mesh.triangle_count(), o.atlas.resolution, !o.texels_png.empty());
  if (needed > double(budget))
    throw UsageError(fmt::format("--resolution {}: the atlas of {} would need about {} of memory, more than "
                                 "--max-memory {}",
                                 o.atlas.resolution, o.mesh, format_bytes(needed), format_bytes(double(budget))));
  const SurfaceAtlas atlas = build_surface_atlas(mesh, o.atlas);
  const AtlasReport& r = atlas.report;
  if (r.packing_overflow) warn("{}: too many charts for a {}x{} atlas: packed without gutter", o.mesh, o.atlas.resolution, o.atlas.resolution);
  const double atlas_seconds = r.seconds_charts + r.seconds_lscm + r.seconds_pack + r.seconds_texels;

  UvMeshMaterial material;
  std::string checker_path;
  if (o.checker) {
    const std::filesystem::path obj(o.out);
    checker_path = (obj.parent_path() / (obj.stem().string() + ".checker.png")).string();
    write_png(checker_path, checker_image(o.atlas.resolution), true);
    material.color_texture = std::filesystem::path(checker_path).filename().string();
  }
  write_uv_mesh_obj(o.out, mesh, atlas, material);
  if (!o.texels_png.empty()) write_png(o.texels_png, texel_image(mesh, atlas), true);

  if (o.json) {
    nlohmann::json j;
    j["mesh"] = o.mesh;
    j["triangles"] = mesh.triangle_count();
    j["vertices"] = mesh.vertex_count();
    j["resolution"] = o.atlas.resolution;
    j["gutter"] = o.atlas.gutter;
    j["threads"] = thread_count();
    j["charts"] = r.charts;
    j["utilization"] = r.utilization;
    j["lost_to_gutters"] = r.lost_to_gutters;
    j["lost_to_packing"] = r.lost_to_packing;
    j["chart_texels"] = atlas.texels.size();
    j["density_p95_low"] = r.density_p95_low;
    j["density_p95_high"] = r.density_p95_high;
    j["area_in_density_bounds"] = r.area_in_density_bounds;
    j["flipped_triangles"] = r.flipped_triangles;
    j["texels_per_metre"] = r.texels_per_metre;
    j["packing_overflow"] = r.packing_overflow;
    j["seconds"] = {{"read", read_seconds}, {"charts", r.seconds_charts}, {"lscm", r.seconds_lscm},
                    {"pack", r.seconds_pack}, {"texels", r.seconds_texels}, {"atlas", atlas_seconds}};
    j["obj"] = o.out;
    j["mtl"] = uv_mesh_mtl_path(o.out);
    if (!checker_path.empty()) j["checker"] = checker_path;
    fmt::print("{}\n", j.dump(2));
  } else if (o.report) {
    fmt::print("mesh            {} ({} triangles, {} vertices)\n", o.mesh, mesh.triangle_count(), mesh.vertex_count());
    fmt::print("atlas           {}x{} texels, gutter {} texels, {} threads\n", o.atlas.resolution, o.atlas.resolution,
               o.atlas.gutter, thread_count());
    fmt::print("charts          {}\n", r.charts);
    fmt::print("density         {:.1f} texels per metre ({:.3g} mm per texel){}\n", r.texels_per_metre,
               r.texels_per_metre > 0 ? 1000 / r.texels_per_metre : 0.0,
               r.packing_overflow ? "; gutter dropped: too many charts for this resolution" : "");
    fmt::print("utilization     {:.1f}% ({} chart texels); lost to gutters {:.1f}%, lost to packing {:.1f}%\n",
               100 * r.utilization, atlas.texels.size(), 100 * r.lost_to_gutters, 100 * r.lost_to_packing);
    fmt::print("texel density   95% of the area within [{:.3f}, {:.3f}] of the mean; {:.1f}% of the area in [0.8, 1.25]\n",
               r.density_p95_low, r.density_p95_high, 100 * r.area_in_density_bounds);
    fmt::print("flipped         {} triangles\n", r.flipped_triangles);
    fmt::print("seconds         charts {:.3f}, lscm {:.3f}, pack {:.3f}, texels {:.3f}, total {:.3f} (read {:.3f})\n",
               r.seconds_charts, r.seconds_lscm, r.seconds_pack, r.seconds_texels, atlas_seconds, read_seconds);
    fmt::print("wrote           {} + {}{}\n", o.out, uv_mesh_mtl_path(o.out),
               checker_path.empty() ? "" : " + " + checker_path);
  } else {
    info("atlas: {} triangles, {} charts, utilization {:.1f}%, {:.1f}% of the area in the density bounds, {:.3f} s; wrote {}",
         mesh.triangle_count(), r.charts, 100 * r.utilization, 100 * r.area_in_density_bounds, atlas_seconds, o.out);
  }
}

}  // namespace

void add_atlas_command(CLI::App& app) {
  auto o = std::make_shared<AtlasCommand>();
  auto* cmd = app.add_subcommand(
      "atlas",
      "Atlas one mesh on its own: cut it into charts, flatten them (LSCM), pack them at one texel density,\n"
      "and write the mesh with its atlas UVs as OBJ + MTL. Prints the chart count, utilization (and what\n"
      "gutters and packing lose), texel-density spread and seconds per stage. Works on any triangle mesh\n"
      "(PLY or OBJ), static ones included.");
  cmd->add_option("mesh", o->mesh, "Input mesh (PLY or OBJ)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", o->out, "Output OBJ; the MTL is written beside it with the extension .mtl")->required();
  cmd->add_option("--resolution", o->atlas.resolution,
                  "Atlas width = height in texels; refused (exit 2) before any texel is allocated when its "
                  "buffers (about 12 bytes per texel, 33 with --texels) do not fit --max-memory")
      ->check(CLI::Range(16, 65536))
      ->capture_default_str();
  cmd->add_option("--gutter", o->atlas.gutter,
                  "Empty texels between two charts, shared by the two (G/2, rounded up, to the atlas's edges)")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  cmd->add_option("--max-stretch", o->atlas.max_stretch,
                  "A chart is split when more than 2% of its area has a texel density outside [1/S, S] of its mean")
      ->check(CLI::Range(1.01, 100.0))
      ->capture_default_str();
  cmd->add_flag("--report", o->report, "Print the quality figures and timings");
  cmd->add_flag("--json", o->json, "Print the figures as JSON on stdout");
  cmd->add_flag("--checker", o->checker, "Write <obj stem>.checker.png beside the OBJ and point the MTL at it");
  cmd->add_option("--texels", o->texels_png, "Write a PNG of the chart texels coloured by chart (a look at the packing)");
  add_max_memory_option(*cmd, o->max_memory, "A larger atlas is refused (exit 2) before it is built.");
  add_global_options(*cmd);
  cmd->callback([o] { run(*o); });
}

}  // namespace lapflow::cli
