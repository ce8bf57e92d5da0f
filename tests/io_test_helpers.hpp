#pragma once
// Helpers for the input-side tests (readers, bad input, inspect): scratch
// folders, raw file bytes, running the CLI, a small bake's options.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "lapflow/surface/mesh.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/layers.hpp"
#include "lapflow/core/errors.hpp"
#include "test_helpers.hpp"

namespace lapflow::test {

/// The message of the InputError `f` throws ("" when it throws none).
template <class F>
std::string input_error_of(F&& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

/// A fresh folder under the system temp dir, removed with everything in it.
class TempDir {
 public:
  explicit TempDir(const std::string& tag) {
    static std::atomic<int> counter{0};
    path_ = std::filesystem::temp_directory_path() /
            ("lapflow_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  /// Path of `name` inside the folder.
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }
  std::string str() const { return path_.string(); }

 private:
  std::filesystem::path path_;
};

inline void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(bytes.data(), std::streamsize(bytes.size()));
}

inline std::string read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

/// The names of the files in `dir`, sorted.
inline std::vector<std::string> names_in(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

/// The id of a process that has ended (a child that exited and was reaped):
/// its temporary files are stale.
inline long ended_process_id() {
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  int status = 0;
  ::waitpid(child, &status, 0);
  return long(child);
}

/// The temporary name lapflow gives `NAME` (before the extension) written by
/// process `pid` of host `host` in call `k`: `.NAME.tmpHOST-PID_K.EXT`.
inline std::string temporary_name(const std::string& name, const std::string& ext, const std::string& host, long pid,
                                  int k = 0) {
  return "." + name + ".tmp" + host + "-" + std::to_string(pid) + "_" + std::to_string(k) + ext;
}

/// The temporary files (".tmp" in the name) left in `dir`, sorted.
inline std::vector<std::string> temporaries_in(const std::string& dir) {
  std::vector<std::string> t;
  for (const std::string& n : names_in(dir))
    if (n.find(".tmp") != std::string::npos) t.push_back(n);
  return t;
}

/// A bake's NAME.stats.jsonl without what depends on the clock and the
/// machine (seconds, peak memory).
inline std::vector<nlohmann::json> stats_without_timings(const std::string& path) {
  std::vector<nlohmann::json> lines;
  std::istringstream in(read_bytes(path));
  for (std::string line; std::getline(in, line);) {
    nlohmann::json j = nlohmann::json::parse(line);
    j.erase("seconds");
    j.erase("peak_rss_mb");
    lines.push_back(j);
  }
  return lines;
}

/// Appends the raw bytes of a value in the host (little-endian) order, or
/// swapped for big-endian files.
template <typename T>
void append_raw(std::string& out, T v, bool big_endian = false) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian) std::reverse(b, b + sizeof(T));
  out.append(b, sizeof(T));
}

/// Runs a shell command with stdout and stderr captured; returns its exit code.
inline int run_command(const std::string& cmd, std::string* out, std::string* err, const TempDir& scratch) {
  const std::string o = scratch / "cmd.stdout", e = scratch / "cmd.stderr";
  const int status = std::system((cmd + " >'" + o + "' 2>'" + e + "'").c_str());
  if (out) *out = read_bytes(o);
  if (err) *err = read_bytes(e);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// Whether the program `name` is on PATH (tests that need blender or node
/// skip without it; CI installs both).
inline bool have_command(const std::string& name, const TempDir& scratch) {
  return run_command("command -v " + name, nullptr, nullptr, scratch) == 0;
}

/// The built-in demo, `frames` frames of 2000 triangles, in `dir`/mesh (kept
/// when already there), baked with the lava exemplar at radius 0.05 into
/// `dir`/bake with `options` added (e.g. "--resolution 256"). Fails the
/// test with the command's message.
inline void bake_lava_demo(const TempDir& dir, int frames, const std::string& options) {
  const std::string lapflow = LAPFLOW_BINARY;
  std::string err;
  if (!std::filesystem::exists(dir / "mesh")) {
    ASSERT_EQ(run_command(lapflow + " demo --out '" + (dir / "mesh") + "' --frames " + std::to_string(frames) +
                              " --triangles 2000 --no-bake -q",
                          nullptr, &err, dir),
              0)
        << err;
  }
  ASSERT_EQ(run_command(lapflow + " bake --mesh '" + (dir / "mesh") + "/demo.%04d.ply' --exemplar lava --radius 0.05 -q " +
                            "--out '" + (dir / "bake") + "' " + options,
                        nullptr, &err, dir),
            0)
      << err;
}

/// A 1 m x 1 m plane flowing along +y at 0.2 m/s, with a vertex property
/// `heat` = heat(x, frame), as ASCII PLY frames m.0001.ply, ...
/// A shipped exemplar's file: `exemplars/NAME.KIND.png` (KIND color, feature or disp).
inline std::string shipped(const std::string& name, const std::string& kind) {
  return std::string(LAPFLOW_SOURCE_DIR) + "/exemplars/" + name + "." + kind + ".png";
}

/// Layer `layer` of shipped exemplar `exemplar`'s three files.
inline ExemplarLayer shipped_layer(const std::string& layer, const std::string& exemplar) {
  return {layer, shipped(exemplar, "color"), shipped(exemplar, "feature"), shipped(exemplar, "disp")};
}

inline void write_heat_plane(const std::string& dir, int frames, const std::function<double(double, int)>& heat) {
  const TriMesh m = plane_grid(48, 48, 1.0, 1.0);
  for (int f = 1; f <= frames; ++f) {
    std::string text = fmt::format(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n"
        "property float vx\nproperty float vy\nproperty float vz\nproperty float heat\nelement face {}\n"
        "property list uchar int vertex_indices\nend_header\n",
        m.vertex_count(), m.triangle_count());
    for (const Vec3& p : m.positions) text += fmt::format("{} {} {} 0 0.2 0 {}\n", p.x, p.y, p.z, heat(p.x, f));
    for (const Tri& t : m.triangles) text += fmt::format("3 {} {} {}\n", t[0], t[1], t[2]);
    test::write_bytes(fmt::format("{}/m.{:04d}.ply", dir, f), text);
  }
}

/// Whether a test whose ../shared/data input is absent fails instead of
/// skipping: LAPFLOW_REQUIRE_SHARED_DATA set and not "0". scripts/test.sh
/// sets it when ../shared/data is there, so a folder with a scene missing
/// cannot shrink the suite unseen.
inline bool shared_data_required() {
  const char* v = std::getenv("LAPFLOW_REQUIRE_SHARED_DATA");
  return v && *v && std::string(v) != "0";
}

/// The shared Mantaflow data folder, or "" when it is absent.
inline std::string shared_data_dir() {
  const std::string dir = LAPFLOW_SOURCE_DIR "/../shared/data";
  return std::filesystem::is_directory(dir + "/dam_break") ? dir : std::string();
}

/// ../shared/data/dam_break, whether it is there or not.
inline std::string shared_data_path() { return LAPFLOW_SOURCE_DIR "/../shared/data/dam_break"; }

/// ../shared/data/dam_break/dam_break.NNNN.ply (it may be absent).
inline std::string dam_break_frame(int frame) {
  char name[64];
  std::snprintf(name, sizeof name, "/dam_break/dam_break.%04d.ply", frame);
  return std::string(LAPFLOW_SOURCE_DIR "/../shared/data") + name;
}

/// A small bake of `meshes_dir`/m.%04d.ply into `out_dir` with the shipped
/// pebbles exemplar: name "t", a 256^2 atlas, AOVs on.
inline BakeOptions small_pebbles_bake(const std::string& meshes_dir, const std::string& out_dir) {
  BakeOptions o;
  const std::string ex = std::string(LAPFLOW_SOURCE_DIR) + "/exemplars/pebbles";
  o.exemplar_color = ex + ".color.png";
  o.exemplar_feature = ex + ".feature.png";
  o.exemplar_displacement = ex + ".disp.png";
  o.mesh_pattern = meshes_dir + "/m.%04d.ply";
  o.out_dir = out_dir;
  o.name = "t";
  o.atlas.resolution = 256;
  o.aov = true;
  return o;
}

/// The compression attribute of an EXR file's header (OpenEXR file layout:
/// magic, version, then name\0 type\0 int32 size, value... until an empty
/// name). -1 when absent. 0 none, 1 RLE, 2 ZIPS, 3 ZIP, 4 PIZ, 8 DWAA.
inline int exr_header_compression(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::size_t at = 8;
  auto cstring = [&] {
    std::string out;
    while (at < bytes.size() && bytes[at] != 0) out += bytes[at++];
    ++at;
    return out;
  };
  while (at < bytes.size()) {
    const std::string name = cstring();
    if (name.empty()) break;
    const std::string type = cstring();
    if (at + 4 > bytes.size()) break;
    int32_t size;
    std::memcpy(&size, &bytes[at], 4);
    at += 4;
    if (name == "compression" && type == "compression" && size == 1 && at < bytes.size())
      return int(static_cast<unsigned char>(bytes[at]));
    at += std::size_t(size);
  }
  return -1;
}

}  // namespace lapflow::test

/// Skips the calling test when `path`, an input under ../shared/data, is
/// absent, or fails it when test::shared_data_required().
#define LAPFLOW_NEED_SHARED(path)                                                                        \
  do {                                                                                                   \
    const std::string lapflow_need_ = (path);                                                            \
    if (!std::filesystem::exists(lapflow_need_)) {                                                       \
      if (::lapflow::test::shared_data_required())                                                       \
        FAIL() << lapflow_need_ << " is absent (LAPFLOW_REQUIRE_SHARED_DATA is set)";                  \
      else                                                                                               \
        GTEST_SKIP() << lapflow_need_ << " is absent: test skipped";                                   \
    }                                                                                                    \
  } while (0)
