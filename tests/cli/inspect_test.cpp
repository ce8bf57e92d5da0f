// `lapflow inspect` end to end through the built binary: exit codes, messages
// naming the file, and the JSON report's counts.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "io_test_helpers.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;

namespace {
std::string inspect(const std::string& args) { return std::string("'") + LAPFLOW_BINARY + "' inspect " + args; }

/// Three frames: a sphere, nothing (legal), a sphere with a second droplet.
void write_sequence(const TempDir& tmp) {
  TriMesh a = test::icosphere(2, 0.3);
  for (const Vec3& p : a.positions) a.velocities.push_back({0, 0, p.z});
  TriMesh c = a;
  const TriMesh drop = test::icosphere(1, 0.05, {1, 0, 0});
  const int base = int(c.positions.size());
  for (const Vec3& p : drop.positions) c.positions.push_back(p), c.velocities.push_back({0, 0, -2});
  for (Tri f : drop.triangles) c.triangles.push_back({f[0] + base, f[1] + base, f[2] + base});
  const FramePattern p(tmp / "fluid.%04d.ply");
  write_ply(p.path(1), a);
  write_ply(p.path(2), TriMesh{});
  write_ply(p.path(3), c);
}
}  // namespace

TEST(InspectCommand, JsonReportHasTheRightCounts) {
  TempDir tmp("inspect");
  write_sequence(tmp);
  std::string out, err;
  ASSERT_EQ(test::run_command(inspect("'" + (tmp / "fluid.####.ply") + "' --json --quiet"), &out, &err, tmp), 0) << err;
  const nlohmann::json j = nlohmann::json::parse(out);
  ASSERT_EQ(j["frames"].size(), 3u);
  EXPECT_EQ(j["frames"][0]["frame"], 1);
  EXPECT_EQ(j["frames"][0]["triangles"], 320);
  EXPECT_EQ(j["frames"][0]["vertices"], 162);
  EXPECT_EQ(j["frames"][0]["components"], 1);
  EXPECT_EQ(j["frames"][0]["boundary_edges"], 0);
  EXPECT_EQ(j["frames"][0]["velocity_source"], "vertex");
  EXPECT_NEAR(j["frames"][0]["speed"]["max"].get<double>(), 0.3, 1e-6);
  EXPECT_EQ(j["frames"][1]["triangles"], 0);
  EXPECT_EQ(j["frames"][1]["empty"], true);
  EXPECT_EQ(j["frames"][2]["triangles"], 320 + 80);
  EXPECT_EQ(j["frames"][2]["components"], 2);
  EXPECT_NEAR(j["frames"][2]["speed"]["max"].get<double>(), 2.0, 1e-6);
  const auto& s = j["summary"];
  EXPECT_EQ(s["empty_frames"], nlohmann::json::array({2}));
  EXPECT_EQ(s["triangles"]["min"], 0);
  EXPECT_EQ(s["triangles"]["max"], 400);
  EXPECT_NEAR(s["peak_speed"].get<double>(), 2.0, 1e-6);
  EXPECT_EQ(s["peak_speed_frame"], 3);
  EXPECT_NEAR(s["bounds"]["max"][0].get<double>(), 1.05, 1e-6);
}

TEST(InspectCommand, TableAndSummaryNameTheEmptyFrame) {
  TempDir tmp("inspect");
  write_sequence(tmp);
  std::string out, err;
  ASSERT_EQ(test::run_command(inspect("'" + (tmp / "fluid.%04d.ply") + "' --frames 1-3 --min-speed 0.5"), &out, &err, tmp), 0)
      << err;
  EXPECT_NE(out.find("empty frames      2"), std::string::npos) << out;
  EXPECT_NE(out.find("below 0.5 m/s"), std::string::npos) << out;
}

TEST(InspectCommand, BadFrameExitsWithCode2NamingFileAndFrame) {
  TempDir tmp("inspect");
  write_sequence(tmp);
  const std::string frame3 = FramePattern(tmp / "fluid.%04d.ply").path(3);
  const std::string bytes = test::read_bytes(frame3);
  test::write_bytes(frame3, bytes.substr(0, bytes.size() - 100));
  std::string out, err;
  EXPECT_EQ(test::run_command(inspect("'" + (tmp / "fluid.%04d.ply") + "' --quiet"), &out, &err, tmp), 2);
  EXPECT_NE(err.find(frame3 + " (frame 3): file truncated"), std::string::npos) << err;
  // The readable frames are still reported.
  EXPECT_NE(out.find("unreadable"), std::string::npos) << out;
}

TEST(InspectCommand, MissingFrameInRangeAndMissingPatternExitWith2) {
  TempDir tmp("inspect");
  write_sequence(tmp);
  std::string err;
  EXPECT_EQ(test::run_command(inspect("'" + (tmp / "fluid.%04d.ply") + "' --frames 2-5"), nullptr, &err, tmp), 2);
  EXPECT_NE(err.find(tmp / "fluid.0004.ply"), std::string::npos) << err;
  EXPECT_NE(err.find("frame 4"), std::string::npos) << err;
  EXPECT_EQ(test::run_command(inspect("'" + (tmp / "other.%04d.ply") + "'"), nullptr, &err, tmp), 2);
  EXPECT_NE(err.find("other.%04d.ply"), std::string::npos) << err;
  EXPECT_EQ(test::run_command(inspect("'" + (tmp / "fluid.%04d.ply") + "' --frames 9-1"), nullptr, &err, tmp), 2);
}

TEST(InspectCommand, HelpReadsLikeAManPage) {
  TempDir tmp("inspect");
  std::string out;
  ASSERT_EQ(test::run_command(inspect("--help"), &out, nullptr, tmp), 0);
  for (const char* part : {"--frames", "--velocity-vdb", "--velocity-grid", "--json", "--min-speed", "--threads",
                           "INPUT FORMATS", "EXIT CODES", "EXAMPLES"})
    EXPECT_NE(out.find(part), std::string::npos) << part;
}

TEST(InspectCommand, DamBreakWithVdbVelocities) {
  LAPFLOW_NEED_SHARED(test::shared_data_path());
  const std::string dir = test::shared_data_dir();
  TempDir tmp("inspect");
  std::string out, err;
  ASSERT_EQ(test::run_command(inspect("'" + dir + "/dam_break/dam_break.%04d.ply' --frames 1-3 --json --quiet "
                                      "--velocity-vdb '" + dir + "/dam_break/dam_break.%04d.vdb'"),
                              &out, &err, tmp),
            0)
      << err;
  const nlohmann::json j = nlohmann::json::parse(out);
  ASSERT_EQ(j["frames"].size(), 3u);
  EXPECT_EQ(j["frames"][0]["triangles"], 7836);
  EXPECT_EQ(j["frames"][0]["vertices"], 3920);
  EXPECT_EQ(j["frames"][0]["velocity_source"], "vdb");
  EXPECT_EQ(j["frames"][0]["grid"]["name"], "velocity");
  for (const auto& f : j["frames"]) EXPECT_LT(f["grid"]["relative_difference"].get<double>(), 0.2);
  // A grid name the files do not have: exit 2, the message lists what is there.
  EXPECT_EQ(test::run_command(inspect("'" + dir + "/dam_break/dam_break.%04d.ply' --frames 1-1 --quiet "
                                      "--velocity-vdb '" + dir + "/dam_break/dam_break.%04d.vdb' --velocity-grid vel"),
                              nullptr, &err, tmp),
            2);
  EXPECT_NE(err.find("dam_break.0001.vdb (frame 1): no vector grid named 'vel'"), std::string::npos) << err;
}

TEST(InspectCommand, NamesTheVertexPropertiesALayerRuleMayRead) {
  TempDir tmp("inspect_attributes");
  test::write_heat_plane(tmp.str(), 2, [](double x, int) { return x; });
  std::string out, err;
  ASSERT_EQ(test::run_command(inspect("'" + (tmp / "m.%04d.ply") + "' --json --quiet"), &out, &err, tmp), 0) << err;
  EXPECT_EQ(nlohmann::json::parse(out)["summary"]["vertex_attributes"], nlohmann::json::array({"heat"}));
  ASSERT_EQ(test::run_command(inspect("'" + (tmp / "m.%04d.ply") + "'"), &out, &err, tmp), 0) << err;
  EXPECT_NE(out.find("rule attributes   speed, curvature, heat"), std::string::npos) << out;
}
