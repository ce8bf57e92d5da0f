// Closest-point and ray queries on a frame's surface, backed by Embree 3.
// Embree's BVH is in float; the closest point itself is recomputed in double
// from the mesh's own positions, so the projection residual is not limited by
// float precision.
#include "lapflow/surface/surface_query.hpp"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <vector>

#include "lapflow/core/errors.hpp"

namespace lapflow {

TrianglePoint closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  // Voronoi regions of the triangle: vertices, then edges, then the face.
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return {a, 0, 0};
  const Vec3 bp = p - b;
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return {b, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {a + ab * v, v, 0};
  }
  const Vec3 cp = p - c;
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return {c, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {a + ac * w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {b + (c - b) * w, 1 - w, w};
  }
  // sum = |ab x ac|^2. When the corners are (nearly) collinear the signs
  // above are rounding noise and the face formula divides by it: the
  // closest point is then on one of the three edges.
  const double sum = va + vb + vc;
  if (!(sum > 1e-12 * dot(ab, ab) * dot(ac, ac))) {
    auto on_segment = [&](const Vec3& s, const Vec3& e) {
      const Vec3 d = e - s;
      const double len2 = dot(d, d);
      return len2 > 0 ? std::clamp(dot(p - s, d) / len2, 0.0, 1.0) : 0.0;
    };
    const double tab = on_segment(a, b), tac = on_segment(a, c), tbc = on_segment(b, c);
    TrianglePoint best{a + ab * tab, tab, 0};
    const TrianglePoint other[2] = {{a + ac * tac, 0, tac}, {b + (c - b) * tbc, 1 - tbc, tbc}};
    for (const TrianglePoint& q : other)
      if (norm2(q.point - p) < norm2(best.point - p)) best = q;
    return best;
  }
  const double v = vb / sum, w = vc / sum;
  return {a + ab * v + ac * w, v, w};
}

namespace {

RTCDevice shared_device() {
  // One device for the process: devices are thread-safe and costly to create.
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice(nullptr);
    if (!d) throw std::runtime_error("Embree: cannot create a device");
    return d;
  }();
  return device;
}

// What the callback reads of one triangle, in one place: its bounding box
// (float, rounded outward from the double positions) and its corners.
struct TriangleRecord {
  float lo[3], hi[3];
  Vec3 a, b, c;
};

struct QueryState {
  const TriangleRecord* records;
  Vec3 p;
  ClosestHit best;
  double best_d2;
};

bool point_query_callback(RTCPointQueryFunctionArguments* args) {
  auto* s = static_cast<QueryState*>(args->userPtr);
  const int t = int(args->primID);
  // Embree calls back for every triangle of a leaf whose node meets the
  // query sphere; most of them are farther than the sphere's radius, which
  // their bounding box shows for a fraction of the exact closest point's
  // cost. The box holds the triangle, so a box beyond the radius means a
  // triangle beyond it: no closer point (nor tie) is skipped.
  const TriangleRecord& rec = s->records[t];
  {
    const TriangleRecord& b = rec;
    const double dx = std::max({double(b.lo[0]) - s->p.x, s->p.x - double(b.hi[0]), 0.0});
    const double dy = std::max({double(b.lo[1]) - s->p.y, s->p.y - double(b.hi[1]), 0.0});
    const double dz = std::max({double(b.lo[2]) - s->p.z, s->p.z - double(b.hi[2]), 0.0});
    const double radius = args->query->radius;
    if (dx * dx + dy * dy + dz * dz > radius * radius) return false;
  }
  const TrianglePoint h = closest_point_on_triangle(s->p, rec.a, rec.b, rec.c);
  const double d2 = norm2(h.point - s->p);
  // Exact ties (shared edges and vertices) go to the lowest index so the
  // answer does not depend on BVH traversal order.
  if (d2 < s->best_d2 || (d2 == s->best_d2 && t < s->best.triangle)) {
    s->best_d2 = d2;
    s->best = {true, t, h.point, h.b1, h.b2, std::sqrt(d2)};
    // Shrink the query sphere (Embree's radius is float: round up a little).
    const float r = float(std::sqrt(d2)) * (1 + 1e-6f) + 1e-30f;
    if (r < args->query->radius) {
      args->query->radius = r;
      return true;
    }
  }
  return false;
}

}  // namespace

struct SurfaceQuery::Impl {
  RTCScene scene = nullptr;
  std::vector<float> vertices;      // xyz per vertex + padding for 16-byte loads
  std::vector<uint32_t> indices;
  std::vector<TriangleRecord> records;  // per triangle
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
  }
};

SurfaceQuery::SurfaceQuery(const TriMesh& mesh) : mesh_(mesh), impl_(std::make_unique<Impl>()) {
  if (mesh.triangles.empty()) return;  // an empty frame: every query finds nothing
  RTCDevice device = shared_device();
  impl_->vertices.resize(3 * mesh.positions.size() + 4, 0.f);
  for (std::size_t i = 0; i < mesh.positions.size(); ++i)
    for (int k = 0; k < 3; ++k) impl_->vertices[3 * i + k] = float(mesh.positions[i][k]);
  impl_->indices.resize(3 * mesh.triangles.size());
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) impl_->indices[3 * t + k] = uint32_t(mesh.triangles[t][k]);

  impl_->records.resize(mesh.triangles.size());
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Tri& f = mesh.triangles[t];
    TriangleRecord& rec = impl_->records[t];
    rec.a = mesh.positions[f[0]], rec.b = mesh.positions[f[1]], rec.c = mesh.positions[f[2]];
    for (int k = 0; k < 3; ++k) {
      const double lo = std::min({mesh.positions[f[0]][k], mesh.positions[f[1]][k], mesh.positions[f[2]][k]});
      const double hi = std::max({mesh.positions[f[0]][k], mesh.positions[f[1]][k], mesh.positions[f[2]][k]});
      float flo = float(lo), fhi = float(hi);
      if (double(flo) > lo) flo = std::nextafter(flo, -std::numeric_limits<float>::infinity());
      if (double(fhi) < hi) fhi = std::nextafter(fhi, std::numeric_limits<float>::infinity());
      rec.lo[k] = flo;
      rec.hi[k] = fhi;
    }
  }

  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, impl_->vertices.data(), 0,
                             3 * sizeof(float), mesh.positions.size());
  rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, impl_->indices.data(), 0,
                             3 * sizeof(uint32_t), mesh.triangles.size());
  rtcCommitGeometry(geom);
  impl_->scene = rtcNewScene(device);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  rtcAttachGeometry(impl_->scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(impl_->scene);
  if (rtcGetDeviceError(device) != RTC_ERROR_NONE) throw std::runtime_error("Embree: scene build failed");
}

SurfaceQuery::~SurfaceQuery() = default;

bool within_rounding_of_triangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  double scale = std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)});
  for (const Vec3* v : {&a, &b, &c}) scale = std::max({scale, std::abs(v->x), std::abs(v->y), std::abs(v->z)});
  return norm(q - p) <= 16 * std::numeric_limits<double>::epsilon() * scale;
}

ClosestHit SurfaceQuery::closest(const Vec3& p, double max_distance) const {
  QueryState state{impl_->records.data(), p, {}, std::numeric_limits<double>::infinity()};
  if (!impl_->scene || !is_finite(p)) return state.best;
  RTCPointQuery query;
  query.x = float(p.x);
  query.y = float(p.y);
  query.z = float(p.z);
  query.time = 0.f;
  // Float BVH bounds: widen the radius slightly so no candidate is culled.
  query.radius = std::isfinite(max_distance) ? float(max_distance) * (1 + 1e-5f) + 1e-7f
                                             : std::numeric_limits<float>::infinity();
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &query, &context, point_query_callback, &state);
  if (state.best.found && state.best.distance > max_distance) state.best = {};
  // A point already on the surface projects to itself, bit for bit: without
  // this, re-projecting still patches every frame would drift by rounding and
  // a still scene would not bake to identical atlases.
  if (state.best.found) {
    const Tri& f = mesh_.triangles[state.best.triangle];
    if (within_rounding_of_triangle(p, state.best.point, mesh_.positions[f[0]], mesh_.positions[f[1]],
                                    mesh_.positions[f[2]])) {
      state.best.point = p;
      state.best.distance = 0;
    }
  }
  return state.best;
}

RayHit SurfaceQuery::intersect(const Vec3& origin, const Vec3& dir, double t_min, double t_max) const {
  RayHit hit;
  if (!impl_->scene) return hit;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh{};
  rh.ray.org_x = float(origin.x);
  rh.ray.org_y = float(origin.y);
  rh.ray.org_z = float(origin.z);
  rh.ray.dir_x = float(dir.x);
  rh.ray.dir_y = float(dir.y);
  rh.ray.dir_z = float(dir.z);
  rh.ray.tnear = float(t_min);
  rh.ray.tfar = std::isfinite(t_max) ? float(t_max) : std::numeric_limits<float>::infinity();
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
  hit.found = true;
  hit.triangle = int(rh.hit.primID);
  hit.t = rh.ray.tfar;
  hit.b1 = rh.hit.u;
  hit.b2 = rh.hit.v;
  return hit;
}

}  // namespace lapflow
