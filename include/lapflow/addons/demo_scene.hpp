#pragma once
/// \file demo_scene.hpp The built-in demo: a liquid-like blob in the 3D
/// single-vortex deformation field of Enright, Fedkiw, Ferziger and Mitchell
/// 2002 (LeVeque's test), re-meshed every frame from its level set so that,
/// like real data, every frame is a different mesh. Also a flat 2D case like
/// the paper's 2D example.
#include <cstddef>
#include <functional>
#include <string>

#include "lapflow/surface/mesh.hpp"

namespace lapflow {

enum class DemoCase {
  Vortex,  ///< sphere of radius 0.15 at (0.35, 0.35, 0.35) in the unit box
  Slab,    ///< 4 cm thin disk slab (radius 0.15 at (0.5, 0.75), z = 0.5) in LeVeque's 2D single
           ///< vortex (x, y swirl): its spiral tail splits off and merges back
};

struct DemoOptions {
  DemoCase scene = DemoCase::Vortex;
  int frames = 49;          ///< number of frames written (frame 1 is t = 0; frame 49 is t = T at the defaults)
  double fps = 24;          ///< frame rate; dt = 1/fps seconds
  double period = 2.0;      ///< T in seconds: the field reverses, the shape returns at t = T
  double voxel_size = 1.0 / 128;  ///< level-set voxel (metres); smaller = more triangles
};

/// The analytic velocity (m/s) of the demo case at point p and time t.
Vec3 demo_velocity(DemoCase scene, const Vec3& p, double t, double period);

/// Where the flow carries point p from time t0 to time t1 (seconds; t1 < t0
/// goes backward). Exact up to the RK4 trace (error far below a voxel).
Vec3 demo_flow_map(DemoCase scene, const Vec3& p, double t0, double t1, double period);

/// The demo surface at frame `frame` (1-based; t = (frame-1)/fps), with exact
/// per-vertex velocities from the analytic field.
TriMesh demo_frame(const DemoOptions& options, int frame);

/// Voxel size (metres) that gives about `triangles` triangles at frame 1
/// (mid-period frames have more; docs/demo_scene.md, "Numbers").
double demo_voxel_size_for(DemoCase scene, double triangles);

/// `DIR/NAME.%04d.ply` for frame f.
std::string demo_frame_path(const std::string& dir, const std::string& name, int frame);

struct DemoSequenceStats {
  int frames = 0;
  std::size_t triangles_min = 0, triangles_max = 0;
  double triangles_mean = 0;
  double seconds = 0;  ///< wall clock, generation and writing
};
/// Generates frames 1..options.frames and writes each as binary PLY with
/// velocities to demo_frame_path(dir, name, f) (atomically; creates `dir`),
/// calling on_frame(f, mesh) after each write (progress, or a bake reusing the
/// mesh). Throws OutputError.
DemoSequenceStats write_demo_sequence(const DemoOptions& options, const std::string& dir, const std::string& name,
                                      const std::function<void(int, const TriMesh&)>& on_frame = {});

}  // namespace lapflow
