// lapflow inspect's analysis (addons/inspect.hpp).
#include "lapflow/addons/inspect.hpp"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>

#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow {
namespace {

/// Speeds over the referenced vertices, with --min-speed applied (slower = 0).
SpeedStats speed_stats(const std::vector<Vec3>& v, const std::vector<uint8_t>& referenced, double min_speed) {
  SpeedStats s;
  s.present = true;
  s.min = INFINITY;
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (!referenced[i]) continue;
    double sp = norm(v[i]);
    if (sp < min_speed) sp = 0;
    s.min = std::min(s.min, sp);
    s.max = std::max(s.max, sp);
    sum += sp;
    ++n;
  }
  if (n == 0) s.min = 0;
  s.mean = n ? sum / double(n) : 0;
  return s;
}

void inspect_frame(const InspectOptions& o, const FramePattern& mesh_pattern, const std::optional<FramePattern>& vdb,
                   FrameInspection& r) {
  r.file = mesh_pattern.path(r.frame);
  // Absurd bounds are read and reported here, not refused: the user runs
  // inspect to find out what is wrong with the sequence.
  const MeshFile file = read_mesh_file(r.file, false);
  const TriMesh& m = file.mesh;
  r.report = analyze_mesh(m);
  r.warnings = units_problems(m, file.declared);
  r.attributes = file.declared.attributes;
  bool sampleable = true;  // OpenVDB's index space overflows beyond kMaxMeshCoordinate
  try {
    check_mesh_bounds(m, r.file);
  } catch (const InputError&) {
    sampleable = false;
  }
  std::vector<uint8_t> referenced(m.vertex_count(), 0);
  for (const Tri& f : m.triangles)
    for (int32_t x : f) referenced[x] = 1;
  if (m.has_velocities()) r.vertex_speed = speed_stats(m.velocities, referenced, o.min_speed);
  if (!vdb || !sampleable) return;
  const VelocityGrid grid(vdb->path(r.frame), o.grid_name);
  r.grid_name = grid.grid_name();
  std::vector<Vec3> sampled(m.vertex_count());
  parallel_for(sampled.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i)
      if (referenced[i]) sampled[i] = grid.sample(m.positions[i]);
  });
  r.grid_speed = speed_stats(sampled, referenced, o.min_speed);
  double fastest = 0;
  std::size_t at = 0;
  for (std::size_t i = 0; i < sampled.size(); ++i)
    if (referenced[i] && norm(sampled[i]) > fastest) fastest = norm(sampled[i]), at = i;
  if (!(fastest <= kMaxLiquidSpeed))
    r.warnings.push_back(speed_problem(fastest, at, "the VDB grid '" + r.grid_name + "'"));
  if (m.has_velocities()) {
    double diff = 0, base = 0;
    for (std::size_t i = 0; i < sampled.size(); ++i) {
      if (!referenced[i]) continue;
      diff += norm(sampled[i] - m.velocities[i]);
      base += norm(m.velocities[i]);
    }
    r.grid_difference = base > 0 ? diff / base : (diff > 0 ? INFINITY : 0);
  }
}

}  // namespace

std::vector<FrameInspection> inspect_sequence(const InspectOptions& o, const std::function<void(int frame, std::size_t total)>& done) {
  const FramePattern mesh_pattern(o.mesh_pattern);
  std::optional<FrameRange> range;
  if (!o.frames.empty()) range = parse_frame_range(o.frames);
  const std::vector<int> frames = resolve_frames(mesh_pattern, range);
  std::optional<FramePattern> vdb;
  if (!o.vdb_pattern.empty()) vdb.emplace(o.vdb_pattern);

  std::vector<FrameInspection> results(frames.size());
  std::mutex done_mutex;
  parallel_for(frames.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      FrameInspection& r = results[i];
      r.frame = frames[i];
      try {
        inspect_frame(o, mesh_pattern, vdb, r);
      } catch (const InputError& err) {
        // One bad frame must not hide the others: record it, report all.
        r.error = std::make_exception_ptr(err.with_frame(r.frame));
        r.error_text = printable_line(err.with_frame(r.frame).what());
      } catch (const std::exception& err) {
        r.error = std::current_exception();
        r.error_text = printable_line(err.what());
      }
      std::lock_guard lock(done_mutex);
      if (done) done(r.frame, frames.size());
    }
  }, 1);

  return results;
}

InspectSummary summarize(const std::vector<FrameInspection>& results) {
  InspectSummary s;
  double tri_sum = 0, diff_sum = 0;
  std::size_t diff_n = 0;
  for (const FrameInspection& r : results) {
    if (r.error) {
      s.unreadable.push_back(r.frame);
      continue;
    }
    const MeshReport& m = r.report;
    // The properties every readable frame has.
    if (s.readable == 0)
      s.attributes = r.attributes;
    else
      std::erase_if(s.attributes, [&](const std::string& a) {
        return std::find(r.attributes.begin(), r.attributes.end(), a) == r.attributes.end();
      });
    ++s.readable;
    if (m.triangles == 0) s.empty.push_back(r.frame);
    if (m.triangles < s.tri_min) s.tri_min = m.triangles, s.tri_min_frame = r.frame;
    if (m.triangles > s.tri_max) s.tri_max = m.triangles, s.tri_max_frame = r.frame;
    tri_sum += double(m.triangles);
    s.non_manifold_edges += m.non_manifold_edges;
    s.non_manifold_vertices += m.non_manifold_vertices;
    if (m.non_manifold_edges + m.non_manifold_vertices > 0) s.frames_with_non_manifold.push_back(r.frame);
    if (m.boundary_edges > 0) s.frames_with_boundary.push_back(r.frame);
    if (!r.warnings.empty()) s.frames_with_warnings.push_back(r.frame);
    s.degenerate += m.degenerate_triangles;
    s.boundary += m.boundary_edges;
    s.isolated += m.isolated_vertices;
    if (!m.bounds.empty()) s.bounds.extend(m.bounds.lo), s.bounds.extend(m.bounds.hi);
    const SpeedStats& sp = used_speed(r);
    if (!sp.present && m.triangles > 0) s.frames_without_velocity.push_back(r.frame);
    if (sp.present && sp.max > s.peak_speed) s.peak_speed = sp.max, s.peak_frame = r.frame;
    if (r.grid_difference >= 0) {
      diff_sum += r.grid_difference;
      ++diff_n;
      if (r.grid_difference > s.worst_difference) s.worst_difference = r.grid_difference, s.worst_difference_frame = r.frame;
    }
  }
  if (s.readable == 0) s.tri_min = 0;
  s.tri_mean = s.readable ? tri_sum / double(s.readable) : 0;
  s.mean_difference = diff_n ? diff_sum / double(diff_n) : -1;
  return s;
}

namespace {

nlohmann::json box_json(const Box3& b) {
  if (b.empty()) return nullptr;
  return {{"min", {b.lo.x, b.lo.y, b.lo.z}}, {"max", {b.hi.x, b.hi.y, b.hi.z}}};
}

nlohmann::json speed_json(const SpeedStats& s) {
  if (!s.present) return nullptr;
  return {{"min", s.min}, {"mean", s.mean}, {"max", s.max}};
}

}  // namespace

std::string inspection_warning(const FrameInspection& r, const std::string& problem) {
  return InputError(r.file, problem, r.frame).what();
}

namespace {

nlohmann::json inspection_json_value(const InspectOptions& o, const std::vector<FrameInspection>& results, const InspectSummary& s) {
  nlohmann::json frames = nlohmann::json::array(), all_warnings = nlohmann::json::array();
  for (const FrameInspection& r : results)
    for (const std::string& w : r.warnings) all_warnings.push_back(inspection_warning(r, w));
  for (const FrameInspection& r : results) {
    nlohmann::json f = {{"frame", r.frame}, {"file", r.file}};
    if (r.error) {
      f["error"] = r.error_text;
    } else {
      const MeshReport& m = r.report;
      f.update({{"triangles", m.triangles}, {"vertices", m.vertices}, {"components", m.components},
                {"non_manifold_edges", m.non_manifold_edges}, {"non_manifold_vertices", m.non_manifold_vertices},
                {"boundary_edges", m.boundary_edges}, {"degenerate_triangles", m.degenerate_triangles},
                {"isolated_vertices", m.isolated_vertices}, {"area", m.area}, {"bounds", box_json(m.bounds)},
                {"empty", m.triangles == 0}, {"velocity_source", r.grid_speed.present ? "vdb" : (r.vertex_speed.present ? "vertex" : "none")},
                {"speed", speed_json(used_speed(r))}, {"vertex_speed", speed_json(r.vertex_speed)},
                {"warnings", r.warnings}});
      if (r.grid_speed.present) {
        f["grid"] = {{"name", r.grid_name}, {"speed", speed_json(r.grid_speed)}};
        f["grid"]["relative_difference"] = r.grid_difference >= 0 ? nlohmann::json(r.grid_difference) : nlohmann::json(nullptr);
      }
    }
    frames.push_back(std::move(f));
  }
  nlohmann::json summary = {{"frames", results.size()},
                            {"first_frame", results.front().frame},
                            {"last_frame", results.back().frame},
                            {"readable_frames", s.readable},
                            {"unreadable_frames", s.unreadable},
                            {"empty_frames", s.empty},
                            {"triangles", {{"min", s.tri_min}, {"mean", s.tri_mean}, {"max", s.tri_max}}},
                            {"non_manifold_edges", s.non_manifold_edges},
                            {"non_manifold_vertices", s.non_manifold_vertices},
                            {"boundary_edges", s.boundary},
                            {"degenerate_triangles", s.degenerate},
                            {"isolated_vertices", s.isolated},
                            {"bounds", box_json(s.bounds)},
                            {"peak_speed", s.peak_speed},
                            {"peak_speed_frame", s.peak_frame},
                            {"frames_without_velocity", s.frames_without_velocity},
                            {"frames_with_warnings", s.frames_with_warnings},
                            {"warnings", all_warnings},
                            {"min_speed", o.min_speed},
                            {"vertex_attributes", s.attributes}};
  if (s.mean_difference >= 0)
    summary["grid_relative_difference"] = {{"mean", s.mean_difference}, {"worst", s.worst_difference},
                                           {"worst_frame", s.worst_difference_frame}};
  return {{"mesh_pattern", o.mesh_pattern}, {"velocity_vdb", o.vdb_pattern.empty() ? nlohmann::json(nullptr) : nlohmann::json(o.vdb_pattern)},
          {"frames", std::move(frames)}, {"summary", std::move(summary)}};
}

}  // namespace

std::string inspection_json(const InspectOptions& o, const std::vector<FrameInspection>& results,
                            const InspectSummary& s) {
  // Invalid UTF-8 in a path would make dump() throw: replaced instead.
  return inspection_json_value(o, results, s).dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace lapflow
