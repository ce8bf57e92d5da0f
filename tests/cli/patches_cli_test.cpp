// `lapflow patches` end to end on a tiny generated sequence, and the patch PLY.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <sys/wait.h>
#include <unistd.h>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "lapflow/io/mesh_io.hpp"
#include "lapflow/patches/patches.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
namespace fs = std::filesystem;

namespace {

std::string read_header(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line, header;
  while (std::getline(in, line)) {
    header += line + "\n";
    if (line == "end_header") break;
  }
  return header;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("lapflow_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

}  // namespace

TEST(PatchesPly, HeaderAndSizeMatchThePatches) {
  const TriMesh plane = test::plane_grid(10, 10, 1.0, 1.0);
  SurfaceQuery q(plane);
  PatchOptions po;
  po.radius = 0.2;
  PatchSet set;
  for (uint32_t i = 0; i < 2; ++i) set.patches.push_back(*create_patch(q, {{0.3 + 0.4 * i, 0.5, 0}, {0, 0, 1}, -1}, i, 0, po, {}));
  const fs::path dir = fresh_dir("ply");
  const std::string path = (dir / "p.ply").string();
  write_patches_ply(path, set);
  std::size_t nv = 0, nt = 0;
  for (const Patch& p : set.patches) nv += p.positions.size(), nt += p.triangles.size();
  const std::string h = read_header(path);
  EXPECT_NE(h.find("element vertex " + std::to_string(nv) + "\n"), std::string::npos) << h;
  EXPECT_NE(h.find("element face " + std::to_string(nt) + "\n"), std::string::npos);
  EXPECT_NE(h.find("property int patch_id\nproperty float u\nproperty float v\nproperty float w\n"), std::string::npos);
  EXPECT_EQ(fs::file_size(path), h.size() + nv * 28 + nt * 17);
  fs::remove_all(dir);
}

TEST(PatchesCli, WritesOnePlyPerFrameAndRejectsBadRadius) {
  const fs::path dir = fresh_dir("cli");
  // A sphere drifting along +x at 0.24 m/s, re-meshed every frame.
  for (int f = 1; f <= 3; ++f) {
    TriMesh m = test::icosphere(f % 2 ? 3 : 4, 1.0, {0.01 * (f - 1), 0, 0});
    m.velocities.assign(m.positions.size(), Vec3{0.24, 0, 0});
    write_ply((dir / ("ball." + std::to_string(1000 + f).substr(1) + ".ply")).string(), m);
  }
  const std::string cmd = std::string(LAPFLOW_BINARY) + " patches --quiet --mesh " + (dir / "ball.%03d.ply").string() +
                          " --radius 0.4 --out " + (dir / "out").string();
  ASSERT_EQ(std::system((cmd + " 2>" + (dir / "err.txt").string()).c_str()), 0);
  for (int f = 1; f <= 3; ++f) {
    const fs::path out = dir / "out" / ("ball.patches." + std::to_string(10000 + f).substr(1) + ".ply");
    ASSERT_TRUE(fs::exists(out)) << out;
    EXPECT_NE(read_header(out.string()).find("element face "), std::string::npos);
  }
  const std::string bad = std::string(LAPFLOW_BINARY) + " patches --quiet --mesh " + (dir / "ball.%03d.ply").string() +
                          " --radius -1 --out " + (dir / "out2").string() + " 2>/dev/null";
  const int status = std::system(bad.c_str());
  EXPECT_EQ(WEXITSTATUS(status), 2);
  fs::remove_all(dir);
}
