// The table of the bake's options (lapflow/bake/options.hpp).
#include "lapflow/bake/options.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <regex>
#include <stdexcept>

#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/memory.hpp"

namespace lapflow {

namespace {

// A repeatable option's text: ';' separates several values, each replaces
// the one of its name in `list` or comes last; an empty text clears it.
template <class T, class Parse, class Name>
void set_named(std::vector<T>& list, const std::string& text, Parse parse, Name name_of) {
  if (text.empty()) list.clear();
  for (std::size_t at = 0; at < text.size();) {
    const std::size_t end = std::min(text.find(';', at), text.size());
    T item = parse(text.substr(at, end - at));
    auto same = std::find_if(list.begin(), list.end(), [&](const T& x) { return name_of(x) == name_of(item); });
    if (same != list.end())
      *same = std::move(item);
    else
      list.push_back(std::move(item));
    at = end + 1;
  }
}

template <class T>
using Field = T& (*)(BakeOptions&);

[[noreturn]] void not_(const std::string& expected) { throw std::invalid_argument(expected); }

double parse_number(const std::string& t) {
  double v = 0;
  const char* end = t.data() + t.size();
  const auto [ptr, ec] = std::from_chars(t.data(), end, v);
  if (t.empty() || ec != std::errc() || ptr != end || !std::isfinite(v)) not_("a number");
  return v;
}

template <class Int>
Int parse_whole(const std::string& t) {
  Int v = 0;
  const char* end = t.data() + t.size();
  const auto [ptr, ec] = std::from_chars(t.data(), end, v);
  if (t.empty() || ec != std::errc() || ptr != end) not_("a whole number");
  return v;
}

bool parse_bool(const std::string& t) {
  if (t == "true") return true;
  if (t == "false") return false;
  not_("true or false");
}

std::string text(double v) { return fmt::format("{}", v); }

/// The entries, built field by field.
class Table {
 public:
  BakeOption& number(std::string name, Field<double> f) {
    BakeOption& o = add(std::move(name), OptionKind::Number);
    o.get = [f](const BakeOptions& b) { return text(f(const_cast<BakeOptions&>(b))); };
    o.set = [f](BakeOptions& b, const std::string& t) { f(b) = parse_number(t); };
    return o;
  }
  template <class Int>
  BakeOption& integer(std::string name, Field<Int> f) {
    BakeOption& o = add(std::move(name), OptionKind::Integer);
    o.get = [f](const BakeOptions& b) { return fmt::format("{}", f(const_cast<BakeOptions&>(b))); };
    o.set = [f](BakeOptions& b, const std::string& t) { f(b) = parse_whole<Int>(t); };
    return o;
  }
  BakeOption& flag(std::string name, Field<bool> f) {
    BakeOption& o = add(std::move(name), OptionKind::Flag);
    o.get = [f](const BakeOptions& b) { return f(const_cast<BakeOptions&>(b)) ? "true" : "false"; };
    o.set = [f](BakeOptions& b, const std::string& t) { f(b) = parse_bool(t); };
    return o;
  }
  BakeOption& string(std::string name, OptionKind kind, Field<std::string> f) {
    BakeOption& o = add(std::move(name), kind);
    o.get = [f](const BakeOptions& b) { return f(const_cast<BakeOptions&>(b)); };
    o.set = [f](BakeOptions& b, const std::string& t) { f(b) = t; };
    return o;
  }
  /// An enumeration spelled by `words` on the command line (words[i] is
  /// value i; `aliases` are older spellings) and by its number in the manifest.
  template <class Enum>
  BakeOption& choice(std::string name, Field<Enum> f, std::vector<std::pair<std::string, Enum>> words) {
    BakeOption& o = add(std::move(name), OptionKind::Choice);
    // A word whose value an earlier word has is an old spelling: accepted, not shown.
    std::vector<Enum> shown;
    for (const auto& [word, value] : words)
      if (std::find(shown.begin(), shown.end(), value) == shown.end()) shown.push_back(value), o.choices.push_back(word);
    o.get = [f, words](const BakeOptions& b) {
      for (const auto& [word, value] : words)
        if (value == f(const_cast<BakeOptions&>(b))) return word;
      return std::string();
    };
    o.set = [f, words, expected = fmt::format("one of {}", fmt::join(o.choices, ", "))](BakeOptions& b,
                                                                                      const std::string& t) {
      for (const auto& [word, value] : words)
        if (word == t) {
          f(b) = value;
          return;
        }
      not_(expected);
    };
    return o;
  }
  /// The manifest records the enumeration as its number, below `count`.
  template <class Enum>
  static void recorded_as_number(BakeOption& o, Field<Enum> f, int count) {
    o.manifest_get = [f](const BakeOptions& b) { return fmt::format("{}", int(f(const_cast<BakeOptions&>(b)))); };
    o.manifest_set = [f, count](BakeOptions& b, const std::string& t) {
      const int n = parse_whole<int>(t);
      if (n < 0 || n >= count) not_("one of the known values");
      f(b) = Enum(n);
    };
  }

  BakeOption& add(std::string name, OptionKind kind) {
    BakeOption& o = entries.emplace_back();
    o.name = std::move(name);
    o.kind = kind;
    return o;
  }

  std::vector<BakeOption> entries;
};

std::vector<BakeOption> make_table() {
  Table t;
  using S = OptionStage;
  using E = OptionEffect;
  const auto in = [](BakeOption& o, S stage, E effect, std::string help) -> BakeOption& {
    o.stage = stage;
    o.effect = effect;
    o.help = std::move(help);
    return o;
  };

  // Input
  {
    BakeOption& o = in(t.string("mesh", OptionKind::Path, [](BakeOptions& b) -> auto& { return b.mesh_pattern; }),
                       S::Input, E::Animation,
                       "Per-frame meshes: name.%04d.ply, name.####.ply, name.$F4.ply or name.$F.ply (PLY or OBJ)");
    o.manifest_key = "mesh";
    o.absent = "";
    o.example = "sim/fluid.%04d.ply";
  }
  {
    BakeOption& o = in(t.add("frames", OptionKind::Text), S::Input, E::Animation,
                       "Frame range A-B (default: every frame found on disk)");
    o.get = [](const BakeOptions& b) {
      return b.frames ? fmt::format("{}-{}", b.frames->first, b.frames->last) : std::string();
    };
    o.set = [](BakeOptions& b, const std::string& t) {
      try {
        b.frames = parse_frame_range(t);
      } catch (const std::exception&) {
        not_("a frame range A-B");
      }
    };
    o.example = "3-40";
  }
  {
    BakeOption& o = in(t.string("velocity-vdb", OptionKind::Path,
                                [](BakeOptions& b) -> auto& { return b.velocity_vdb_pattern; }),
                       S::Input, E::Animation,
                       "Per-frame OpenVDB velocity files (default: per-vertex vx vy vz of the meshes)");
    o.manifest_key = "velocity_vdb";
    o.absent = "";
    o.example = "sim/vel.%04d.vdb";
  }
  {
    BakeOption& o = in(t.string("velocity-grid", OptionKind::Text,
                                [](BakeOptions& b) -> auto& { return b.velocity_grid; }),
                       S::Input, E::Animation, "Grid name in the VDB files (default: vel, v, velocity)");
    o.manifest_key = "velocity_grid";
    o.absent = "";
    o.example = "flow";
  }
  {
    BakeOption& o = in(t.number("fps", [](BakeOptions& b) -> auto& { return b.fps; }), S::Input, E::Animation,
                       "Frames per second; dt = 1/fps");
    o.unit = "1/s";

    o.manifest_key = "fps";
    o.absent = "24";
    o.example = "30";
  }
  {
    BakeOption& o = in(t.number("min-speed", [](BakeOptions& b) -> auto& { return b.min_speed; }), S::Input,
                       E::Animation, "Velocities slower than this count as zero: stops creep at rest");
    o.unit = "m/s";

    o.manifest_key = "min_speed";
    o.absent = "0";
    o.example = "0.05";
  }
  {
    BakeOption& o = in(t.flag("allow-zero-velocity", [](BakeOptions& b) -> auto& { return b.allow_zero_velocity; }),
                       S::Input, E::Animation, "Accept meshes without velocity (a still texture)");
    o.manifest_key = "allow_zero_velocity";
    o.absent = "false";
  }
  in(t.flag("units-ok", [](BakeOptions& b) -> auto& { return b.units_ok; }), S::Input, E::Neither,
     units_ok_help("bake"));
  {
    BakeOption& o = in(t.integer<int>("velocity-band", [](BakeOptions& b) -> auto& { return b.velocity_band; }),
                       S::Input, E::Animation,
                       "Per-vertex velocity is sampled once per frame on voxels within N voxels of the surface and "
                       "read trilinearly; 0 = exact closest-point sampling everywhere (slower)");
    o.unit = "voxels";
    o.range = {0, 16};
    o.manifest_key = "settings/velocity_band";
    o.example = "3";
  }
  {
    BakeOption& o = in(t.number("velocity-voxel", [](BakeOptions& b) -> auto& { return b.velocity_voxel; }),
                       S::Input, E::Animation, "Voxel size of that band, in mean edge lengths of the frame's mesh");
    o.unit = "edges";
    o.range = {0.25, 16.0};
    o.manifest_key = "settings/velocity_voxel";
    o.example = "1.5";
  }

  // Exemplar
  {
    BakeOption& o = in(t.string("exemplar", OptionKind::Path, [](BakeOptions& b) -> auto& { return b.exemplar_color; }),
                       S::Exemplar, E::Picture,
                       "Colour exemplar (PNG/JPEG/TIFF/EXR), or the name of a shipped exemplar (pebbles, lava, "
                       "squares, scales, foam)");
    o.manifest_key = "exemplar/color";
    o.absent = "";
    o.example = "maps/rock.color.png";
  }
  {
    BakeOption& o = in(t.string("feature", OptionKind::Path, [](BakeOptions& b) -> auto& { return b.exemplar_feature; }),
                       S::Exemplar, E::Picture,
                       "Feature map in [0,1], same aspect (default: NAME.feature.* beside the exemplar); the "
                       "erosion follows it, so the tracking records its digest");
    o.manifest_key = "exemplar/feature";
    o.absent = "";
    o.example = "maps/rock.feature.png";
  }
  {
    BakeOption& o = in(t.string("displacement", OptionKind::Path,
                                [](BakeOptions& b) -> auto& { return b.exemplar_displacement; }),
                       S::Exemplar, E::Picture,
                       "Displacement map (default: NAME.disp.* beside the exemplar, else the feature map)");
    o.manifest_key = "exemplar/displacement";
    o.absent = "";
    o.example = "maps/rock.disp.exr";
  }

  {
    BakeOption& o = in(t.add("layer", OptionKind::Text), S::Exemplar, E::Picture,
                       "An exemplar layer NAME=COLOR[,FEATURE[,DISP]] (repeatable; the files as with --exemplar): "
                       "with --where, the layers' rules choose one where each patch is born; the last is the "
                       "default (docs/layers.md)");
    o.get = [](const BakeOptions& b) {
      std::string text;
      for (const ExemplarLayer& l : b.layers) text += (text.empty() ? "" : ";") + layer_text(l);
      return text;
    };
    // Each layer replaces the one of its name (a render's swap) or comes last.
    o.set = [](BakeOptions& b, const std::string& t) {
      set_named(b.layers, t, parse_layer, [](const ExemplarLayer& l) { return l.name; });
    };
    o.repeatable = true;
    o.manifest_key = "exemplar/layers";
    o.absent = "";
    o.example = "foam=/maps/foam.png;calm=/maps/calm.png,/maps/calm.feature.png";  // absolute: as recorded
  }
  {
    BakeOption& o = in(t.add("where", OptionKind::Text), S::Exemplar, E::Animation,
                       "A layer's rule NAME:RULE (repeatable), e.g. 'foam:speed > 1.5 and curvature > 20': over "
                       "speed (m/s), curvature (1/m) and the PLY's vertex properties by name (docs/layers.md)");
    o.get = [](const BakeOptions& b) {
      std::string text;
      for (const auto& [name, rule] : b.layer_rules) text += (text.empty() ? "" : ";") + name + ":" + rule;
      return text;
    };
    o.set = [](BakeOptions& b, const std::string& t) {
      set_named(b.layer_rules, t, parse_layer_rule, [](const auto& r) { return r.first; });
    };
    o.repeatable = true;
    o.manifest_key = "layer_rules";
    o.absent = "";
    o.example = "foam:speed > 1.5";
  }
  {
    BakeOption& o = in(t.integer<int>("layer-switch", [](BakeOptions& b) -> auto& { return b.layer_switch; }),
                       S::Exemplar, E::Animation,
                       "Frames in a row a patch's centre lies where the rules choose another layer before it is "
                       "retired for that layer's patches (the lag of a changing region)");
    o.unit = "frames";
    o.range = {1, 1000};
    o.manifest_key = "settings/layer_switch";
    o.absent = "6";
    o.example = "3";
  }
  {
    BakeOption& o = in(t.number("exemplar-fps", [](BakeOptions& b) -> auto& { return b.exemplar_fps; }),
                       S::Exemplar, E::Animation,
                       "An animated exemplar's (an image sequence's) frames per second; 0 plays one exemplar frame "
                       "a bake frame. Each patch plays it from its birth with a phase of its own");
    o.unit = "1/s";
    o.range = {0, 10000};
    o.manifest_key = "settings/exemplar_fps";
    o.absent = "0";
    o.example = "12";
  }
  {
    const Field<ExemplarLoop> f = [](BakeOptions& b) -> auto& { return b.exemplar_loop; };
    BakeOption& o = in(t.choice<ExemplarLoop>("exemplar-loop", f,
                                              {{"loop", ExemplarLoop::Loop},
                                               {"ping-pong", ExemplarLoop::PingPong},
                                               {"hold", ExemplarLoop::Hold}}),
                       S::Exemplar, E::Animation,
                       "What an animated exemplar plays past its last frame: loop (from the first again), "
                       "ping-pong (backwards, then forwards) or hold (the last frame; every patch starts at the "
                       "first, so the frame is the patch's age)");
    o.manifest_key = "settings/exemplar_loop";
    o.absent = "loop";
    o.example = "ping-pong";
  }

  // Output
  {
    BakeOption& o = in(t.string("out", OptionKind::Path, [](BakeOptions& b) -> auto& { return b.out_dir; }),
                       S::Output, E::Neither, "Output folder (created)");
    o.example = "bake/shot";
  }
  {
    BakeOption& o = in(t.string("name", OptionKind::Text, [](BakeOptions& b) -> auto& { return b.name; }), S::Output,
                       E::Neither, "Output file prefix (default: the mesh pattern's name)");
    o.example = "shot";
    // The files are named after it inside --out: no path in it.
    o.set = [](BakeOptions& b, const std::string& text) {
      if (text == "." || text == ".." || text.find_first_of("/\\") != std::string::npos)
        throw std::invalid_argument("a file name (no folder: the files go in --out)");
      b.name = text;
    };
  }
  in(t.flag("resume", [](BakeOptions& b) -> auto& { return b.resume; }), S::Output, E::Neither,
     "Continue after the last complete frame in --out that has a state (NAME.state.N.bin), with the same options; "
     "bake from the first frame when there is none");
  {
    BakeOption& o = in(t.add("keep-states", OptionKind::Text), S::Output, E::Neither,
                       "Patch states kept in --out: the last N frames' (all, last = 1, none = 0: no --resume)");
    o.get = [](const BakeOptions& b) {
      return b.keep_states < 0 ? std::string("all") : fmt::format("{}", b.keep_states);
    };
    o.set = [](BakeOptions& b, const std::string& t) {
      if (t == "all") b.keep_states = -1;
      else if (t == "last") b.keep_states = 1;
      else if (t == "none") b.keep_states = 0;
      else {
        int n = -1;
        try {
          n = parse_whole<int>(t);
        } catch (const std::invalid_argument&) {
        }
        if (n < 0) not_("all, last, none or a count of frames");
        b.keep_states = n;
      }
    };
    o.example = "all";
  }
  in(t.flag("write-behind", [](BakeOptions& b) -> auto& { return b.background_write; }), S::Output, E::Neither,
     "Write each frame's files on another thread while the next frame computes (the same files; one more frame "
     "of images in memory, and a frame's stats line comes after the next frame's computation)");
  {
    BakeOption& o = in(t.flag("aov", [](BakeOptions& b) -> auto& { return b.aov; }), S::Output, E::Picture,
                       "Also write NAME.aov.N.exr: patch_id, u, v, w per texel");
    o.manifest_key = "aov";
    o.absent = "false";
  }
  {
    BakeOption& o = in(t.flag("dump-patches", [](BakeOptions& b) -> auto& { return b.dump_patches; }), S::Output,
                       E::Picture, "Also write the patches of every frame as NAME.patches.N.ply");
    o.manifest_key = "dump_patches";
    o.absent = "false";
  }
  {
    const Field<ExrLayout> f = [](BakeOptions& b) -> auto& { return b.exr.layout; };
    BakeOption& o = in(t.choice<ExrLayout>("texture", f, {{"scanline", ExrLayout::Scanline}, {"tiled", ExrLayout::TiledMipmap}}),
                       S::Output, E::Picture,
                       "Layout of the colour and displacement EXRs: scanline, or tiled: tiled and mip-mapped as "
                       "maketx makes them, which production renderers read without converting");
    o.manifest_key = "settings/texture";
    o.absent = "scanline";
    o.example = "tiled";
  }
  {
    BakeOption& o = in(t.flag("usd", [](BakeOptions& b) -> auto& { return b.usd; }), S::Output, E::Picture,
                       "Also write each frame as a USD layer (NAME.usd.N.usda) and the shot's stage NAME.usda, "
                       "which stitches them as value clips with the atlases as material");
    o.negatable = true;
    o.manifest_key = "usd";
    o.absent = "false";
  }
  {
    const Field<char> f = [](BakeOptions& b) -> auto& { return b.up_axis; };
    BakeOption& o = in(t.choice<char>("up-axis", f, {{"z", 'Z'}, {"y", 'Y'}}), S::Output, E::Picture,
                       "The USD stage's up axis: the simulation's (z: Blender, Mantaflow; y: Houdini, Maya)");
    o.manifest_key = "settings/up_axis";
    o.absent = "z";
    o.example = "y";
  }
  {
    const Field<ExrPixelType> f = [](BakeOptions& b) -> auto& { return b.exr.type; };
    BakeOption& o = in(t.choice<ExrPixelType>("exr-type", f, {{"half", ExrPixelType::Half}, {"float", ExrPixelType::Float}}),
                       S::Output, E::Picture, "EXR pixel type of colour and displacement");
    Table::recorded_as_number(o, f, 2);
    o.manifest_key = "settings/exr_type";
    o.example = "float";
  }
  {
    const Field<ExrCompression> f = [](BakeOptions& b) -> auto& { return b.exr.compression; };
    BakeOption& o = in(t.choice<ExrCompression>("compression", f,
                                                {{"rle", ExrCompression::Rle},
                                                 {"piz", ExrCompression::Piz},
                                                 {"zip", ExrCompression::Zip},
                                                 {"dwaa", ExrCompression::Dwaa},
                                                 {"none", ExrCompression::None}}),
                       S::Output, E::Picture,
                       "EXR compression: rle (lossless, fastest), piz (lossless, smaller, more CPU), zip (lossless, "
                       "smallest, slowest), dwaa (lossy), none");
    Table::recorded_as_number(o, f, 5);
    o.manifest_key = "settings/exr_compression";
    o.example = "zip";
  }

  // Patches
  {
    BakeOption& o = in(t.number("radius", [](BakeOptions& b) -> auto& { return b.patch.radius; }), S::Patches,
                       E::Animation,
                       "Patch radius r in scene units: the exemplar spans 2r on the surface (0 = about 1500 "
                       "patches); a radius that needs more patches than --max-memory holds (or 2e7) is refused");
    o.unit = "m";

    o.manifest_key = "radius";
    o.absent = "0";
    o.example = "0.04";
  }
  {
    BakeOption& o = in(t.integer<uint64_t>("seed", [](BakeOptions& b) -> auto& { return b.seed; }), S::Patches,
                       E::Animation, "Random seed of the seeding and the orientations (the global --seed)");
    o.global = true;
    o.manifest_key = "seed";
    o.absent = "0";
    o.example = "18446744073709551615";
  }
  {
    BakeOption& o = in(t.number("spacing", [](BakeOptions& b) -> auto& { return b.seeding.spacing; }), S::Patches,
                       E::Animation,
                       "Poisson-disk distance between seeds (patches grow as 1/spacing^2: a spacing whose patches "
                       "would not fit --max-memory is refused)");
    o.unit = "r";

    o.manifest_key = "settings/spacing";
    o.example = "1.2";
  }
  {
    BakeOption& o = in(t.flag("remesh", [](BakeOptions& b) -> auto& { return b.patch.remesh; }), S::Patches,
                       E::Animation, "Remesh new patches isotropically before flattening (--no-remesh: do not)");
    o.negatable = true;
    o.manifest_key = "settings/remesh";
    o.example = "false";
  }
  {
    const Field<Remesher> f = [](BakeOptions& b) -> auto& { return b.patch.remesher; };
    BakeOption& o = in(t.choice<Remesher>("remesher", f,
                                          {{"lattice", Remesher::Lattice},
                                           {"isotropic", Remesher::Isotropic},
                                           {"cgal", Remesher::CgalIsotropic},
                                           {"grid", Remesher::Lattice},
                                           {"fast", Remesher::Isotropic}}),
                       S::Patches, E::Animation,
                       "How new patches get even triangles: lattice (tangent-plane lattice, isotropic where the cut is "
                       "not a height field), isotropic (remeshing), cgal (CGAL's isotropic remeshing, same "
                       "algorithm); grid and fast are the old names of lattice and isotropic");
    Table::recorded_as_number(o, f, 3);
    o.manifest_key = "settings/remesher";
    o.example = "cgal";
  }
  {
    BakeOption& o = in(t.number("remesh-edge", [](BakeOptions& b) -> auto& { return b.patch.remesh_edge; }),
                       S::Patches, E::Animation,
                       "Remeshing target edge length (a patch's memory grows as 1/edge^2: an edge whose patches would "
                       "not fit --max-memory is refused)");
    o.unit = "r";

    o.manifest_key = "settings/remesh_edge";
    o.example = "0.2";
  }
  {
    BakeOption& o = t.add("orientation", OptionKind::Text);
    // The manifest spells a direction x,y,z; the command line world:x,y,z.
    o.manifest_get = [](const BakeOptions& b) {
      const Vec3& d = b.patch.align_direction;
      return b.patch.align ? fmt::format("{},{},{}", d.x, d.y, d.z) : std::string("random");
    };
    o.get = [m = o.manifest_get](const BakeOptions& b) { return b.patch.align ? "world:" + m(b) : m(b); };
    o.manifest_set = [](BakeOptions& b, const std::string& t) {
      if (t == "random") {
        b.patch.align = false;
        return;
      }
      Vec3 d;
      char tail = 0;
      if (std::sscanf(t.c_str(), "%lf,%lf,%lf%c", &d.x, &d.y, &d.z, &tail) != 3) not_("random or x,y,z");
      if (!(norm(d) > 0) || !std::isfinite(norm(d))) not_("a direction (a zero or infinite one is not)");
      b.patch.align = true;
      b.patch.align_direction = d;
    };
    o.set = [m = o.manifest_set](BakeOptions& b, const std::string& t) {
      if (t == "random") return m(b, t);
      static const std::regex world(R"(world:\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+))");
      std::smatch w;
      if (!std::regex_match(t, w, world)) not_("'random' or 'world:x,y,z'");
      m(b, fmt::format("{},{},{}", w[1].str(), w[2].str(), w[3].str()));
    };
    o.manifest_key = "settings/align";
    o.example = "world:0,0,1";
    in(o, S::Patches, E::Animation,
       "random (from seed and patch id) or world:x,y,z (u along that direction on the tangent plane)");
  }
  {
    BakeOption& o = in(t.flag("through-flow", [](BakeOptions& b) -> auto& { return b.advect.through_flow; }),
                       S::Patches, E::Animation,
                       "Where the liquid crosses its own surface (an outflow or inflow face: a vertex's step leaves "
                       "the surface along its normal while the surface stays), the texture keeps to the surface with "
                       "the tangential part of the step instead of being cut away there and born again every frame "
                       "(--no-through-flow: removed, as in the paper; docs/temporal.md)");
    o.negatable = true;
    o.manifest_key = "settings/advect_through_flow";
    o.absent = "false";  // manifests from before the rule: the bake ran without it
    o.example = "false";
  }
  {
    BakeOption& o = in(t.flag("run-off", [](BakeOptions& b) -> auto& { return b.advect.run_off; }), S::Patches,
                       E::Animation,
                       "Where the liquid runs off the edge of its surface (leaving the domain at an open end), the "
                       "texture goes over the edge with it instead of being cut away or piled up before the edge "
                       "(--no-run-off: removed or projected onto the edge, as in the paper; docs/temporal.md)");
    o.negatable = true;
    o.manifest_key = "settings/advect_run_off";
    o.absent = "false";
    o.example = "false";
  }

  // Erosion
  {
    BakeOption& o = in(t.number("anticipate", [](BakeOptions& b) -> auto& { return b.patch.anticipate; }),
                       S::Erosion, E::Animation,
                       "New patches are born deformed against the flow they will meet (predicted as if the flow were "
                       "steady, less where it is not) by this fraction of their predicted life, so their distortion "
                       "falls before it grows and they live longer (0 = the paper's conformal patch; "
                       "docs/temporal.md)");
    o.range = {0, 1};
    o.manifest_key = "settings/anticipate";
    o.example = "0.25";
  }
  {
    BakeOption& o = in(t.number("delta-max", [](BakeOptions& b) -> auto& { return b.weights.delta_max; }),
                       S::Erosion, E::Animation, "Distortion at which a patch is fully eroded (Sorkine delta)");

    o.manifest_key = "delta_max";
    o.absent = "0";
    o.example = "4";
  }
  {
    BakeOption& o = in(t.number("epsilon", [](BakeOptions& b) -> auto& { return b.raster.epsilon; }), S::Erosion,
                       E::Animation, "Erosion offset epsilon of the paper");

    o.manifest_key = "epsilon";
    o.absent = "0";
    o.example = "0.2";
  }
  {
    BakeOption& o = in(t.number("small-hole", [](BakeOptions& b) -> auto& { return b.raster.small_hole; }),
                       S::Erosion, E::Animation,
                       "Holes no wider than this times the radius are closed by the patches around them instead of "
                       "a new patch (0 = a new patch for every hole, as in the paper)");
    o.unit = "r";
    o.range = {0, 1};
    o.manifest_key = "small_hole";
    o.absent = "0";
    o.example = "0.5";
  }
  {
    BakeOption& o = in(t.number("rest-hole", [](BakeOptions& b) -> auto& { return b.raster.rest_hole; }),
                       S::Erosion, E::Animation,
                       "Holes no wider than this times the radius whose rim is held only by patches at rest (below "
                       "--min-speed) are closed by those patches: the strip a slowly spreading still liquid uncovers "
                       "continues their texture instead of a new patch popping in (0 = --small-hole there too)");
    o.unit = "r";
    o.range = {0, 4};
    o.manifest_key = "rest_hole";
    o.absent = "0";  // manifests from before the rule
    o.example = "1";
  }
  {
    BakeOption& o = in(t.flag("hold", [](BakeOptions& b) -> auto& { return b.raster.hold; }), S::Erosion,
                       E::Animation,
                       "Hysteresis of the erosion test where a patch won texels before, so a texel does not change "
                       "hands when only the atlas's sampling moved, and a patch at rest keeps its weights and the "
                       "small holes it closed (--no-hold: the paper's memoryless test; docs/temporal.md)");
    o.negatable = true;
    o.manifest_key = "hold";
    o.absent = "false";
    o.example = "false";
  }
  {
    BakeOption& o = in(t.flag("rest-bound", [](BakeOptions& b) -> auto& { return b.raster.rest_bound; }),
                       S::Erosion, E::Animation,
                       "With --hold: a patch at rest (below --min-speed) takes no surface farther than two tracking "
                       "texels from what it held, so the strip a spreading still liquid uncovers continues the patch "
                       "beside it instead of whichever patch's far edge reaches over the rim (--no-rest-bound: a "
                       "patch wins wherever its erosion test passes; docs/temporal.md)");
    o.negatable = true;
    o.manifest_key = "settings/rest_bound";
    o.absent = "false";
    o.example = "false";
  }
  {
    BakeOption& o = in(t.number("hold-margin", [](BakeOptions& b) -> auto& { return b.raster.hold_margin; }),
                       S::Erosion, E::Animation,
                       "Where a patch won texels before, its erosion test passes with w lower by this much");
    o.range = {0, 1};
    o.manifest_key = "hold_margin";
    o.absent = "0";
    o.example = "0.1";
  }
  {
    BakeOption& o = in(t.number("merge", [](BakeOptions& b) -> auto& { return b.raster.merge; }), S::Erosion,
                       E::Animation,
                       "Retire a patch that won fewer texels than this fraction of pi r^2 when other patches keep "
                       "every one of them (0 = only patches that won nothing retire, as in the paper)");
    o.range = {0, 1};
    o.manifest_key = "merge";
    o.absent = "0";
    o.example = "0.3";
  }
  {
    BakeOption& o = t.add("paper", OptionKind::Flag);
    o.get = [](const BakeOptions&) { return std::string("false"); };  // a preset: the options it sets are recorded
    o.set = [](BakeOptions& b, const std::string& t) {
      if (!parse_bool(t)) return;
      b.raster.use_paper_hole_filling();
      b.patch.anticipate = 0;
      b.advect.through_flow = false;
      b.advect.run_off = false;
    };
    o.example = "true";
    in(o, S::Erosion, E::Animation,
       "The paper's patches, hole filling and retirement as published, for comparisons: conformal new patches, "
       "every hole a new patch, no hysteresis, only patches that won nothing retire (= --anticipate 0 "
       "--no-through-flow --no-run-off --small-hole 0 --rest-hole 0 --no-hold --no-rest-bound --merge 0). The "
       "population then grows on steady flow and a still liquid keeps churning (docs/temporal.md)");
    o.excludes = {"small-hole", "rest-hole", "hold", "rest-bound", "merge", "anticipate", "through-flow", "run-off"};
  }
  {
    const Field<RasterMode> f = [](BakeOptions& b) -> auto& { return b.raster.mode; };
    BakeOption& o = in(t.choice<RasterMode>("mode", f,
                                            {{"erosion", RasterMode::Erosion},
                                             {"blend", RasterMode::Blend},
                                             {"advect", RasterMode::NoErosion}}),
                       S::Erosion, E::Animation,
                       "erosion (the paper), blend (the 2019 baseline: every covering patch alpha-blended by its "
                       "weight; ghosts) or advect (no erosion, no retirement: a purely advected texture that "
                       "stretches)");
    o.manifest_key = "mode";
    o.absent = "erosion";
    o.example = "blend";
  }

  // Atlas
  {
    BakeOption& o = in(t.integer<int>("resolution", [](BakeOptions& b) -> auto& { return b.atlas.resolution; }),
                       S::Atlas, E::Picture,
                       "Atlas width = height, 16-32768 (0 = from the exemplar's density, 512-4096); a resolution "
                       "whose buffers do not fit --max-memory is refused before the bake starts");
    o.unit = "texels";

    o.manifest_key = "resolution";
    o.absent = "0";
    o.example = "2048";
  }
  {
    BakeOption& o = in(t.integer<int>("gutter", [](BakeOptions& b) -> auto& { return b.atlas.gutter; }), S::Atlas,
                       E::Picture, "Empty texels between two charts, shared by the two; colour is dilated into them");
    o.unit = "texels";

    o.manifest_key = "settings/gutter";
    o.example = "8";
  }
  {
    BakeOption& o = in(t.number("track-texel", [](BakeOptions& b) -> auto& { return b.track_texel; }), S::Atlas,
                       E::Animation,
                       "Births, retirements and held cells are decided on an atlas of their own with texels of this "
                       "size on the surface, whatever --resolution: a preview and a final of another resolution show "
                       "the same patches (docs/farm.md)");
    o.unit = "r";
    o.range = {1.0 / 1024, 1.0};
    o.manifest_key = "settings/track_texel";
    o.example = "0.0625";
  }

  // Limits
  {
    BakeOption& o = t.add("max-memory", OptionKind::Size);
    o.get = [](const BakeOptions& b) { return fmt::format("{}", b.max_memory); };
    o.set = [](BakeOptions& b, const std::string& t) {
      b.max_memory = t == "0" ? 0 : parse_memory_size(t);  // 0: the default budget; a UsageError names the flag
    };
    o.example = "12G";
    in(o, S::Limits, E::Neither,
       "Memory the bake may use, e.g. 16G or 500M (0 = 80% of physical memory). Before reading more than the first "
       "frame, the bake estimates its memory from the surface area, --radius, --resolution and the exemplar's size "
       "(docs/robustness.md) and refuses (exit 2) what would not fit");
  }

  // Set by the library (and --paper), recorded so that --resume and
  // `lapflow render` decide as the bake did.
  const auto internal = [&](BakeOption& o, E effect, std::string key) {
    o.on_command_line = false;
    o.stage = S::Limits;
    o.effect = effect;
    o.manifest_key = "settings/" + std::move(key);
  };
  internal(t.integer<int>("anticipate-horizon", [](BakeOptions& b) -> auto& { return b.patch.anticipate_horizon; }),
           E::Animation, "anticipate_horizon");
  internal(t.number("advect-max-step-fraction", [](BakeOptions& b) -> auto& { return b.advect.max_step_fraction; }),
           E::Animation, "advect_max_step_fraction");
  internal(t.number("advect-max-turn", [](BakeOptions& b) -> auto& { return b.advect.max_turn; }), E::Animation,
           "advect_max_turn");
  internal(t.number("advect-max-projection", [](BakeOptions& b) -> auto& { return b.advect.max_projection; }),
           E::Animation, "advect_max_projection");
  internal(t.number("center-radius", [](BakeOptions& b) -> auto& { return b.weights.center_radius; }), E::Animation,
           "center_radius");
  internal(t.number("max-stretch", [](BakeOptions& b) -> auto& { return b.atlas.max_stretch; }), E::Animation,
           "max_stretch");
  internal(t.flag("fill-holes", [](BakeOptions& b) -> auto& { return b.raster.fill_holes; }), E::Animation,
           "fill_holes");
  internal(t.flag("retire", [](BakeOptions& b) -> auto& { return b.raster.retire; }), E::Animation, "retire");
  internal(t.flag("mipmap", [](BakeOptions& b) -> auto& { return b.raster.mipmap; }), E::Picture, "mipmap");
  internal(t.flag("trilinear", [](BakeOptions& b) -> auto& { return b.raster.trilinear; }), E::Picture, "trilinear");
  internal(t.flag("dilate", [](BakeOptions& b) -> auto& { return b.raster.dilate; }), E::Picture, "dilate");
  internal(t.integer<std::size_t>("max-hole-patches", [](BakeOptions& b) -> auto& { return b.raster.max_hole_patches; }),
           E::Animation, "max_hole_patches");
  // A flag's example is the other state; an internal number's an arbitrary value.
  for (BakeOption& o : t.entries)
    if (o.example.empty()) o.example = o.kind != OptionKind::Flag ? "3" : o.get(BakeOptions()) == "true" ? "false" : "true";
  return std::move(t.entries);
}

}  // namespace

const std::vector<BakeOption>& bake_option_table() {
  static const std::vector<BakeOption> table = make_table();
  return table;
}

const BakeOption* find_bake_option(std::string_view name) {
  std::string key(name);
  std::replace(key.begin(), key.end(), '_', '-');
  for (const BakeOption& o : bake_option_table())
    if (o.name == key) return &o;
  return nullptr;
}

BakeOptions default_bake_options() {
  BakeOptions o;
  o.patch.radius = 0;      // automatic
  o.atlas.resolution = 0;  // automatic
  o.name.clear();          // the mesh pattern's
  return o;
}

std::string BakeOption::default_text() const { return get(default_bake_options()); }

void set_bake_option(BakeOptions& o, const BakeOption& option, const std::string& text) {
  try {
    if (option.range && (option.kind == OptionKind::Number || option.kind == OptionKind::Integer)) {
      const double v = parse_number(text);
      if (!(v >= option.range->first && v <= option.range->second))
        not_(fmt::format("in [{}, {}]", option.range->first, option.range->second));
    }
    option.set(o, text);
  } catch (const std::invalid_argument& e) {
    throw UsageError(option.flag() + ": '" + text + "' is not " + e.what());
  }
}

std::string_view option_stage_name(OptionStage stage) {
  switch (stage) {
    case OptionStage::Input: return "Input";
    case OptionStage::Exemplar: return "Exemplar";
    case OptionStage::Patches: return "Patches";
    case OptionStage::Erosion: return "Erosion";
    case OptionStage::Atlas: return "Atlas";
    case OptionStage::Output: return "Output";
    case OptionStage::Limits: return "Limits";
  }
  return "";
}

std::string_view option_effect_name(OptionEffect effect) {
  switch (effect) {
    case OptionEffect::Animation: return "animation";
    case OptionEffect::Picture: return "picture";
    case OptionEffect::Neither: return "neither";
  }
  return "";
}

std::string bake_options_markdown() {
  std::string md;
  for (const OptionStage stage : {OptionStage::Input, OptionStage::Exemplar, OptionStage::Patches,
                                  OptionStage::Erosion, OptionStage::Atlas, OptionStage::Output,
                                  OptionStage::Limits}) {
    md += fmt::format("### {}\n\n| option | default | unit | range | changes | manifest key | meaning |\n"
                      "|---|---|---|---|---|---|---|\n",
                      option_stage_name(stage));
    for (const BakeOption& o : bake_option_table()) {
      if (o.stage != stage || !o.on_command_line) continue;
      std::string flag = "`" + o.flag() + "`";
      if (o.negatable) flag += " / `--no-" + o.name + "`";
      std::string range;
      if (o.range) range = fmt::format("{} to {}", o.range->first, o.range->second);
      if (!o.choices.empty()) range = fmt::format("{}", fmt::join(o.choices, ", "));
      const std::string d = o.default_text();
      md += fmt::format("| {} | {} | {} | {} | {} | {} | {} |\n", flag, d.empty() ? "" : "`" + d + "`", o.unit, range,
                        option_effect_name(o.effect), o.manifest_key.empty() ? "" : "`" + o.manifest_key + "`",
                        o.help);
    }
    md += "\n";
  }
  md += "Recorded in the manifest's settings, not on the command line (set by the library and `--paper`): ";
  std::vector<std::string> hidden;
  for (const BakeOption& o : bake_option_table())
    if (!o.on_command_line) hidden.push_back("`" + o.manifest_key + "`");
  md += fmt::format("{}.\n", fmt::join(hidden, ", "));
  return md;
}

}  // namespace lapflow
