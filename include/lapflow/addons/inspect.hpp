// `lapflow inspect`'s analysis: every frame of a liquid surface sequence
// read and reported (topology, bounds, velocity and where it comes from,
// units warnings), and a summary over the sequence. docs/io.md.
#pragma once

#include <cstdint>
#include <exception>
#include <functional>
#include <string>
#include <vector>

#include "lapflow/surface/mesh.hpp"

namespace lapflow {

struct InspectOptions {
  std::string mesh_pattern;  ///< a frame pattern (FramePattern) or one file
  std::string frames;        ///< "A-B" or "A"; empty: every frame on disk
  std::string vdb_pattern;   ///< OpenVDB velocity sequence; empty: none
  std::string grid_name;     ///< its vector grid; empty: vel, v, velocity
  double min_speed = 0;      ///< speeds below it (m/s) count as 0, as in the bake
};

struct SpeedStats {
  bool present = false;
  double min = 0, mean = 0, max = 0;
};

/// One frame's report. A frame that could not be read has `error` set (an
/// InputError names the file and frame) and nothing else.
struct FrameInspection {
  int frame = 0;
  std::string file;
  std::exception_ptr error;
  std::string error_text;  ///< error's message on one printable line
  MeshReport report;
  SpeedStats vertex_speed;  ///< from the PLY's vertex properties
  SpeedStats grid_speed;    ///< from the VDB sampled at the vertices
  std::string grid_name;
  std::vector<std::string> attributes;  ///< the PLY's other vertex properties (MeshFileInfo::attributes)
  double grid_difference = -1;  ///< sum |v_grid - v_vertex| / sum |v_vertex|; -1 = not measured
  /// Sizes, speeds and property types no liquid has (units_problems): a
  /// bake refuses the frame unless --units-ok.
  std::vector<std::string> warnings;
};

/// The velocity a bake would use: the VDB's when given, else the vertices'.
inline const SpeedStats& used_speed(const FrameInspection& r) {
  return r.grid_speed.present ? r.grid_speed : r.vertex_speed;
}

/// Every frame of the sequence, in frame order, read in parallel. A frame
/// that cannot be read does not stop the others (FrameInspection::error);
/// a missing frame in `frames` or a malformed pattern throws InputError or
/// UsageError. `done(frame, total)` is called once per frame as it is
/// finished, one call at a time (total: the frames inspected).
std::vector<FrameInspection> inspect_sequence(const InspectOptions& options,
                                              const std::function<void(int frame, std::size_t total)>& done = {});

struct InspectSummary {
  std::size_t readable = 0;
  std::vector<int> empty, unreadable;
  std::size_t tri_min = SIZE_MAX, tri_max = 0;
  int tri_min_frame = 0, tri_max_frame = 0;
  double tri_mean = 0;
  std::size_t non_manifold_edges = 0, non_manifold_vertices = 0, degenerate = 0, boundary = 0, isolated = 0;
  std::vector<int> frames_with_non_manifold, frames_with_boundary, frames_without_velocity, frames_with_warnings;
  /// Vertex properties every readable frame has (what a layer rule may read besides speed and curvature).
  std::vector<std::string> attributes;
  Box3 bounds;
  double peak_speed = 0;
  int peak_frame = 0;
  double worst_difference = -1, mean_difference = 0;
  int worst_difference_frame = 0;
};

InspectSummary summarize(const std::vector<FrameInspection>& frames);

/// "file (frame N): problem", as an error names a frame.
std::string inspection_warning(const FrameInspection& r, const std::string& problem);

/// `lapflow inspect --json`: the options, every frame and the summary as
/// JSON text, indented by 2 (invalid UTF-8 in a path replaced).
std::string inspection_json(const InspectOptions& options, const std::vector<FrameInspection>& results,
                            const InspectSummary& summary);

}  // namespace lapflow
