// `lapflow render`: the output half of a bake from tracked patch states.
#include "lapflow/bake/render.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cstdio>
#include <map>
#include <filesystem>

#include "bake/writer.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/core/stopwatch.hpp"

namespace lapflow {
namespace fs = std::filesystem;

namespace {

/// --skip-done: the frame's OBJ is in the output folder, newer than its
/// state, from a render whose manifest there had the same options.
bool already_rendered(const BakeManifest& out, int frame, const std::string& state, bool same_options) {
  if (!same_options) return false;
  std::error_code ec;
  const fs::path obj = out.frame_file("obj", frame);
  if (!fs::exists(obj, ec)) return false;
  const auto obj_time = fs::last_write_time(obj, ec);
  if (ec) return false;
  const auto state_time = fs::last_write_time(state, ec);
  return !ec && obj_time >= state_time;
}

}  // namespace

BakeOptions bake_options_from_manifest(const BakeManifest& m) {
  BakeOptions o = m.options;
  o.out_dir = m.dir;
  o.name = m.name;
  if (!m.frames.empty()) o.frames = FrameRange{m.frames.front(), m.frames.back()};
  return o;
}

void render(const RenderOptions& r, const std::function<void(const RenderedFrame&)>& on_frame) {
  const BakeManifest tracked = read_bake_manifest(r.dir, r.name);
  const std::string tracked_path = bake_manifest_path(tracked.dir, tracked.name);
  BakeOptions o = bake_options_from_manifest(tracked);
  if (!r.exemplar_color.empty()) {
    o.exemplar_color = r.exemplar_color;
    o.exemplar_feature = r.exemplar_feature;
    o.exemplar_displacement = r.exemplar_displacement;
  }
  if (r.resolution > 0) o.atlas.resolution = r.resolution;
  if (r.aov) o.aov = *r.aov;
  if (!r.out_dir.empty()) o.out_dir = r.out_dir;
  o.max_memory = r.max_memory;
  // The render keeps no state and dumps no patches.
  o.units_ok = true;  // the tracking checked them
  o.keep_states = 0;
  o.dump_patches = false;
  o.track_only = false;
  o.resume = false;
  std::vector<int> frames;
  for (int f : tracked.frames)
    if (!r.frames || (f >= r.frames->first && f <= r.frames->last)) frames.push_back(f);
  if (frames.empty())
    throw UsageError(fmt::format("--frames {}-{}: no frame of the tracked sequence ({}-{}) is in that range",
                                 r.frames ? r.frames->first : 0, r.frames ? r.frames->last : 0,
                                 tracked.frames.empty() ? 0 : tracked.frames.front(),
                                 tracked.frames.empty() ? 0 : tracked.frames.back()));
  o.frames = FrameRange{frames.front(), frames.back()};
  resolve_bake_options(o);  // the memory check; radius and resolution are set

  const Exemplar exemplar = load_exemplar(o.exemplar_color, o.exemplar_feature, o.exemplar_displacement);
  const std::string digest = exemplar_feature_digest(exemplar.feature);
  if (!tracked.feature_digest.empty() && tracked.feature_digest != digest)
    throw InputError(o.exemplar_feature.empty() ? o.exemplar_color : o.exemplar_feature,
                     "this exemplar's feature map (digest " + digest + ") is not the one the patches of " +
                         tracked_path + " were tracked with (" + tracked.feature_digest +
                         "): its erosion would differ; give the tracked feature map with --feature, or track again");
  const RasterExemplar textures = prepare_raster_exemplar(exemplar, o.raster.epsilon);

  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) throw OutputError(o.out_dir + ": cannot create the output folder (--out): " + ec.message());
  BakeManifest out = make_bake_manifest(o, tracked.frames);
  // The tracking's options with the render's output ones (o came from the
  // tracked manifest), and the tracked feature map's digest.
  out.feature_digest = tracked.feature_digest;
  out.dir = fs::absolute(o.out_dir, ec).lexically_normal().string();
  const std::string out_path = bake_manifest_path(out.dir, out.name);
  bool same_options = false;
  if (r.skip_done && fs::exists(out_path, ec)) {
    try {
      same_options = bake_manifest_differences(out_path, out).empty();
    } catch (const InputError&) {
      same_options = false;  // a damaged manifest: render again
    }
  }
  if (bake_tracking_checksum(out) != bake_tracking_checksum(tracked))
    throw std::logic_error("render: the output manifest changed the tracking's options");
  write_bake_manifest(out, out_path);

  const FrameSource source = frame_source(o);  // meshes only (load_frame_surface)
  std::vector<std::string> missing;
  detail::FrameWriter writer(
      o, out, [&](const FrameStats& written) { if (on_frame) on_frame({written.frame, false, o.atlas.resolution, written}); },
      /*stats_file=*/false);
  for (int f : frames) {
    const std::string state_path = tracked.frame_file("state", f);
    if (!fs::exists(state_path, ec)) {
      missing.push_back(state_path);
      continue;
    }
    if (already_rendered(out, f, state_path, same_options)) {
      if (on_frame) on_frame({f, true, o.atlas.resolution, {}});
      continue;
    }
    if (const int signal = stop_signal()) {
      writer.finish();
      throw Interrupted(signal, writer.last_complete_frame());
    }
    Stopwatch frame_clock, clock;
    const BakeState state = read_bake_state(state_path);
    check_bake_state(state, state_path, tracked, f);
    const PatchSet& patches = state.patches;
    const std::shared_ptr<Frame> frame = load_frame_surface(source, f);
    FrameStats& st = frame->stats;
    st.seconds_read = clock.lap();
    frame->atlas = build_surface_atlas(frame->mesh, o.atlas);
    st.seconds_atlas = clock.lap();
    // As the bake draws its output: the frame's patches, no birth.
    render_frame(*frame, patches, textures, o);
    st.frame = f;
    st.triangles = frame->mesh.triangle_count();
    st.vertices = frame->mesh.vertex_count();
    st.patches_alive = patches.patches.size();
    writer.write(frame, patches, frame_clock.total());  // on disk when it returns, then on_frame
  }
  writer.finish();
  if (!missing.empty())
    throw InputError(missing.front(), fmt::format("no patch state for this frame{}: track it first (lapflow track "
                                                  "... --out {})",
                                                  missing.size() > 1
                                                      ? fmt::format(" (nor for {} more of the frames asked for)",
                                                                    missing.size() - 1)
                                                      : "",
                                                  tracked.dir));
}

}  // namespace lapflow
