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

/// The settings of a manifest, read back: a missing key keeps the default
/// (a manifest older than the setting), a malformed one is an InputError.
class Settings {
 public:
  explicit Settings(const BakeManifest& m) : m_(m), path_(bake_manifest_path(m.dir, m.name)) {}

  void read(const std::string& key, double& value) const {
    if (const std::string* t = find(key)) {
      const char* end = t->data() + t->size();
      const auto [ptr, ec] = std::from_chars(t->data(), end, value);
      if (ec != std::errc() || ptr != end) bad(key, *t, "a number");
    }
  }
  template <class Int>
    requires std::is_integral_v<Int>
  void read(const std::string& key, Int& value) const {
    if (const std::string* t = find(key)) {
      if (*t == "true" || *t == "false") {
        if constexpr (std::is_same_v<Int, bool>) {
          value = *t == "true";
          return;
        }
        bad(key, *t, "a whole number");
      }
      if constexpr (std::is_same_v<Int, bool>) {
        bad(key, *t, "true or false");
      } else {
        const char* end = t->data() + t->size();
        const auto [ptr, ec] = std::from_chars(t->data(), end, value);
        if (ec != std::errc() || ptr != end) bad(key, *t, "a whole number");
      }
    }
  }
  /// An enumeration stored as its number, below `count`.
  template <class Enum>
  void read_enum(const std::string& key, Enum& value, int count) const {
    int n = int(value);
    read(key, n);
    if (n < 0 || n >= count) bad(key, std::to_string(n), "one of the known values");
    value = Enum(n);
  }
  /// A rule added after the first manifests: on when the manifest says so,
  /// off when the manifest predates it (the bake that wrote it ran without).
  template <class T>
  void read_later_rule(const std::string& key, T& value) const {
    value = T(0);
    read(key, value);
  }
  const std::string* find(const std::string& key) const {
    const auto at = m_.settings.find(key);
    return at == m_.settings.end() ? nullptr : &at->second;
  }

 private:
  [[noreturn]] void bad(const std::string& key, const std::string& text, const char* expected) const {
    throw InputError(path_, "settings." + key + ": '" + text + "' is not " + expected);
  }
  const BakeManifest& m_;
  std::string path_;
};

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
  BakeOptions o;
  const Settings s(m);
  o.mesh_pattern = m.mesh_pattern;
  o.velocity_vdb_pattern = m.velocity_vdb_pattern;
  o.velocity_grid = m.velocity_grid;
  if (!m.frames.empty()) o.frames = FrameRange{m.frames.front(), m.frames.back()};
  o.fps = m.fps;
  o.min_speed = m.min_speed;
  o.allow_zero_velocity = m.allow_zero_velocity;
  o.exemplar_color = m.exemplar_color;
  o.exemplar_feature = m.exemplar_feature;
  o.exemplar_displacement = m.exemplar_displacement;
  o.out_dir = m.dir;
  o.name = m.name;
  o.aov = m.aov;
  o.dump_patches = m.dump_patches;
  o.seed = m.seed;
  try {
    o.raster.mode = parse_raster_mode(m.mode);
  } catch (const UsageError&) {
    throw InputError(bake_manifest_path(m.dir, m.name), "mode: '" + m.mode + "' is not erosion, blend or advect");
  }
  o.patch.radius = m.radius;
  o.raster.epsilon = m.epsilon;
  o.raster.hold = m.hold;
  o.raster.hold_margin = m.hold_margin;
  o.raster.small_hole = m.small_hole;
  o.raster.rest_hole = m.rest_hole;
  o.raster.merge = m.merge;
  o.weights.delta_max = m.delta_max;
  o.atlas.resolution = m.resolution;
  s.read("velocity_band", o.velocity_band);
  s.read("velocity_voxel", o.velocity_voxel);
  s.read("spacing", o.seeding.spacing);
  s.read("remesh", o.patch.remesh);
  s.read_enum("remesher", o.patch.remesher, 3);
  s.read("remesh_edge", o.patch.remesh_edge);
  s.read("anticipate", o.patch.anticipate);
  s.read("anticipate_horizon", o.patch.anticipate_horizon);
  s.read("advect_max_step_fraction", o.advect.max_step_fraction);
  s.read("advect_max_turn", o.advect.max_turn);
  s.read("advect_max_projection", o.advect.max_projection);
  s.read_later_rule("advect_through_flow", o.advect.through_flow);  // stop 29
  s.read_later_rule("advect_run_off", o.advect.run_off);             // stop 31
  s.read("center_radius", o.weights.center_radius);
  s.read("gutter", o.atlas.gutter);
  s.read("max_stretch", o.atlas.max_stretch);
  s.read("fill_holes", o.raster.fill_holes);
  s.read("retire", o.raster.retire);
  s.read_later_rule("rest_bound", o.raster.rest_bound);  // stop 30
  s.read("mipmap", o.raster.mipmap);
  s.read("trilinear", o.raster.trilinear);
  s.read("dilate", o.raster.dilate);
  s.read("max_hole_patches", o.raster.max_hole_patches);
  s.read_enum("exr_type", o.exr.type, 2);
  s.read_enum("exr_compression", o.exr.compression, 5);
  s.read("track_texel", o.track_texel);
  if (const std::string* align = s.find("align"); align && *align != "random") {
    Vec3& d = o.patch.align_direction;
    if (std::sscanf(align->c_str(), "%lf,%lf,%lf", &d.x, &d.y, &d.z) != 3)
      throw InputError(bake_manifest_path(m.dir, m.name), "settings.align: '" + *align + "' is not x,y,z");
    o.patch.align = true;
  }
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
  if (const auto at = tracked.settings.find("feature_digest"); at != tracked.settings.end() && at->second != digest)
    throw InputError(o.exemplar_feature.empty() ? o.exemplar_color : o.exemplar_feature,
                     "this exemplar's feature map (digest " + digest + ") is not the one the patches of " +
                         tracked_path + " were tracked with (" + at->second +
                         "): its erosion would differ; give the tracked feature map with --feature, or track again");
  const RasterExemplar textures = prepare_raster_exemplar(exemplar, o.raster.epsilon);

  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) throw OutputError(o.out_dir + ": cannot create the output folder (--out): " + ec.message());
  BakeManifest out = make_bake_manifest(o, tracked.frames);
  // The tracking's settings (its feature digest too), with the render's
  // output ones.
  std::map<std::string, std::string> settings = tracked.settings;
  for (const auto& [key, value] : out.settings)
    if (key == "gutter" || key == "mipmap" || key == "trilinear" || key == "dilate" || key.starts_with("exr_"))
      settings[key] = value;
  out.settings = std::move(settings);
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
