// The bake: the frame loop, one visible call per step of ALGORITHM.md.
#include "lapflow/bake/bake.hpp"

#include <fcntl.h>
#include <malloc.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>

#include "bake/read_ahead.hpp"
#include "bake/writer.hpp"
#include "lapflow/bake/budget.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/bake/render_record.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/core/stopwatch.hpp"
#include "lapflow/io/mesh_io.hpp"

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

int tracking_resolution(double area, double radius, double track_texel) {
  const double texel = track_texel * radius;
  if (!(texel > 0) || !(area > 0)) return 64;
  const double n = std::ceil(std::sqrt(area / 0.7) / texel / 8.0) * 8.0;
  return int(std::clamp(n, 64.0, 16384.0));
}

FrameSource frame_source(const BakeOptions& o) {
  FrameSource source;
  source.mesh_pattern = o.mesh_pattern;
  source.velocity_vdb_pattern = o.velocity_vdb_pattern;
  source.velocity_grid = o.velocity_grid;
  source.min_speed = o.min_speed;
  source.allow_zero_velocity = o.allow_zero_velocity;
  source.units_ok = o.units_ok;
  source.velocity_band = o.velocity_band;
  source.velocity_voxel = o.velocity_voxel;
  source.attributes = layer_rules(o).file_attributes();
  return source;
}

BakeMemoryEstimate resolve_bake_options(BakeOptions& o) {
  if (o.mesh_pattern.empty()) throw UsageError("--mesh is required (a per-frame PLY/OBJ pattern)");
  if (o.out_dir.empty()) throw UsageError("--out is required");
  if (o.layers.empty() && o.exemplar_color.empty()) throw UsageError("--exemplar (or --layer) is required");
  if (!o.layers.empty() && !o.exemplar_color.empty())
    throw UsageError("--exemplar and --layer: with layers, give every exemplar as a --layer");
  layer_rules(o);  // checks the layers and their rules
  if (!(o.fps > 0)) throw UsageError("--fps must be positive");
  o.advect.dt = 1.0 / o.fps;
  o.patch.seed = o.seed;
  if (o.patch.radius < 0) throw UsageError("--radius must be positive");
  if (!(o.seeding.spacing > 0)) throw UsageError("--spacing must be positive");
  if (!(o.track_texel >= 1.0 / 1024 && o.track_texel <= 1)) throw UsageError("--track-texel must be in [1/1024, 1]");
  if (o.patch.remesh && !(o.patch.remesh_edge > 0)) throw UsageError("--remesh-edge must be positive");
  // The first frame's mesh and the exemplar's headers: the automatic values
  // and the memory estimate come from them, before anything large exists.
  const BakeInputSizes sizes = read_bake_input_sizes(o);
  if (o.patch.radius == 0) {
    // About 1500 patches on the first frame: small enough to follow the flow,
    // large enough that each shows the exemplar's features.
    o.patch.radius = sizes.area > 0 ? std::sqrt(sizes.area / 1500.0) : 0.05;
  }
  if (o.atlas.resolution == 0) {
    // One atlas texel per exemplar texel: the exemplar spans 2r over its
    // width; charts fill about 65% of the atlas.
    const double texel = 2 * o.patch.radius / std::max(1, sizes.color.width);
    const double n = std::sqrt(std::max(sizes.area, 1e-12) / 0.65) / texel;
    o.atlas.resolution = int(std::clamp(std::ceil(n / 256.0) * 256.0, 512.0, 4096.0));
  }
  if (o.atlas.resolution < 16 || o.atlas.resolution > 32768)
    throw UsageError("--resolution must be between 16 and 32768 texels");
  const BakeMemoryEstimate estimate = check_bake_budget(o, sizes);
  o.raster.radius = o.patch.radius;
  o.raster.aov = o.aov;
  o.raster.gutter = o.atlas.gutter;
  o.raster.clock.rate = o.exemplar_fps > 0 ? o.exemplar_fps / o.fps : 1.0;
  o.raster.clock.loop = o.exemplar_loop;
  o.raster.clock.seed = o.seed;
  o.weights.keep_at_rest = o.raster.hold;
  return estimate;
}

namespace {

/// The counts of a frame that its stages leave in the frame, the tracking
/// raster and the patches; `rendered`: render_frame drew the output.
void record_frame_stats(const Frame& frame, const RasterStats& tracking, const PatchSet& patches, FrameStats& st,
                        bool rendered) {
  st.frame = frame.number;
  st.triangles = frame.mesh.triangle_count();
  st.vertices = frame.mesh.vertex_count();
  st.velocity_source = frame.velocity_source;
  // Births and deaths: the tracking raster's decisions.
  const RasterStats& t = tracking;
  st.patches_born += t.patches_born;
  st.patches_retired = t.patches_retired + st.retired_layer;
  st.retired_eroded = t.retired_eroded;
  st.retired_hidden = t.retired_hidden;
  st.retired_merged = t.retired_merged;
  st.patches_alive = patches.patches.size();
  st.tracking.resolution = frame.tracking_atlas.resolution;
  st.tracking.texel_size = t.texel_world_size;
  st.tracking.chart_texels = t.chart_texels;
  st.tracking.forced_texels = t.forced_texels;
  st.tracking.closed_texels = t.closed_texels;
  st.tracking.held_texels = t.held_texels;
  st.tracking.utilization = frame.tracking_atlas.report.utilization;
  if (!rendered) {
    // `lapflow track`: no output raster (render_frame fills these otherwise).
    st.charts = frame.tracking_atlas.chart_count;
    st.coverage = t.chart_texels ? double(t.covered_texels) / double(t.chart_texels) : 1.0;
    st.seconds_raster = st.seconds_track;
  }
}

/// A SIGINT or SIGTERM asked to stop: the frame in hand has no file yet and
/// is abandoned; a frame still being written in the background is finished.
void stop_if_asked(detail::FrameWriter& writer) {
  if (const int signal = stop_signal()) {
    writer.finish();
    throw Interrupted(signal, writer.last_complete_frame());
  }
}

/// Where a bake starts: after frames[index] with `state`, or from the first
/// frame (index < 0).
struct ResumePoint {
  std::ptrdiff_t index = -1;
  BakeState state;
};

/// Removes the NAME.state.N.bin files in --out that this bake will not
/// resume from: every one for a bake from the first frame, those of the frames
/// after `from` (an earlier run's, about to be recomputed) otherwise.
void remove_states_after(const BakeOptions& o, const BakeManifest& names, std::ptrdiff_t from) {
  const std::regex state(bake_state_file_pattern(o.name));
  std::set<std::string> keep;
  for (std::ptrdiff_t i = 0; i <= from; ++i)
    keep.insert(fs::path(names.frame_file("state", names.frames[std::size_t(i)])).filename().string());
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(o.out_dir, ec)) {
    const std::string file = e.path().filename().string();
    if (std::regex_match(file, state) && !keep.count(file)) fs::remove(e.path(), ec);
  }
}

/// --resume: the last frame of an unbroken run of complete frames (each
/// with its OBJ) from the first that has a state, checked against the
/// options. Throws InputError naming the manifest and each difference, or
/// the state file and what is wrong with it.
ResumePoint find_resume_point(const BakeOptions& o, const BakeManifest& current) {
  ResumePoint point;
  const std::string manifest_path = bake_manifest_path(o.out_dir, o.name);
  if (!fs::exists(manifest_path)) return point;  // nothing baked here yet
  // `lapflow track` needs only the patches' options to match: a render may
  // have set the output's anew in the manifest.
  const std::vector<std::string> differences = bake_manifest_differences(manifest_path, current, o.track_only);
  if (!differences.empty()) {
    std::string what;
    for (std::size_t i = 0; i < differences.size() && i < 4; ++i) what += (i ? "; " : "") + differences[i];
    if (differences.size() > 4) what += "; and " + std::to_string(differences.size() - 4) + " more";
    throw InputError(manifest_path, "cannot resume: the bake in this folder was made with other options (" + what +
                                        "); run without --resume to bake from the first frame");
  }
  const std::vector<int>& frames = current.frames;
  // A tracked frame is complete with its state; a baked one with its OBJ.
  const std::string complete = o.track_only ? "state" : "obj";
  for (std::size_t i = 0; i < frames.size() && fs::exists(current.frame_file(complete, frames[i])); ++i)
    if (fs::exists(current.frame_file("state", frames[i]))) point.index = std::ptrdiff_t(i);
  if (point.index < 0) return point;
  const int frame = frames[std::size_t(point.index)];
  const std::string path = current.frame_file("state", frame);
  point.state = read_bake_state(path);
  check_bake_state(point.state, path, current, frame);
  return point;
}

/// NAME.stats.jsonl's lines of the frames up to and including the resume
/// point, in frame order; the resumed frame's line from its state when a
/// kill came before it was written.
std::string stats_lines_until(const BakeOptions& o, const BakeManifest& names, const ResumePoint& point) {
  std::map<int, std::string> by_frame;
  std::ifstream in(fs::path(o.out_dir) / (o.name + ".stats.jsonl"));
  for (std::string line; std::getline(in, line);) {
    const nlohmann::json j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_object() && j.contains("frame") && j["frame"].is_number_integer())
      by_frame.emplace(j["frame"].get<int>(), line);
  }
  by_frame.emplace(point.state.header.frame, point.state.header.stats_line);
  std::string text;
  for (std::ptrdiff_t i = 0; i <= point.index; ++i)
    if (const auto line = by_frame.find(names.frames[std::size_t(i)]); line != by_frame.end())
      text += line->second + "\n";
  return text;
}

}  // namespace

void check_bake_state(const BakeState& state, const std::string& path, const BakeManifest& manifest, int frame) {
  const BakeStateHeader& h = state.header;
  if (h.name != manifest.name || h.frame != frame)
    throw InputError(path, "the state is of bake '" + h.name + "' frame " + std::to_string(h.frame) +
                               ", not of '" + manifest.name + "' frame " + std::to_string(frame));
  if (h.options_checksum != bake_tracking_checksum(manifest))
    throw InputError(path, "the state was written with other options than " +
                               fs::path(bake_manifest_path(manifest.dir, manifest.name)).filename().string() +
                               "'s");
}

void render_frame(Frame& frame, const PatchSet& patches, ExemplarLayers exemplar, const BakeOptions& o) {
  FrameStats& st = frame.stats;
  RasterOptions output = o.raster;
  output.held_texel = o.track_texel;
  output.clock.frame = frame.number;
  // The writer's pixels as the resolve makes them (no float images).
  output.half_images = o.exr.type == ExrPixelType::Half;
  frame.textures = output_pass(frame.mesh, frame.atlas, exemplar, output, o.weights,
                               surface_triangle_locator(*frame.surface, o.raster.radius), patches);
  const RasterStats& r = frame.textures.stats;
  st.seconds_draw = r.seconds_setup + r.seconds_raster;
  st.seconds_holes = r.seconds_holes;
  st.seconds_resolve = r.seconds_resolve;
  st.seconds_dilate = r.seconds_dilate;
  st.charts = frame.atlas.chart_count;
  st.utilization = frame.atlas.report.utilization;
  st.chart_texels = r.chart_texels;
  st.forced_texels = r.forced_texels;
  st.closed_texels = r.closed_texels;
  st.held_texels = r.held_texels;
  st.coverage = r.chart_texels ? double(r.covered_texels) / double(r.chart_texels) : 1.0;
  st.seconds_raster = st.seconds_track + st.seconds_draw + st.seconds_holes + st.seconds_resolve + st.seconds_dilate;
}

void build_frame_atlases(Frame& frame, const BakeOptions& o) {
  // The tracking atlas (the patches' decisions), then the output's.
  AtlasOptions tracking = o.atlas;
  tracking.resolution = tracking_resolution(surface_area(frame.mesh), o.patch.radius, o.track_texel);
  tracking.gutter = kTrackingGutter;
  if (o.track_only) {
    frame.tracking_atlas = build_surface_atlas(frame.mesh, tracking);
    return;
  }
  // One segmentation and flattening for both.
  std::vector<SurfaceAtlas> both = build_surface_atlases(frame.mesh, {tracking, o.atlas});
  frame.tracking_atlas = std::move(both[0]);
  frame.atlas = std::move(both[1]);
}

namespace {

/// Counts, per patch, the frames in a row its centre has lain where `field`
/// chooses another layer (Patch::layer_off), and removes the patches where
/// that count reaches `frames`. Returns how many went.
std::size_t retire_off_layer(const LayerField& field, int frames, PatchSet& patches) {
  std::vector<Patch>& all = patches.patches;
  parallel_for(all.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p) {
      Patch& patch = all[p];
      if (field.layer_at(patch.center) == int(patch.layer))
        patch.layer_off = 0;
      else if (patch.layer_off < UINT16_MAX)
        ++patch.layer_off;
    }
  }, 16);
  const std::size_t before = all.size();
  std::erase_if(all, [&](const Patch& patch) { return patch.layer_off >= frames; });
  return before - all.size();
}

}  // namespace

RasterStats track_frame(Frame& cur, const Frame* prev, PatchSet& patches, ExemplarLayers textures,
                        const BakeOptions& o) {
  if (textures.size() != std::max<std::size_t>(1, o.layers.size()))
    throw std::invalid_argument("track_frame: one exemplar per layer");
  FrameStats& st = cur.stats;
  Stopwatch clock;
  // Exemplar layers: the layer the rules choose at each surface point.
  const LayerRules rules = layer_rules(o);
  LayerField field;
  if (rules.size() > 1) field = LayerField(rules, cur);
  st.layered = rules.size() > 1;
  if (prev && !patches.patches.empty()) {
    // Step 4: the patches follow the flow onto this frame's surface.
    AdvectOptions advect = o.advect;
    advect.dt = double(cur.number - prev->number) / o.fps;
    const AdvectStats a = advect_patches(*cur.surface, prev->velocity, cur.velocity, o.patch, advect, patches);
    st.patches_lost = a.patches_removed;
    st.patch_vertices_removed = a.vertices_removed;
    st.seconds_advect = clock.lap();
    // Step 5.
    update_weights(cur.mesh, o.patch.radius, o.weights, patches);
    st.seconds_weights = clock.lap();
    // A patch whose centre has lain where the rules choose another layer
    // for layer_switch frames goes, and the new layer's patches take its
    // place (docs/layers.md, "Changing regions").
    if (!field.empty()) st.retired_layer = retire_off_layer(field, o.layer_switch, patches);
  }
  // New patches (seeding, hole filling) see this frame's flow.
  PatchOptions born = o.patch;
  born.velocity = &cur.velocity;
  born.previous_velocity = prev ? &prev->velocity : nullptr;
  born.dt = 1.0 / o.fps;
  if (patches.patches.empty() && !cur.mesh.empty()) {
    // Steps 1-3 on the first frame, and after the liquid vanished.
    seed_patches(*cur.surface, cur.number, born, o.seeding, o.weights, patches);
    if (!field.empty()) {
      parallel_for(patches.patches.size(), [&](std::size_t b, std::size_t e) {
        for (std::size_t p = b; p < e; ++p) patches.patches[p].layer = uint16_t(field.layer_at(patches.patches[p].center));
      }, 16);
    }
    st.patches_born += patches.patches.size();
    st.seconds_seed = clock.lap();
  }

  // Steps 7-9 at the tracking resolution (docs/farm.md): lapped
  // rasterization, the oldest non-eroded patch per texel; new patches at
  // the holes' centres; the texels each patch won; retirement. Patches
  // and their held cells then carry over to the next frame. Only what
  // carries over is decided here: no image.
  RasterOptions tracking = o.raster;
  tracking.held_texel = o.track_texel;
  tracking.clock.frame = cur.number;
  Stopwatch step;
  const SurfaceAdjacency adjacency = build_surface_adjacency(cur.mesh);
  const double seconds_adjacency = step.lap();
  PatchMaker make_patch = surface_patch_maker(*cur.surface, adjacency, born, o.weights, cur.number);
  if (!field.empty()) {
    // A newborn takes the layer of the point it is born at.
    make_patch = [base = std::move(make_patch), &field](const SurfacePoint& at, uint32_t id) {
      std::optional<Patch> patch = base(at, id);
      if (patch) patch->layer = uint16_t(field.layer_at(at.position));
      return patch;
    };
  }
  const RasterStats t = track_pass(cur.mesh, cur.tracking_atlas, textures, tracking, o.weights,
                                   surface_triangle_locator(*cur.surface, o.raster.radius), cur.number, make_patch,
                                   patches);
  st.tracking.seconds_setup = t.seconds_setup;
  st.tracking.seconds_draw = t.seconds_raster;
  st.tracking.seconds_holes = seconds_adjacency + t.seconds_holes;
  st.tracking.seconds_resolve = t.seconds_resolve;
  st.tracking.seconds_retire = t.seconds_retire;
  st.seconds_track = clock.lap();
  return t;
}

namespace detail {

void prepare_output_folder(const BakeOptions& o) {
  const std::string& dir = o.out_dir;
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw OutputError(dir + ": the output folder (--out) is a file, not a folder");
  fs::create_directories(dir, ec);
  if (ec) throw OutputError(dir + ": cannot create the output folder (--out): " + ec.message());
  // The effective user's rights (root passes permission bits, but not a
  // read-only file system).
  if (::faccessat(AT_FDCWD, dir.c_str(), W_OK | X_OK, AT_EACCESS) != 0)
    throw OutputError(dir + ": cannot write in the output folder (--out): " +
                      std::generic_category().message(errno));
  remove_stale_temporaries(dir, bake_file_stem_patterns(o.name));
}

}  // namespace detail

void bake(const BakeOptions& o, const std::function<void(const FrameStats&)>& on_frame) {
  const FramePattern meshes(o.mesh_pattern);
  const std::vector<int> frames = resolve_frames(meshes, o.frames);
  const BakeExemplars exemplars = load_bake_exemplars(o);
  const ExemplarLayers textures = exemplars.layers();
  detail::prepare_output_folder(o);
  // The manifest also names every output file (BakeManifest::frame_file).
  BakeManifest manifest = make_bake_manifest(o, frames);
  manifest.feature_digest = exemplars.feature_digest();
  ResumePoint resume;
  if (o.resume) resume = find_resume_point(o, manifest);
  remove_states_after(o, manifest, resume.index);
  write_bake_manifest(manifest, bake_manifest_path(o.out_dir, o.name));

  // The frames to compute: after the resume point, up to --until.
  std::vector<int> todo(frames.begin() + (resume.index + 1), frames.end());
  if (o.until_frame) std::erase_if(todo, [&](int f) { return f > *o.until_frame; });
  detail::FrameReader reader(o, todo);
  detail::FrameWriter writer(o, manifest, on_frame);
  writer.set_exemplar_digest(exemplars.digest());
  PatchSet patches;  // the state that carries over from frame to frame
  std::shared_ptr<const Frame> prev;
  if (resume.index >= 0 && !todo.empty()) {
    // The patches from the state, and the resumed frame read again for the
    // velocity the next advection starts from.
    patches = std::move(resume.state.patches);
    prev = load_frame(frame_source(o), resume.state.header.frame);
    writer.resume(stats_lines_until(o, manifest, resume), resume.state.header.frame);
  }
  try {
    for (std::size_t left = todo.size(); left > 0; --left) {
      stop_if_asked(writer);
      Stopwatch frame_clock;
      // Read ahead: mesh, surface query, velocity, and step 6, the frame's
      // own atlases (they need only the mesh).
      const std::shared_ptr<Frame> frame = reader.next();
      Frame& cur = *frame;
      FrameStats& st = cur.stats;
      st.seconds_read = frame_clock.lap();
      const RasterStats tracked = track_frame(cur, prev.get(), patches, textures, o);

      // The output at its own resolution, from the patches as they leave the
      // frame: what `lapflow render` does with the frame's state.
      if (!o.track_only) render_frame(cur, patches, textures, o);

      // Step 10: the frame's files, under temporary names and renamed into
      // place together, the OBJ last (the state, for `lapflow track`); its
      // stats line follows.
      record_frame_stats(cur, tracked, patches, st, !o.track_only);
      // The next frame reads only this one's number, mesh and velocity: its
      // tracking atlas goes now, not when the next frame replaces it as
      // `prev` (hundreds of megabytes at production resolutions that the next
      // frame's own buffers would otherwise come on top of;
      // docs/performance.md, "Memory and large blocks").
      cur.tracking_atlas = SurfaceAtlas{};
      stop_if_asked(writer);
      writer.write(frame, patches, frame_clock.total());
      prev = frame;
    }
    writer.finish();
  } catch (...) {
    // A bad frame or a stop ends the bake; the frame already computed is
    // still written in full (its files and stats line), then the error goes up.
    try {
      writer.finish();
    } catch (...) {
    }
    throw;
  }
}

}  // namespace lapflow
