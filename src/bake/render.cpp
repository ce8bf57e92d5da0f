// `lapflow render`: the output half of a bake from tracked patch states.
#include "lapflow/bake/render.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <thread>
#include <variant>

#include "bake/writer.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/bake/render_record.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/io/file_lock.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/core/stopwatch.hpp"

namespace lapflow {
namespace fs = std::filesystem;

namespace {

/// What --skip-done makes of frame `f` already in `out`: "" to skip it, else
/// why it is rendered again. Fills `differences` when a record says the
/// frame was made with other options.
std::string rerender_reason(const BakeManifest& out, int f, const RenderRecord& wanted,
                            std::vector<std::string>& differences) {
  std::error_code ec;
  const std::string obj = out.frame_file("obj", f), record_path = out.frame_file("render", f);
  if (!fs::exists(obj, ec)) return "not rendered yet";
  if (!fs::exists(record_path, ec))
    return fs::path(record_path).filename().string() + " is missing (a frame of an older lapflow, or damaged)";
  RenderRecord disk;
  try {
    disk = read_render_record(record_path);
  } catch (const InputError& e) {
    return std::string("its record is damaged: ") + e.what();
  }
  differences = render_record_differences(disk, wanted);
  if (!differences.empty()) {
    std::string text = "made with other options: ";
    for (std::size_t i = 0; i < differences.size(); ++i) text += (i ? "; " : "") + differences[i];
    return text;
  }
  return render_record_file_problem(out, disk);
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
  if (!r.exemplar_color.empty() && !o.layers.empty())
    throw UsageError("--exemplar: " + tracked_path + " was tracked with exemplar layers; swap one with --layer NAME=...");
  for (const ExemplarLayer& swap : r.layers) {
    auto at = std::find_if(o.layers.begin(), o.layers.end(), [&](const ExemplarLayer& l) { return l.name == swap.name; });
    if (at == o.layers.end()) {
      std::string names;
      for (const ExemplarLayer& l : o.layers) names += (names.empty() ? "" : ", ") + l.name;
      throw UsageError("--layer " + swap.name + ": " + tracked_path + " has no layer '" + swap.name + "'" +
                       (names.empty() ? std::string(" (it was tracked with one exemplar: use --exemplar)")
                                      : " (its layers: " + names + ")"));
    }
    *at = swap;
  }
  if (!r.exemplar_color.empty()) {
    o.exemplar_color = r.exemplar_color;
    o.exemplar_feature = r.exemplar_feature;
    o.exemplar_displacement = r.exemplar_displacement;
  }
  if (r.resolution > 0) o.atlas.resolution = r.resolution;
  if (r.aov) o.aov = *r.aov;
  if (r.usd) o.usd = *r.usd;
  if (!r.texture.empty()) set_bake_option(o, *find_bake_option("texture"), r.texture);
  if (r.up_axis) o.up_axis = *r.up_axis;
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

  const BakeExemplars exemplars = load_bake_exemplars(o);
  const std::string digest = exemplars.feature_digest();
  if (!tracked.feature_digest.empty() && tracked.feature_digest != digest) {
    if (o.layers.empty())
      throw InputError(o.exemplar_feature.empty() ? o.exemplar_color : o.exemplar_feature,
                       "this exemplar's feature map (digest " + digest + ") is not the one the patches of " +
                           tracked_path + " were tracked with (" + tracked.feature_digest +
                           "): its erosion would differ; give the tracked feature map with --feature, or track again");
    throw InputError(tracked_path, "the layers' feature maps (" + digest + ") are not the ones the patches were " +
                                       "tracked with (" + tracked.feature_digest +
                                       "): their erosion would differ; swap a layer only for one with its feature map");
  }
  const ExemplarLayers textures = exemplars.layers();

  detail::prepare_output_folder(o);  // also rid of the temporaries of killed runs
  std::error_code ec;
  BakeManifest out = make_bake_manifest(o, tracked.frames);
  // The tracking's options with the render's output ones (o came from the
  // tracked manifest), and the tracked feature map's digest.
  out.feature_digest = tracked.feature_digest;
  out.dir = fs::absolute(o.out_dir, ec).lexically_normal().string();
  if (bake_tracking_checksum(out) != bake_tracking_checksum(tracked)) {
    // A manifest edited by hand: a tracking option that does not hold as
    // written (a radius of 0 that the options resolve anew, ...).
    std::string keys;
    for (const std::string& d : bake_manifest_differences(tracked_path, out, true)) keys += (keys.empty() ? "" : "; ") + d;
    throw InputError(tracked_path, "its tracking options do not hold as written (" +
                                       (keys.empty() ? std::string("the checksum differs") : keys) +
                                       "): was it edited? Track again");
  }
  // The tracked manifest is the tracking's and is never rewritten; another
  // folder gets one (for eval and preview) when it has none of this tracking.
  // What each frame was rendered with is its record's to say.
  const bool same_folder = fs::equivalent(out.dir, tracked.dir, ec);
  const std::string out_path = bake_manifest_path(out.dir, out.name);
  if (!same_folder) {
    bool keep = false;
    if (fs::exists(out_path, ec)) {
      try {
        keep = bake_tracking_checksum(read_bake_manifest(out_path)) == bake_tracking_checksum(tracked);
      } catch (const InputError&) {
        keep = false;  // damaged: replaced
      }
    }
    if (!keep) write_bake_manifest(out, out_path);
  }

  FrameSource source = frame_source(o);  // meshes only (load_frame_surface)
  source.attributes.clear();             // the layers are in the states
  const std::string digest_of_exemplar = exemplars.digest();
  std::vector<std::string> missing;
  std::vector<std::pair<std::string, std::string>> refused;  // file, why
  std::map<int, std::string> reasons;                        // why a frame on disk is rendered again
  detail::FrameWriter writer(
      o, out,
      [&](const FrameStats& written) {
        if (on_frame) on_frame({written.frame, false, o.atlas.resolution, written, reasons[written.frame]});
      },
      /*stats_file=*/false);
  writer.set_exemplar_digest(digest_of_exemplar);

  // One frame under its lock. Returns false when another render of the same
  // options holds the lock (the frame is tried again at the end).
  const auto render_one = [&](int f, bool may_defer) -> bool {
    const std::string state_path = tracked.frame_file("state", f);
    if (!fs::exists(state_path, ec)) {
      missing.push_back(state_path);
      return true;
    }
    RenderRecord wanted = make_render_record(o, out, f, digest_of_exemplar);
    const std::string lock_path = out.frame_file("lock", f);
    auto taken = FileLock::try_take(lock_path, render_lock_purpose(wanted));
    if (const LockOwner* owner = std::get_if<LockOwner>(&taken)) {
      if (owner->purpose == render_lock_purpose(wanted)) {
        if (may_defer) return false;
        // Waiting for it: the other render writes this frame's very bytes.
        while (std::holds_alternative<LockOwner>(taken)) {
          if (const int signal = stop_signal()) {
            writer.finish();
            throw Interrupted(signal, writer.last_complete_frame());
          }
          std::this_thread::sleep_for(std::chrono::milliseconds(100));
          taken = FileLock::try_take(lock_path, render_lock_purpose(wanted));
        }
      } else {
        refused.emplace_back(lock_path, fmt::format("frame {} is being written by {} ({}), with other options "
                                                    "than this render's ({}): wait for it, or render into another "
                                                    "--out",
                                                    f, owner->describe(), owner->purpose, render_lock_purpose(wanted)));
        return true;
      }
    }
    FileLock lock = std::move(std::get<FileLock>(taken));
    std::string reason;
    if (r.skip_done) {
      wanted.patches_crc = bake_state_file_patches_crc(state_path);
      std::vector<std::string> differences;
      reason = rerender_reason(out, f, wanted, differences);
      if (reason.empty()) {
        if (on_frame) on_frame({f, true, o.atlas.resolution, {}, {}});
        return true;
      }
      if (!differences.empty() && r.refuse_other_options) {
        refused.emplace_back(out.frame_file("render", f),
                             "frame " + std::to_string(f) + " is already there, " + reason + " (--no-rerender)");
        return true;
      }
      if (reason != "not rendered yet") reasons[f] = reason;
    }
    if (const int signal = stop_signal()) {
      writer.finish();
      throw Interrupted(signal, writer.last_complete_frame());
    }
    Stopwatch frame_clock, clock;
    std::ifstream in(state_path, std::ios::binary);
    const std::string state_bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    if (!in.good() && !in.eof()) throw InputError(state_path, "cannot read the bake state");
    const BakeState state = parse_bake_state(state_bytes, state_path);
    check_bake_state(state, state_path, tracked, f);
    if (state.header.mesh && !r.allow_changed_input) {
      const std::string mesh = FramePattern(o.mesh_pattern).path(f);
      const InputStamp now = stamp_input_file(mesh), then = *state.header.mesh;
      if (now.bytes != then.bytes || now.crc != then.crc)
        throw InputError(mesh, fmt::format("changed since frame {} was tracked ({} bytes, CRC {:08x}; tracked: {} "
                                           "bytes, CRC {:08x}): its patches would not fit it; track again, or "
                                           "render with --allow-changed-input",
                                           f, now.bytes, now.crc, then.bytes, then.crc), f);
    }
    const PatchSet& patches = state.patches;
    const std::shared_ptr<Frame> frame = load_frame_surface(source, f, o.usd);
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
    // On disk when it returns, then on_frame; the lock goes with the files.
    writer.write(frame, patches, frame_clock.total(), bake_state_patches_crc(state_bytes), std::move(lock));
    return true;
  };
  std::vector<int> deferred;
  for (int f : frames)
    if (!render_one(f, true)) deferred.push_back(f);
  for (int f : deferred) render_one(f, false);
  writer.finish();
  writer.write_usd_stage_file();  // also when every frame was skipped
  if (!refused.empty())
    throw InputError(refused.front().first,
                     refused.front().second + (refused.size() > 1
                                                   ? fmt::format(" (and {} more frames refused)", refused.size() - 1)
                                                   : std::string()));
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
