// lapflow_bench replay: one frame of a finished bake computed again several
// times in one process, the tracking from the previous frame's state and the
// output from its result, each step timed. A bake's frame times share the
// two cores with the reader (atlases) and the writer (EXR): fine for the
// whole bake, too noisy to tell a small change in one step. Here nothing else
// runs, the inputs stay in memory, and every repeat must give the same
// images and the same patches (a digest of both is printed).
#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <vector>

#include "bench.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow::bench {
namespace {

// The digest of the images and of the patches' ids, births and vertices (a
// change anywhere changes it).
uint64_t digest(const Frame& frame, const PatchSet& patches) {
  uint64_t h = kFnvOffset;
  for (const Image* img : {&frame.textures.color, &frame.textures.displacement, &frame.textures.aov})
    h = fnv1a(img->pixels.data(), img->pixels.size() * sizeof(float), h);
  for (const HalfImage* img : {&frame.textures.color_half, &frame.textures.displacement_half})
    h = fnv1a(img->bits.data(), img->bits.size() * sizeof(uint16_t), h);
  for (const Patch& p : patches.patches) {
    h = fnv1a(&p.id, sizeof p.id, h);
    h = fnv1a(&p.birth_frame, sizeof p.birth_frame, h);
    h = fnv1a(p.positions.data(), p.positions.size() * sizeof(Vec3), h);
  }
  return h;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

}  // namespace

void bench_replay(const std::string& dir, int frame_number, int repeats) {
  const BakeManifest manifest = read_bake_manifest(dir);
  const auto at = std::find(manifest.frames.begin(), manifest.frames.end(), frame_number);
  if (at == manifest.frames.end())
    throw UsageError(fmt::format("replay: frame {} is not a frame of {}", frame_number, dir));
  BakeOptions o = bake_options_from_manifest(manifest);
  o.frames = FrameRange{manifest.frames.front(), manifest.frames.back()};
  o.units_ok = true;  // the bake checked them
  resolve_bake_options(o);
  const BakeExemplars exemplars = load_bake_exemplars(o);
  const ExemplarLayers layers = exemplars.layers();
  const FrameSource source = frame_source(o);

  // The previous frame's state and velocity (none before the first frame:
  // the replay seeds).
  PatchSet start;
  std::shared_ptr<const Frame> previous;
  if (at != manifest.frames.begin()) {
    const int p = *(at - 1);
    const std::string path = manifest.frame_file("state", p);
    const BakeState state = read_bake_state(path);
    check_bake_state(state, path, manifest, p);
    start = state.patches;
    previous = load_frame(source, p);
  }
  const std::shared_ptr<Frame> frame = load_frame(source, frame_number);
  build_frame_atlases(*frame, o);
  const FrameStats fresh = frame->stats;

  fmt::print("replay of {} frame {}: {} triangles, {} patches before, tracking {}^2, output {}^2, {} threads\n", dir,
             frame_number, frame->mesh.triangle_count(), start.patches.size(), frame->tracking_atlas.resolution,
             frame->atlas.resolution, thread_count());
  const char* names[] = {"advect", "weights", "seed", "t.draw", "t.holes", "t.resolve", "t.retire",
                         "draw",   "holes",   "resolve", "dilate", "total"};
  constexpr std::size_t kColumns = std::size(names);
  fmt::print("{:>4}", "run");
  for (const char* n : names) fmt::print(" {:>9}", n);
  fmt::print(" {:>8} {:>16}\n", "patches", "digest");
  std::vector<std::vector<double>> columns(kColumns);
  uint64_t first_digest = 0;
  for (int r = 0; r < repeats; ++r) {
    frame->stats = fresh;
    PatchSet patches = start;
    track_frame(*frame, previous.get(), patches, layers, o);
    render_frame(*frame, patches, layers, o);
    const FrameStats& s = frame->stats;
    const double row[kColumns] = {s.seconds_advect,         s.seconds_weights,          s.seconds_seed,
                                  s.tracking.seconds_draw,  s.tracking.seconds_holes,   s.tracking.seconds_resolve,
                                  s.tracking.seconds_retire, s.seconds_draw,            s.seconds_holes,
                                  s.seconds_resolve,        s.seconds_dilate,           0};
    double total = 0;
    fmt::print("{:>4}", r + 1);
    for (std::size_t c = 0; c < kColumns; ++c) {
      const double v = c + 1 < kColumns ? row[c] : total;
      total += v;
      columns[c].push_back(v);
      fmt::print(" {:>9.3f}", v);
    }
    const uint64_t d = digest(*frame, patches);
    fmt::print(" {:>8} {:016x}\n", patches.patches.size(), d);
    if (r == 0) first_digest = d;
    else if (d != first_digest)
      throw std::runtime_error("replay: a repeat gave other images or patches than the first");
  }
  for (const char* label : {"min", "median"}) {
    fmt::print("{:>4}", label);
    for (const auto& c : columns)
      fmt::print(" {:>9.3f}", label[1] == 'i' ? *std::min_element(c.begin(), c.end()) : median(c));
    fmt::print("\n");
  }
}

}  // namespace lapflow::bench
