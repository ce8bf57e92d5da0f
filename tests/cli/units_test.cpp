// Sizes, speeds and property types no liquid in metres has (issue 14 item
// 5): `lapflow inspect` warns and exits 0, `lapflow bake` refuses the frame
// (exit 2 naming the file and frame) unless --units-ok, on every frame it
// reads. The thresholds are kMaxLiquidSize and kMaxLiquidSpeed.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "io_test_helpers.hpp"
#include "lapflow/bake/frame.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

namespace {

/// An ASCII PLY tetrahedron of edge `size` m with vertex 1 at x = `far`
/// (when not 0), positions declared as `type`, every vertex moving at
/// `speed` m/s along z (vertex 3 at `fast` m/s when not 0).
std::string tetra_ply(double size, double far = 0, const std::string& type = "float", double speed = 0.5,
                      double fast = 0) {
  std::string s = fmt::format(
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty {0} x\nproperty {0} y\nproperty {0} z\n"
      "property float vx\nproperty float vy\nproperty float vz\n"
      "element face 4\nproperty list uchar int vertex_indices\nend_header\n",
      type);
  const double x1 = far != 0 ? far : size;
  s += fmt::format("0 0 0 0 0 {}\n{} 0 0 0 0 {}\n0 {} 0 0 0 {}\n0 0 {} 0 0 {}\n", speed, x1, speed, size, speed,
                   size, fast != 0 ? fast : speed);
  return s + "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
}

std::string lapflow_command(const TempDir& dir, const std::string& args) {
  return fmt::format("cd '{}' && '{}' {}", dir.str(), LAPFLOW_BINARY, args);
}

struct CliResult {
  int code = -1;
  std::string out, err;
};

CliResult run(const TempDir& dir, const std::string& args) {
  CliResult r;
  r.code = test::run_command(lapflow_command(dir, args), &r.out, &r.err, dir);
  return r;
}

/// A VDB whose vector grid `vel` is `v` m/s everywhere (its background).
void write_uniform_vdb(const std::string& path, const Vec3& v) {
  openvdb::initialize();
  auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(float(v.x), float(v.y), float(v.z)));
  grid->setName("vel");
  openvdb::io::File(path).write({grid});
}

std::size_t lines(const std::string& s) { return std::size_t(std::count(s.begin(), s.end(), '\n')); }

/// The bake of dir/NAME.%04d.ply into dir/NAME.out (name t) at 128^2,
/// radius `radius` m.
std::string bake_args(const std::string& name, double radius, const std::string& more = "") {
  return fmt::format("bake --mesh {0}.%04d.ply --exemplar pebbles --resolution 128 --radius {1} --out {0}.out "
                     "--name t --threads 2 --quiet {2}",
                     name, radius, more);
}

}  // namespace

TEST(Units, ProblemsNameWhatNoLiquidHas) {
  TempDir dir("units");
  test::write_bytes(dir / "ok.ply", tetra_ply(1.0));
  test::write_bytes(dir / "large.ply", tetra_ply(999.0));
  test::write_bytes(dir / "huge.ply", tetra_ply(2500.0));
  test::write_bytes(dir / "far.ply", tetra_ply(1.0, 3e38));
  test::write_bytes(dir / "fast.ply", tetra_ply(1.0, 0, "float", 0.5, -2000));
  test::write_bytes(dir / "int.ply", tetra_ply(1.0, 0, "int"));
  test::write_bytes(dir / "uchar.ply", tetra_ply(1.0, 0, "uchar"));

  auto problems = [&](const std::string& name, bool check_bounds = true) {
    const MeshFile f = read_mesh_file(dir / name, check_bounds);
    return units_problems(f.mesh, f.declared);
  };
  EXPECT_TRUE(problems("ok.ply").empty());
  EXPECT_TRUE(problems("large.ply").empty()) << "999 m is under kMaxLiquidSize";
  ASSERT_EQ(problems("huge.ply").size(), 1u);
  EXPECT_EQ(problems("huge.ply")[0], "mesh bounds 2.5e+03 m across: over 1 km, are the units metres?");

  // Beyond kMaxMeshCoordinate read_mesh refuses; read on, it is two problems.
  EXPECT_THROW(read_mesh_file(dir / "far.ply"), InputError);
  const std::vector<std::string> far = problems("far.ply", false);
  ASSERT_EQ(far.size(), 2u);
  EXPECT_EQ(far[0], "mesh bounds 3e+38 m across: over 1 km, are the units metres?");
  EXPECT_NE(far[1].find("even with --units-ok"), std::string::npos) << far[1];

  const std::vector<std::string> fast = problems("fast.ply");
  ASSERT_EQ(fast.size(), 1u);
  EXPECT_EQ(fast[0], "the vertex velocity at vertex 3 is 2e+03 m/s: over 1 km/s, are the velocities in m/s?");
  // The vertex velocity does not count when the velocity comes from a VDB.
  const MeshFile f = read_mesh_file(dir / "fast.ply");
  EXPECT_TRUE(units_problems(f.mesh, f.declared, false).empty());

  const MeshFile declared_int = read_mesh_file(dir / "int.ply");
  ASSERT_EQ(declared_int.declared.positions.size(), 3u);
  EXPECT_EQ(declared_int.declared.positions[0].type, "int");
  EXPECT_TRUE(declared_int.declared.positions[0].integer);
  ASSERT_EQ(declared_int.declared.velocities.size(), 3u);
  EXPECT_FALSE(declared_int.declared.velocities[0].integer);
  ASSERT_EQ(problems("int.ply").size(), 1u);
  EXPECT_EQ(problems("int.ply")[0].rfind("PLY position properties declared as integers (x int, y int, z int)", 0), 0u)
      << problems("int.ply")[0];
  ASSERT_EQ(problems("uchar.ply").size(), 1u);
  EXPECT_NE(problems("uchar.ply")[0].find("x uchar"), std::string::npos);
  // The shared layout (float positions and velocities) is fine.
  const MeshFile written = [&] {
    TriMesh m = test::icosphere(1, 0.3);
    m.velocities.assign(m.positions.size(), Vec3{0, 0, 1});
    write_ply(dir / "written.ply", m);
    return read_mesh_file(dir / "written.ply");
  }();
  EXPECT_TRUE(units_problems(written.mesh, written.declared).empty());
}

TEST(Units, InspectWarnsAndExitsZero) {
  TempDir dir("units");
  test::write_bytes(dir / "far.0001.ply", tetra_ply(1.0, 3e38));
  test::write_bytes(dir / "fast.0001.ply", tetra_ply(1.0, 0, "float", 0.5, 2000));
  test::write_bytes(dir / "int.0001.ply", tetra_ply(1.0, 0, "int"));
  test::write_bytes(dir / "ok.0001.ply", tetra_ply(1.0));
  const struct {
    const char* name;
    std::string part;
  } cases[] = {{"far", "mesh bounds 3e+38 m across: over 1 km, are the units metres?"},
               {"fast", "at vertex 3 is 2e+03 m/s: over 1 km/s"},
               {"int", "PLY position properties declared as integers (x int, y int, z int)"}};
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string file = fmt::format("{}.0001.ply", c.name);
    CliResult r = run(dir, fmt::format("inspect {}.%04d.ply", c.name));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("warning: " + file + " (frame 1): "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(c.part), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("error"), std::string::npos) << r.err;
    EXPECT_NE(r.out.find("units             WARNING in frames 1"), std::string::npos) << r.out;
    // The JSON lists them, per frame and in the summary.
    r = run(dir, fmt::format("inspect {}.%04d.ply --json --quiet", c.name));
    EXPECT_EQ(r.code, 0) << r.err;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    ASSERT_TRUE(j["frames"][0]["warnings"].is_array());
    ASSERT_FALSE(j["frames"][0]["warnings"].empty());
    EXPECT_NE(j["frames"][0]["warnings"][0].get<std::string>().find(c.part), std::string::npos) << j.dump(2);
    EXPECT_EQ(j["summary"]["frames_with_warnings"], nlohmann::json::array({1}));
    ASSERT_FALSE(j["summary"]["warnings"].empty());
    EXPECT_EQ(j["summary"]["warnings"][0].get<std::string>().rfind(file + " (frame 1): ", 0), 0u);
  }
  // A liquid in metres: no warning, and the summary says so.
  const CliResult ok = run(dir, "inspect ok.%04d.ply --json --quiet");
  EXPECT_EQ(ok.code, 0);
  EXPECT_EQ(ok.err, "");
  EXPECT_TRUE(nlohmann::json::parse(ok.out)["frames"][0]["warnings"].empty());
  // The thresholds are in the help.
  const CliResult help = run(dir, "inspect --help");
  EXPECT_NE(help.out.find("bounds more than 1 km across, a vertex faster than 1 km/s"), std::string::npos) << help.out;
}

TEST(Units, BakeRefusesSuchAFrameUnlessUnitsOk) {
  TempDir dir("units");
  // Frame 1 a liquid in metres; frame 2 has a vertex at 2 km/s: the bake
  // checks every frame it reads, not only the first.
  test::write_bytes(dir / "fast.0001.ply", tetra_ply(1.0));
  test::write_bytes(dir / "fast.0002.ply", tetra_ply(1.0, 0, "float", 0.5, 2000));
  CliResult r = run(dir, bake_args("fast", 0.3));
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_EQ(lines(r.err), 1u) << r.err;
  EXPECT_NE(r.err.find("error: fast.0002.ply (frame 2): the vertex velocity at vertex 3 is 2e+03 m/s: over 1 km/s, "
                       "are the velocities in m/s? (--units-ok to bake anyway)"),
            std::string::npos)
      << r.err;
  EXPECT_TRUE(fs::exists(dir / "fast.out/t.0001.obj")) << "frame 1 is baked before frame 2 is refused";
  EXPECT_FALSE(fs::exists(dir / "fast.out/t.0002.obj"));
  r = run(dir, bake_args("fast", 0.3, "--units-ok"));
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "fast.out/t.0002.obj"));

  // 2.5 km across: refused on the first frame, before the memory estimate.
  test::write_bytes(dir / "huge.0001.ply", tetra_ply(2500.0));
  r = run(dir, bake_args("huge", 500));
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("error: huge.0001.ply (frame 1): mesh bounds 2.5e+03 m across: over 1 km, are the units "
                       "metres? (--units-ok to bake anyway)"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir / "huge.out"));
  r = run(dir, bake_args("huge", 500, "--units-ok"));
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "huge.out/t.0001.obj"));

  // Integer coordinates, from a scene file's key as well.
  test::write_bytes(dir / "int.0001.ply", tetra_ply(1.0, 0, "int"));
  r = run(dir, bake_args("int", 0.3));
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("error: int.0001.ply (frame 1): PLY position properties declared as integers"),
            std::string::npos)
      << r.err;
  test::write_bytes(dir / "int.toml", "mesh = \"int.%04d.ply\"\nunits_ok = true\n");
  r = run(dir, "bake int.toml --exemplar pebbles --resolution 128 --radius 0.3 --out scene.out --quiet --threads 2");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "scene.out/int.0001.obj"));

  // Beyond kMaxMeshCoordinate --units-ok does not help.
  test::write_bytes(dir / "far.0001.ply", tetra_ply(1.0, 3e38));
  r = run(dir, bake_args("far", 0.3, "--units-ok"));
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("far.0001.ply (frame 1): mesh bounds 3e+38 m: are the units metres?"), std::string::npos)
      << r.err;
  // The help says the thresholds.
  r = run(dir, "bake --help");
  EXPECT_NE(r.out.find("--units-ok"), std::string::npos);
  EXPECT_NE(r.out.find("bounds more than 1 km across, a vertex faster than 1 km/s"), std::string::npos) << r.out;
}

TEST(Units, AVdbGridFasterThan1KmPerSecondIsWarnedAndRefused) {
  TempDir dir("units");
  // Vertex velocities of 0.5 m/s, a grid of 1500 m/s: the grid is what the
  // bake would advect with.
  test::write_bytes(dir / "m.0001.ply", tetra_ply(1.0));
  write_uniform_vdb(dir / "v.0001.vdb", {0, 1500, 0});
  CliResult r = run(dir, "inspect m.%04d.ply --velocity-vdb v.%04d.vdb --quiet");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("warning: m.0001.ply (frame 1): the VDB grid 'vel' at vertex 0 is 1.5e+03 m/s: over 1 km/s"),
            std::string::npos)
      << r.err;
  r = run(dir, "bake --mesh m.%04d.ply --velocity-vdb v.%04d.vdb --exemplar pebbles --resolution 128 --radius 0.3 "
               "--out out --quiet --threads 2");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("error: m.0001.ply (frame 1): the VDB grid 'vel' at vertex 0 is 1.5e+03 m/s"), std::string::npos)
      << r.err;
  // 900 m/s is fast, but not beyond what the check calls a liquid.
  write_uniform_vdb(dir / "v.0001.vdb", {0, 900, 0});
  r = run(dir, "bake --mesh m.%04d.ply --velocity-vdb v.%04d.vdb --exemplar pebbles --resolution 128 --radius 0.3 "
               "--out out --quiet --threads 2");
  EXPECT_EQ(r.code, 0) << r.err;
}

TEST(Units, ReadFrameInputChecksUnlessUnitsOk) {
  TempDir dir("units");
  test::write_bytes(dir / "m.0007.ply", tetra_ply(1.0, 0, "short"));
  FrameSource source;
  source.mesh_pattern = dir / "m.%04d.ply";
  try {
    read_frame_input(source, 7);
    ADD_FAILURE() << "a short-typed position was accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), dir / "m.0007.ply");
    EXPECT_EQ(e.frame(), 7);
    EXPECT_NE(e.message().find("x short, y short, z short"), std::string::npos) << e.what();
    EXPECT_NE(e.message().find("(--units-ok to bake anyway)"), std::string::npos) << e.what();
  }
  source.units_ok = true;
  EXPECT_EQ(read_frame_input(source, 7).mesh.triangle_count(), 4u);
}
