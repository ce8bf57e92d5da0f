#include "bake/writer.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <exception>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

#include "lapflow/bake/render_record.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/core/stopwatch.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/io/usd.hpp"
#include "lapflow/io/uv_mesh.hpp"

namespace lapflow::detail {
namespace fs = std::filesystem;
namespace {

nlohmann::json stats_json(const FrameStats& s) {
  nlohmann::json j = {{"frame", s.frame},
          {"triangles", s.triangles},
          {"vertices", s.vertices},
          {"velocity", s.velocity_source},
          {"patches", {{"alive", s.patches_alive}, {"born", s.patches_born}, {"retired", s.patches_retired},
                       {"lost", s.patches_lost}, {"fresh_seeding", s.fresh_seeding}}},
          {"deaths", {{"lost_to_projection", s.patches_lost}, {"eroded_away", s.retired_eroded},
                      {"hidden", s.retired_hidden}, {"merged", s.retired_merged}}},
          {"patch_vertices_removed", s.patch_vertices_removed},
          {"charts", s.charts},
          {"utilization", s.utilization},
          {"chart_texels", s.chart_texels},
          {"coverage", s.coverage},
          {"forced_texels", s.forced_texels},
          {"closed_texels", s.closed_texels},
          {"held_texels", s.held_texels},
          {"tracking", {{"resolution", s.tracking.resolution}, {"texel_size", s.tracking.texel_size},
                        {"utilization", s.tracking.utilization}, {"chart_texels", s.tracking.chart_texels},
                        {"forced_texels", s.tracking.forced_texels}, {"closed_texels", s.tracking.closed_texels},
                        {"held_texels", s.tracking.held_texels}}},
          {"seconds", {{"read", s.seconds_read}, {"advect", s.seconds_advect}, {"weights", s.seconds_weights},
                       {"seed", s.seconds_seed}, {"atlas", s.seconds_atlas}, {"raster", s.seconds_raster},
                       {"draw", s.seconds_draw}, {"holes", s.seconds_holes}, {"resolve", s.seconds_resolve},
                       {"retire", s.seconds_retire}, {"dilate", s.seconds_dilate}, {"write", s.seconds_write}, {"state", s.seconds_state},
                       {"track", s.seconds_track}, {"track_setup", s.tracking.seconds_setup},
                       {"track_draw", s.tracking.seconds_draw}, {"track_holes", s.tracking.seconds_holes},
                       {"track_resolve", s.tracking.seconds_resolve}, {"track_retire", s.tracking.seconds_retire},
                       {"total", s.seconds_total}}},
          {"peak_rss_mb", s.peak_rss_mb}};
  if (s.layered) j["deaths"]["other_layer"] = s.retired_layer;
  return j;
}

}  // namespace

/// Everything one frame's files are made of, owned by the writer.
struct FrameWriter::Job {
  int frame = 0;
  FrameTextures textures;
  /// Colour and displacement in half, when the EXRs are (textures' floats then freed).
  HalfImage color_half, displacement_half;
  SurfaceAtlas atlas;
  std::shared_ptr<const Frame> surface;  ///< for the mesh
  PatchSet patches;                      ///< a copy, with dump_patches only
  std::string state;                     ///< NAME.state.N.bin's bytes, unless keep_states is 0
  RenderRecord record;                   ///< NAME.render.N.json, without its files
  std::optional<FileLock> lock;          ///< the frame's, held until its files are in place
};

FrameWriter::FrameWriter(const BakeOptions& options, const BakeManifest& names,
                         std::function<void(const FrameStats&)> on_frame, bool stats_file)
    : options_(options),
      names_(names),
      on_frame_(std::move(on_frame)),
      stats_path_((fs::path(options.out_dir) / (options.name + ".stats.jsonl")).string()),
      options_checksum_(bake_tracking_checksum(names)),
      stats_file_(stats_file) {}

void FrameWriter::resume(std::string stats_lines, int last_frame) {
  stats_text_ = std::move(stats_lines);
  last_complete_frame_ = last_frame;
  note_complete_frame(last_frame);
  write_usd_stage_file();
}

std::string FrameWriter::stats_line_without_timings(const FrameStats& stats) {
  // Every key of "seconds" (whichever a stage adds) and the peak memory: the
  // state's bytes must not depend on the clock.
  nlohmann::json j = stats_json(stats);
  for (auto& [key, value] : j.at("seconds").items()) value = 0.0;
  j["peak_rss_mb"] = 0.0;
  return j.dump();
}

double FrameWriter::write_files(const Job& w) const {
  Stopwatch clock;
  const BakeOptions& o = options_;
  const int f = w.frame;
  const std::string color = names_.frame_file("color", f), disp = names_.frame_file("disp", f);
  const std::string obj = names_.frame_file("obj", f);
  // Every file under a temporary name first; the frame appears only when
  // all of them are written (docs/bake.md, "When a frame is there").
  StagedFiles staged;
  if (o.track_only) {
    // `lapflow track`: the state is the frame.
    const std::string state = names_.frame_file("state", f);
    write_bake_state(state, w.state, &staged);
    staged.commit(state);
    return clock.lap();
  }
  std::vector<std::function<void()>> jobs;
  jobs.push_back([&] {
    if (!w.color_half.bits.empty()) write_exr(color, w.color_half, {"R", "G", "B", "A"}, o.exr, &staged);
    else write_exr(color, w.textures.color, {"R", "G", "B", "A"}, o.exr, &staged);
  });
  jobs.push_back([&] {
    if (!w.displacement_half.bits.empty()) write_exr(disp, w.displacement_half, {"Y"}, o.exr, &staged);
    else write_exr(disp, w.textures.displacement, {"Y"}, o.exr, &staged);
  });
  if (o.aov)
    jobs.push_back([&] {
      // Data: float, and never lossy. RLE finds no runs to shorten in it:
      // every texel holds a patch's (u, v), the gutters too once dilated,
      // and the file comes out the size of the uncompressed one. So under
      // RLE, the default, it is written uncompressed, which spares the
      // encoding; ZIP and PIZ do shrink it, at several times the time
      // (docs/performance.md, "EXR writing and compression").
      ExrCompression lossless = o.exr.compression;
      if (lossless == ExrCompression::Dwaa) lossless = ExrCompression::Zip;
      if (lossless == ExrCompression::Rle) lossless = ExrCompression::None;
      std::vector<std::string> channels = {"patch_id", "u", "v", "w"};
      if (w.textures.aov.channels == 5) channels.push_back("layer");  // exemplar layers: the patch's
      write_exr(names_.frame_file("aov", f), w.textures.aov, channels,
                {ExrPixelType::Float, lossless}, &staged);
    });
  jobs.push_back([&] {
    UvMeshMaterial material;
    material.name = o.name;
    material.color_texture = fs::path(color).filename().string();
    material.displacement_texture = fs::path(disp).filename().string();
    write_uv_mesh_obj(obj, w.surface->mesh, w.atlas, material, &staged);
  });
  if (o.usd)
    jobs.push_back([&] {
      write_usd_frame_layer(names_.frame_file("usd", f), f, w.surface->mesh, w.atlas, surface_velocities(*w.surface),
                            &staged);
    });
  if (o.dump_patches) jobs.push_back([&] { write_patches_ply(names_.frame_file("patches", f), w.patches, &staged); });
  // The state goes into the same group: a frame with an OBJ has its state.
  if (!w.state.empty()) jobs.push_back([&] { write_bake_state(names_.frame_file("state", f), w.state, &staged); });
  if (o.background_write) {
    // One after the other on this thread (OpenEXR compresses on its own
    // pool): the writer must not take the TBB workers the next frame needs.
    for (const auto& job : jobs) job();
    write_record(w, staged);
    staged.commit(obj);
    remove_old_state(f);
    write_usd_stage_file();
    return clock.lap();
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
    if (e) std::rethrow_exception(e);  // `staged` removes the frame's temporary files
  write_record(w, staged);
  // The OBJ is the frame's commit file: renamed last, after every other file.
  staged.commit(obj);
  remove_old_state(f);
  write_usd_stage_file();
  return clock.lap();
}

void FrameWriter::write_usd_stage_file() const {
  const BakeOptions& o = options_;
  if (!o.usd || o.track_only) return;
  // Several processes of a render write frames into one folder: each
  // rewrites the stage under its lock from what is on disk, so the last one
  // names every frame.
  const std::string lock_path = names_.shot_file("usd-lock");
  auto taken = FileLock::take_within(lock_path, "usd stage", std::chrono::seconds(60));
  if (const LockOwner* owner = std::get_if<LockOwner>(&taken))
    throw OutputError(lock_path + ": the USD stage stays locked by " + owner->describe());
  UsdStage stage;
  stage.name = o.name;
  stage.fps = o.fps;
  stage.up_axis = o.up_axis;
  stage.displacement_scale = 0.1 * o.patch.radius;
  stage.clip_manifest = fs::path(names_.shot_file("usd-clips")).filename().string();
  std::error_code ec;
  for (int f : names_.frames) {
    const std::string layer = names_.frame_file("usd", f);
    if (!fs::exists(layer, ec) || !fs::exists(names_.frame_file("obj", f), ec)) continue;
    auto file = [&](const char* kind) { return fs::path(names_.frame_file(kind, f)).filename().string(); };
    stage.frames.push_back({f, file("usd"), file("color"), file("disp")});
  }
  if (stage.frames.empty()) return;
  write_usd_clip_manifest(names_.shot_file("usd-clips"));
  write_usd_stage(names_.shot_file("usd"), stage);
}

void FrameWriter::write_record(const Job& w, StagedFiles& staged) const {
  RenderRecord record = w.record;
  const std::string state = names_.frame_file("state", w.frame), patches = names_.frame_file("patches", w.frame);
  for (const auto& [path, size] : staged.sizes())
    if (path != state && path != patches) record.files.emplace_back(fs::path(path).filename().string(), size);
  write_text_atomically(names_.frame_file("render", w.frame), encode_render_record(record), &staged);
}

void FrameWriter::remove_old_state(int frame) const {
  // Only once this frame's state is in place: there is always one to resume from.
  const int keep = options_.keep_states;
  if (keep <= 0 || options_.track_only) return;
  const std::vector<int>& frames = names_.frames;
  const auto at = std::find(frames.begin(), frames.end(), frame);
  if (at - frames.begin() < keep) return;
  std::error_code ec;
  fs::remove(names_.frame_file("state", *(at - keep)), ec);
}

void FrameWriter::write(const std::shared_ptr<Frame>& frame, const PatchSet& patches, double compute_seconds,
                        std::optional<uint32_t> patches_crc, std::optional<FileLock> lock) {
  auto job = std::make_shared<Job>();
  job->frame = frame->number;
  if (!options_.track_only) {
    if (!lock) {
      const std::string path = names_.frame_file("lock", frame->number);
      auto taken = FileLock::try_take(path, "bake");
      if (const LockOwner* owner = std::get_if<LockOwner>(&taken))
        throw InputError(path, fmt::format("frame {} is being written by {} ({}): wait for it, or write into "
                                           "another folder", frame->number, owner->describe(),
                                           owner->purpose.empty() ? "lapflow" : owner->purpose));
      lock = std::move(std::get<FileLock>(taken));
    }
    job->lock = std::move(lock);
    job->record = make_render_record(options_, names_, frame->number, exemplar_digest_);
    job->record.patches_crc = patches_crc;
  }
  job->textures = std::move(frame->textures);
  if (!job->textures.color_half.bits.empty()) {
    // Made in half by the resolve (RasterOptions::half_images).
    job->color_half = std::move(job->textures.color_half);
    job->displacement_half = std::move(job->textures.displacement_half);
  } else if (options_.exr.type == ExrPixelType::Half && !job->textures.color.empty()) {
    // The same conversion write_exr does, done now: the files are written
    // (or wait for the writer) from half the bytes, and the floats go back to
    // the heap for the next frame's images before the writes begin.
    // One image at a time: each float is freed before the next is converted.
    job->color_half = to_half_image(job->textures.color);
    job->textures.color = Image();
    job->displacement_half = to_half_image(job->textures.displacement);
    job->textures.displacement = Image();
  }
  job->atlas = std::move(frame->atlas);
  // The OBJ needs the charts and corner uvs, not the texel map (8 bytes a
  // chart texel), which no later step reads either.
  job->atlas.texels = TexelMap{};
  job->surface = frame;
  if (options_.dump_patches) job->patches = patches;
  if (options_.keep_states != 0 || options_.track_only) {
    Stopwatch clock;
    BakeStateHeader header;
    header.name = options_.name;
    header.frame = frame->number;
    header.options_checksum = options_checksum_;
    header.layers = int(std::max<std::size_t>(1, options_.layers.size()));
    header.stats_line = stats_line_without_timings(frame->stats);
    header.mesh = stamp_input_file(FramePattern(options_.mesh_pattern).path(frame->number));
    job->state = encode_bake_state(header, patches);
    if (!options_.track_only) job->record.patches_crc = bake_state_patches_crc(job->state);
    frame->stats.seconds_state = clock.lap();
  }
  finish();  // at most one frame in flight: bounds memory to two frames of images
  pending_stats_ = frame->stats;
  pending_compute_seconds_ = compute_seconds;
  pending_ = std::async(std::launch::async, [this, job] {
    const double seconds = write_files(*job);
    job->lock.reset();  // the frame's files are in place
    return seconds;
  });
  if (!options_.background_write) finish();
}

void FrameWriter::finish() {
  if (!pending_.valid()) return;
  Stopwatch wait;
  pending_stats_.seconds_write = pending_.get();  // rethrows a write error
  // Wall time the frame cost the bake: its computation plus the wait for
  // its files beyond the next frame's computation (frames sum to the bake).
  pending_stats_.seconds_total = pending_compute_seconds_ + wait.lap();
  pending_stats_.peak_rss_mb = peak_rss_mb();
  if (stats_file_) {
    stats_text_ += stats_json(pending_stats_).dump() + "\n";
    write_text_atomically(stats_path_, stats_text_);
  }
  last_complete_frame_ = pending_stats_.frame;
  note_complete_frame(pending_stats_.frame);
  if (on_frame_) on_frame_(pending_stats_);
}

}  // namespace lapflow::detail
