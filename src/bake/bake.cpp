// The bake: one short frame loop over the stages (ALGORITHM.md steps 1-10).
#include "lapflow/bake/bake.hpp"

#include <malloc.h>
#include <sys/resource.h>

#include <chrono>
#include <climits>
#include <cmath>
#include <exception>
#include <filesystem>
#include <future>
#include <memory>
#include <nlohmann/json.hpp>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/io/uv_mesh.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow {
namespace fs = std::filesystem;

double peak_rss_mb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return double(usage.ru_maxrss) / 1024.0;  // Linux reports KiB
}

void keep_freed_memory_for_reuse() {
  // No mmap'd chunks (each one's pages are zeroed by the kernel again after
  // every free), never trim the heap's top back to the kernel, and one arena
  // for every thread: a secondary arena maps any block over its 64 MiB heap
  // size with mmap even when M_MMAP_MAX is 0. Small blocks still come from
  // each thread's tcache, so the shared arena's lock is rarely taken.
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, INT_MAX);
  mallopt(M_ARENA_MAX, 1);
}

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// One frame's surface with everything sampled from it.
struct SurfaceFrame {
  int frame = 0;
  std::string path;
  TriMesh mesh;
  std::unique_ptr<SurfaceQuery> query;
  std::unique_ptr<VelocityGrid> grid;
  VelocityField velocity;
  std::string velocity_source;
  /// Step 6, the frame's own atlas: it needs only the mesh, so it is built
  /// with the read, ahead of the frame (BakeOptions::prefetch_read).
  SurfaceAtlas atlas;
  double seconds_atlas = 0;
};

std::unique_ptr<SurfaceFrame> load_frame(const BakeOptions& o, const FramePattern& meshes, int frame) {
  auto s = std::make_unique<SurfaceFrame>();
  s->frame = frame;
  s->path = meshes.path(frame);
  try {
    s->mesh = read_mesh(s->path);
  } catch (const InputError& e) {
    throw e.with_frame(frame);
  }
  s->query = std::make_unique<SurfaceQuery>(s->mesh);
  if (!o.velocity_vdb_pattern.empty()) {
    const std::string vdb = FramePattern(o.velocity_vdb_pattern).path(frame);
    try {
      s->grid = std::make_unique<VelocityGrid>(vdb, o.velocity_grid);
    } catch (const InputError& e) {
      throw e.with_frame(frame);
    }
    s->velocity = grid_velocity_field(*s->grid);
    s->velocity_source = "vdb:" + s->grid->grid_name();
  } else if (s->mesh.has_velocities()) {
    s->velocity = vertex_velocity_field(*s->query);
    s->velocity_source = "vertex";
    if (o.velocity_band > 0) {
      s->velocity = banded_velocity_field(std::move(s->velocity), s->mesh, o.velocity_voxel * mean_edge_length(s->mesh),
                                          o.velocity_band);
      s->velocity_source = "vertex (band of " + std::to_string(o.velocity_band) + " voxels)";
    }
  } else if (s->mesh.empty() || o.allow_zero_velocity) {
    s->velocity = [](const Vec3&) { return Vec3{}; };
    s->velocity_source = "zero";
  } else {
    throw InputError(s->path,
                     "no per-vertex velocity (vx vy vz) and no --velocity-vdb; pass --allow-zero-velocity to bake a "
                     "still texture",
                     frame);
  }
  if (o.min_speed > 0) s->velocity = with_min_speed(std::move(s->velocity), o.min_speed);
  const auto t = Clock::now();
  s->atlas = build_surface_atlas(s->mesh, o.atlas);
  s->seconds_atlas = seconds_since(t);
  return s;
}

nlohmann::json stats_json(const FrameStats& s) {
  return {{"frame", s.frame},
          {"triangles", s.triangles},
          {"vertices", s.vertices},
          {"velocity", s.velocity_source},
          {"patches", {{"alive", s.patches_alive}, {"born", s.patches_born}, {"retired", s.patches_retired},
                       {"lost", s.patches_lost}}},
          {"patch_vertices_removed", s.patch_vertices_removed},
          {"charts", s.charts},
          {"utilization", s.utilization},
          {"chart_texels", s.chart_texels},
          {"coverage", s.coverage},
          {"forced_texels", s.forced_texels},
          {"seconds", {{"read", s.seconds_read}, {"advect", s.seconds_advect}, {"seed", s.seconds_seed},
                       {"atlas", s.seconds_atlas}, {"raster", s.seconds_raster}, {"write", s.seconds_write},
                       {"total", s.seconds_total}}},
          {"peak_rss_mb", s.peak_rss_mb}};
}

/// Everything one frame's files are made of, owned by the writer.
struct FrameWrite {
  FrameTextures textures;
  SurfaceAtlas atlas;
  std::shared_ptr<const SurfaceFrame> surface;
  PatchSet patches;  ///< a copy, with dump_patches only
};

/// Writes frame f's files, each atomically. Returns the seconds it took.
double write_frame(const BakeOptions& o, const BakeManifest& names, const FrameWrite& w, int f) {
  const auto t = Clock::now();
  const std::string color = names.frame_file("color", f), disp = names.frame_file("disp", f);
  std::vector<std::function<void()>> jobs;
  jobs.push_back([&] { write_exr(color, w.textures.color, {"R", "G", "B", "A"}, o.exr); });
  jobs.push_back([&] { write_exr(disp, w.textures.displacement, {"Y"}, o.exr); });
  if (o.aov)
    jobs.push_back([&] {
      // Data: float, and never lossy.
      const ExrCompression lossless =
          o.exr.compression == ExrCompression::Dwaa ? ExrCompression::Zip : o.exr.compression;
      write_exr(names.frame_file("aov", f), w.textures.aov, {"patch_id", "u", "v", "w"},
                {ExrPixelType::Float, lossless});
    });
  jobs.push_back([&] {
    UvMeshMaterial material;
    material.name = o.name;
    material.color_texture = fs::path(color).filename().string();
    material.displacement_texture = fs::path(disp).filename().string();
    write_uv_mesh_obj(names.frame_file("obj", f), w.surface->mesh, w.atlas, material);
  });
  if (o.dump_patches) jobs.push_back([&] { write_patches_ply(names.frame_file("patches", f), w.patches); });
  if (o.background_write) {
    // One after the other on this thread (OpenEXR compresses on its own
    // pool): the writer must not take the TBB workers the next frame needs.
    for (const auto& job : jobs) job();
    return seconds_since(t);
  }
  // Nothing else runs: the files are written concurrently (OIIO converts
  // each image on one thread). Each job keeps its own error; the first in
  // job order is rethrown.
  std::vector<std::exception_ptr> errors(jobs.size());
  parallel_for(jobs.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      try {
        jobs[i]();
      } catch (...) {
        errors[i] = std::current_exception();
      }
    }
  }, 1);
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
  return seconds_since(t);
}

}  // namespace

void resolve_bake_options(BakeOptions& o) {
  if (o.mesh_pattern.empty()) throw UsageError("--mesh is required (a per-frame PLY/OBJ pattern)");
  if (o.out_dir.empty()) throw UsageError("--out is required");
  if (o.exemplar_color.empty()) throw UsageError("--exemplar is required");
  if (!(o.fps > 0)) throw UsageError("--fps must be positive");
  o.advect.dt = 1.0 / o.fps;
  o.patch.seed = o.seed;
  if (o.patch.radius < 0) throw UsageError("--radius must be positive");
  if (o.patch.radius == 0 || o.atlas.resolution == 0) {
    // Automatic values come from the first frame's surface and the exemplar.
    const FramePattern meshes(o.mesh_pattern);
    const std::vector<int> frames = resolve_frames(meshes, o.frames);
    TriMesh first;
    try {
      first = read_mesh(meshes.path(frames.front()));
    } catch (const InputError& e) {
      throw e.with_frame(frames.front());
    }
    const double area = surface_area(first);
    if (o.patch.radius == 0) {
      // About 1500 patches on the first frame: small enough to follow the flow,
      // large enough that each shows the exemplar's features.
      o.patch.radius = area > 0 ? std::sqrt(area / 1500.0) : 0.05;
    }
    if (o.atlas.resolution == 0) {
      // One atlas texel per exemplar texel: the exemplar spans 2r over its
      // width; charts fill about 65% of the atlas.
      const Image probe = read_image(o.exemplar_color);
      const double texel = 2 * o.patch.radius / std::max(1, probe.width);
      const double n = std::sqrt(std::max(area, 1e-12) / 0.65) / texel;
      o.atlas.resolution = int(std::clamp(std::ceil(n / 256.0) * 256.0, 512.0, 4096.0));
    }
  }
  if (o.atlas.resolution < 16 || o.atlas.resolution > 32768)
    throw UsageError("--resolution must be between 16 and 32768 texels");
  o.raster.radius = o.patch.radius;
  o.raster.aov = o.aov;
  o.raster.gutter = o.atlas.gutter;
}

void bake(const BakeOptions& o, const std::function<void(const FrameStats&)>& on_frame) {
  const FramePattern meshes(o.mesh_pattern);
  const std::vector<int> frames = resolve_frames(meshes, o.frames);
  const Exemplar exemplar = load_exemplar(o.exemplar_color, o.exemplar_feature, o.exemplar_displacement);
  const RasterExemplar textures = prepare_raster_exemplar(exemplar, o.raster.epsilon);
  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) throw OutputError(o.out_dir + ": cannot create the output folder: " + ec.message());

  PatchSet patches;
  std::shared_ptr<SurfaceFrame> prev;
  std::string stats_text;
  const std::string stats_path = (fs::path(o.out_dir) / (o.name + ".stats.jsonl")).string();
  // The manifest also names every output file (BakeManifest::frame_file).
  const BakeManifest manifest = make_bake_manifest(o, frames);
  write_bake_manifest(manifest, bake_manifest_path(o.out_dir, o.name));

  // The frame being written in the background, if any.
  std::future<double> pending;
  FrameStats pending_stats;
  double loop_seconds = 0;  // wall time of the frame loop iteration that computed the pending frame
  auto finish_pending = [&] {
    if (!pending.valid()) return;
    const auto t_wait = Clock::now();
    pending_stats.seconds_write = pending.get();  // rethrows a write error
    // Wall time the frame cost the bake: its computation plus the wait for
    // its files beyond the next frame's computation (frames sum to the bake).
    pending_stats.seconds_total = loop_seconds + seconds_since(t_wait);
    pending_stats.peak_rss_mb = peak_rss_mb();
    stats_text += stats_json(pending_stats).dump() + "\n";
    write_text_atomically(stats_path, stats_text);
    if (on_frame) on_frame(pending_stats);
  };

  try {
    // The next frame is read (mesh, Embree scene, velocity band) on another
    // thread while this one computes; its errors surface in frame order.
    std::future<std::shared_ptr<SurfaceFrame>> next;
    auto start_reading = [&](std::size_t i) {
      if (i < frames.size())
        next = std::async(o.prefetch_read ? std::launch::async : std::launch::deferred, [&o, &meshes, f = frames[i]] {
          return std::shared_ptr<SurfaceFrame>(load_frame(o, meshes, f));
        });
    };
    start_reading(0);
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const int f = frames[i];
      if (!o.prefetch_read && i > 0) start_reading(i);
      FrameStats st;
      st.frame = f;
      const auto t_frame = Clock::now();
      auto t = Clock::now();
      std::shared_ptr<SurfaceFrame> cur = next.get();
      if (o.prefetch_read) start_reading(i + 1);
      st.seconds_read = seconds_since(t);  // the wait for the frame read in the background
      st.triangles = cur->mesh.triangle_count();
      st.vertices = cur->mesh.vertex_count();
      st.velocity_source = cur->velocity_source;

      // Steps 1-5: patches follow the flow (or are seeded on the first frame and
      // after the liquid vanished).
      const std::size_t before = patches.patches.size();
      if (prev && !patches.patches.empty()) {
        t = Clock::now();
        AdvectOptions advect = o.advect;
        advect.dt = double(f - prev->frame) / o.fps;
        const AdvectStats a =
            advect_patches(*cur->query, prev->velocity, cur->velocity, o.patch, advect, o.weights, patches);
        st.patches_lost = a.patches_removed;
        st.patch_vertices_removed = a.vertices_removed;
        st.seconds_advect = seconds_since(t);
      }
      if (patches.patches.empty() && !cur->mesh.empty()) {
        t = Clock::now();
        seed_patches(*cur->query, f, o.patch, o.seeding, o.weights, patches);
        st.patches_born += patches.patches.size();
        st.seconds_seed = seconds_since(t);
      }
      (void)before;

      // Step 6: the frame's own atlas, built with the read (its time, which
      // overlapped the previous frame unless this is the first).
      SurfaceAtlas atlas = std::move(cur->atlas);
      st.seconds_atlas = cur->seconds_atlas;
      st.charts = atlas.chart_count;
      st.utilization = atlas.report.utilization;

      // Steps 7-9: lapped rasterization, hole filling, retirement.
      t = Clock::now();
      FrameTextures tex = rasterize_atlas(*cur->query, atlas, textures, o.raster, o.patch, o.weights, f, patches);
      st.seconds_raster = seconds_since(t);
      st.patches_born += tex.stats.patches_born;
      st.patches_retired = tex.stats.patches_retired;
      st.patches_alive = patches.patches.size();
      st.chart_texels = tex.stats.chart_texels;
      st.forced_texels = tex.stats.forced_texels;
      st.coverage = tex.stats.chart_texels ? double(tex.stats.covered_texels) / double(tex.stats.chart_texels) : 1.0;

      // Step 10: write the frame, every file atomically, on a writer thread
      // while the next frame computes. The frame's data moves to the writer;
      // its stats line and on_frame follow when its files are all on disk.
      auto job = std::make_shared<FrameWrite>();
      job->textures = std::move(tex);
      job->atlas = std::move(atlas);
      job->surface = cur;
      if (o.dump_patches) job->patches = patches;
      const double compute_seconds = seconds_since(t_frame);
      finish_pending();  // at most one frame in flight: bounds memory to two frames of images
      pending_stats = st;
      loop_seconds = compute_seconds;
      pending = std::async(std::launch::async, [&o, &manifest, job, f] { return write_frame(o, manifest, *job, f); });
      if (!o.background_write) finish_pending();
      prev = std::move(cur);
    }
    finish_pending();
  } catch (...) {
    // A bad frame stops the bake; the frame already computed is still written
    // in full (its files and stats line), then the error goes up.
    try {
      finish_pending();
    } catch (...) {
    }
    throw;
  }
}

}  // namespace lapflow
