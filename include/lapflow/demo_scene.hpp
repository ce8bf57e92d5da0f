#pragma once
/// \file demo_scene.hpp The built-in demo: a liquid-like blob in the 3D
/// single-vortex deformation field of Enright, Fedkiw, Ferziger and Mitchell
/// 2002 (LeVeque's test), re-meshed every frame from its level set so that,
/// like real data, every frame is a different mesh. Also a flat 2D case like
/// the paper's 2D example.
#include <string>

#include "lapflow/mesh.hpp"

namespace lapflow {

enum class DemoCase {
  Vortex,  ///< sphere of radius 0.15 at (0.35, 0.35, 0.35) in the unit box
  Slab,    ///< thin slab whose top face is swirled, with a split and merge
};

struct DemoOptions {
  DemoCase scene = DemoCase::Vortex;
  int frames = 48;          ///< number of frames written (frame 1 is t = 0)
  double fps = 24;          ///< frame rate; dt = 1/fps seconds
  double period = 2.0;      ///< T in seconds: the field reverses, the shape returns at t = T
  double voxel_size = 1.0 / 128;  ///< level-set voxel (metres); smaller = more triangles
};

/// The analytic velocity (m/s) of the demo case at point p and time t.
Vec3 demo_velocity(DemoCase scene, const Vec3& p, double t, double period);

/// The demo surface at frame `frame` (1-based; t = (frame-1)/fps), with exact
/// per-vertex velocities from the analytic field.
TriMesh demo_frame(const DemoOptions& options, int frame);

/// Voxel size that gives about `triangles` triangles at frame 1.
double demo_voxel_size_for(DemoCase scene, double triangles);

}  // namespace lapflow
