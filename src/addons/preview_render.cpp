// The preview renderer: one Embree scene per frame, primary and shadow rays
// one at a time (rtcIntersect1 / rtcOccluded1), shading as documented on
// PreviewLook. Every random number is hash64(pixel, sample, purpose): the
// picture does not depend on the thread count.
#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "lapflow/core/parallel.hpp"
#include "lapflow/addons/preview.hpp"
#include "raster/sampling.hpp"

namespace lapflow {
namespace {

RTCDevice preview_device() {
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice(nullptr);
    if (!d) throw std::runtime_error("Embree: cannot create a device");
    return d;
  }();
  return device;
}

/// The frame's triangles in an Embree scene (nothing when the frame is empty).
class RayScene {
 public:
  explicit RayScene(const TriMesh& mesh) {
    if (mesh.triangles.empty()) return;
    vertices_.resize(3 * mesh.positions.size() + 4, 0.f);
    for (std::size_t i = 0; i < mesh.positions.size(); ++i)
      for (int k = 0; k < 3; ++k) vertices_[3 * i + k] = float(mesh.positions[i][k]);
    indices_.resize(3 * mesh.triangles.size());
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
      for (int k = 0; k < 3; ++k) indices_[3 * t + k] = uint32_t(mesh.triangles[t][k]);
    RTCDevice device = preview_device();
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices_.data(), 0,
                               3 * sizeof(float), mesh.positions.size());
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices_.data(), 0,
                               3 * sizeof(uint32_t), mesh.triangles.size());
    rtcCommitGeometry(geom);
    scene_ = rtcNewScene(device);
    rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
    rtcAttachGeometry(scene_, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene_);
  }
  ~RayScene() {
    if (scene_) rtcReleaseScene(scene_);
  }
  RayScene(const RayScene&) = delete;
  RayScene& operator=(const RayScene&) = delete;

  struct Hit {
    int triangle = -1;
    float t = 0, b1 = 0, b2 = 0;
  };

  Hit intersect(const Vec3& o, const Vec3& d, float t_max) const {
    Hit hit;
    if (!scene_) return hit;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh{};
    rh.ray.org_x = float(o.x), rh.ray.org_y = float(o.y), rh.ray.org_z = float(o.z);
    rh.ray.dir_x = float(d.x), rh.ray.dir_y = float(d.y), rh.ray.dir_z = float(d.z);
    rh.ray.tnear = 0.f;
    rh.ray.tfar = t_max;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene_, &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
    hit.triangle = int(rh.hit.primID);
    hit.t = rh.ray.tfar;
    hit.b1 = rh.hit.u;
    hit.b2 = rh.hit.v;
    return hit;
  }

  bool occluded(const Vec3& o, const Vec3& d, float t_max) const {
    if (!scene_) return false;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRay ray{};
    ray.org_x = float(o.x), ray.org_y = float(o.y), ray.org_z = float(o.z);
    ray.dir_x = float(d.x), ray.dir_y = float(d.y), ray.dir_z = float(d.z);
    ray.tnear = 0.f;
    ray.tfar = t_max;
    ray.mask = 0xFFFFFFFFu;
    rtcOccluded1(scene_, &context, &ray);
    return ray.tfar < 0.f;  // Embree sets tfar to -inf on a hit
  }

 private:
  RTCScene scene_ = nullptr;
  std::vector<float> vertices_;
  std::vector<uint32_t> indices_;
};

Vec3 mul(const Vec3& a, const Vec3& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
Vec3 lerp(const Vec3& a, const Vec3& b, double t) { return a + (b - a) * t; }

Vec3 sky(const PreviewLook& look, const Vec3& d) {
  return lerp(look.horizon, look.zenith, std::sqrt(std::max(0.0, dot(d, look.up))));
}

/// What a reflection sees: the sky above the horizon, the lit ground's
/// average colour below it.
Vec3 environment(const PreviewLook& look, const Vec3& d) {
  const double e = dot(d, look.up);
  if (e >= 0) return sky(look, d);
  const Vec3 ground = mul(look.ground_albedo, look.key * std::max(0.0, dot(look.up, normalized(look.light_dir))) +
                                                  look.sky_fill * look.ambient);
  return lerp(look.horizon, look.ground ? ground : look.horizon, std::sqrt(std::min(1.0, -e * 4)));
}

/// Any unit vector perpendicular to n.
Vec3 perpendicular(const Vec3& n) {
  const Vec3 a = std::abs(n.x) < 0.7 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  return normalized(cross(n, a));
}

/// The camera's ray basis.
struct RayCamera {
  Vec3 eye, forward, right, up;
  double tan_half = 0, aspect = 1;
  RayCamera(const PreviewCamera& c, double aspect_) : eye(c.eye), aspect(aspect_) {
    forward = normalized(c.target - c.eye);
    if (norm(forward) == 0) throw std::invalid_argument("preview camera: eye and target coincide");
    Vec3 world_up = normalized(c.up);
    if (std::abs(dot(world_up, forward)) > 0.999) world_up = perpendicular(forward);
    right = normalized(cross(forward, world_up));
    up = cross(right, forward);
    tan_half = std::tan(0.5 * std::clamp(c.fov, 1.0, 170.0) * std::numbers::pi / 180);
  }
  /// Direction through image point (x, y) in pixels of a w x h picture (y down).
  Vec3 direction(double x, double y, int w, int h) const {
    const double sx = (2 * x / w - 1) * tan_half * aspect, sy = (1 - 2 * y / h) * tan_half;
    return normalized(forward + right * sx + up * sy);
  }
};

/// Everything one sample needs, fixed for the frame.
struct Shader {
  const PreviewFrame& frame;
  const RayScene& scene;
  const PreviewLook& look;
  RayCamera camera;
  Vec3 light;          // towards the key light (unit)
  Vec3 light_u, light_v;  // basis of the light's disk
  double light_tan;    // tan of its angular radius
  double ground_height;
  Vec3 ground_center;  // fade centre
  double fade_near, fade_far;
  double eps;          // ray offset, metres
  float t_far;
  double pixel_angle;  // radians per sample footprint
  double bump_height;  // metres per displacement unit

  /// A direction towards the light's disk from a point of [0,1)^2.
  Vec3 light_sample(const Vec2& q) const {
    if (light_tan <= 0) return light;
    const double r = std::sqrt(q.x) * light_tan, a = 2 * std::numbers::pi * q.y;
    return normalized(light + light_u * (r * std::cos(a)) + light_v * (r * std::sin(a)));
  }

  /// Key light visible fraction (0 or 1 for one sample) from p along l.
  double visibility(const Vec3& p, const Vec3& l) const {
    return scene.occluded(p, l, t_far) ? 0.0 : 1.0;
  }

  Vec3 ambient(const Vec3& n) const {
    return lerp(look.ground_fill, look.sky_fill, 0.5 * (1 + dot(n, look.up))) * look.ambient;
  }

  Vec3 shade_ground(const Vec3& p, const Vec3& d, const Vec2& q) const {
    const Vec3 l = light_sample(q);
    const double nl = dot(look.up, l);
    const double s = nl > 0 ? visibility(p + look.up * eps, l) : 0.0;
    Vec3 c = mul(look.ground_albedo, look.key * (s * std::max(0.0, nl)) + ambient(look.up));
    // Far ground fades into the horizon colour so the plane has no edge.
    const Vec3 off = p - ground_center;
    const double r = norm(off - look.up * dot(off, look.up));
    double f = std::clamp((r - fade_near) / (fade_far - fade_near), 0.0, 1.0);
    f = f * f * (3 - 2 * f);
    return lerp(c, sky(look, d), f);
  }

  Vec3 shade_surface(const RayScene::Hit& hit, const Vec3& d, const Vec2& q) const {
    const TriMesh& m = frame.mesh.mesh;
    const Tri& tri = m.triangles[hit.triangle];
    const double b1 = hit.b1, b2 = hit.b2, b0 = 1 - b1 - b2;
    const Vec3 &p0 = m.positions[tri[0]], &p1 = m.positions[tri[1]], &p2 = m.positions[tri[2]];
    const Vec3 p = p0 * b0 + p1 * b1 + p2 * b2;
    const Vec3 e1 = p1 - p0, e2 = p2 - p0;
    Vec3 ng = normalized(cross(e1, e2));
    Vec3 n = normalized(frame.normals[tri[0]] * b0 + frame.normals[tri[1]] * b1 + frame.normals[tri[2]] * b2);
    if (norm(n) == 0) n = ng;
    if (dot(ng, d) > 0) {  // the back side (an open sheet, or inside a wall-hugging surface)
      ng = -ng;
      n = -n;
    }
    const Vec3 v = -d;

    // Texture: uv, footprint -> mip level, colour and height.
    float tex[4] = {0.8f, 0.8f, 0.8f, 0.f};
    Vec3 shading_n = n;
    if (!frame.mesh.corner_uv.empty() && !frame.texture.levels.empty()) {
      const Vec2* uv = &frame.mesh.corner_uv[3 * std::size_t(hit.triangle)];
      const Vec2 st = uv[0] * b0 + uv[1] * b1 + uv[2] * b2;
      const Vec2 d1 = uv[1] - uv[0], d2 = uv[2] - uv[0];
      const double uv_area2 = cross(d1, d2), area2 = norm(cross(e1, e2));
      const Image& base = frame.texture.levels[0];
      double lod = 0;
      if (std::abs(uv_area2) > 0 && area2 > 0) {
        const double texels_per_metre = std::sqrt(std::abs(uv_area2) / area2) * base.width;
        // The footprint's long axis (blurry rather than shimmering at grazing angles).
        const double cos_view = std::max(0.1, std::abs(dot(ng, v)));
        const double footprint = hit.t * pixel_angle / cos_view;
        lod = std::max(0.0, std::log2(std::max(1e-9, footprint * texels_per_metre)));
      }
      detail::sample(frame.texture, st.x, st.y, lod, tex);
      if (frame.bump && bump_height > 0 && std::abs(uv_area2) > 0) {
        // Surface gradient of the height (Mikkelsen 2020, "Surface Gradient
        // Based Bump Mapping"): with dP/du, dP/dv of the triangle,
        // grad h = (h_u (dP/dv x n) + h_v (n x dP/du)) / (dP/du . (dP/dv x n)).
        const double r = 1.0 / uv_area2;
        const Vec3 dpdu = (e1 * d2.y - e2 * d1.y) * r, dpdv = (e2 * d1.x - e1 * d2.x) * r;
        const int last = int(frame.texture.levels.size()) - 1;
        const Image& level = frame.texture.levels[std::min(last, int(lod + 0.5))];
        const double du = 1.0 / level.width, dv = 1.0 / level.height;
        float a[4], b[4], c[4], e[4];
        detail::bilinear<4>(level, st.x + du, st.y, a);
        detail::bilinear<4>(level, st.x - du, st.y, b);
        detail::bilinear<4>(level, st.x, st.y + dv, c);
        detail::bilinear<4>(level, st.x, st.y - dv, e);
        const double hu = bump_height * (a[3] - b[3]) / (2 * du), hv = bump_height * (c[3] - e[3]) / (2 * dv);
        const Vec3 r1 = cross(dpdv, n), r2 = cross(n, dpdu);
        const double det = dot(dpdu, r1);
        if (std::abs(det) > 0) {
          const Vec3 bent = normalized(n - (r1 * hu + r2 * hv) / det);
          if (norm(bent) > 0) shading_n = bent;
        }
      }
    }
    // A shading normal facing away from the eye shades black: bend it back.
    const double nv0 = dot(shading_n, v);
    if (nv0 < 0.02) shading_n = normalized(shading_n + v * (0.02 - nv0));
    const Vec3 albedo{tex[0], tex[1], tex[2]};

    const double nv = std::clamp(dot(shading_n, v), 0.0, 1.0);
    const double fresnel = look.reflection * (0.02 + 0.98 * std::pow(1 - nv, 5));
    const Vec3 l = light_sample(q);
    const double nl = dot(shading_n, l);
    double s = 0;
    if (nl > 0 && dot(ng, l) > -0.2) s = visibility(p + ng * eps, l);
    Vec3 c = mul(albedo, look.key * (s * std::max(0.0, nl)) + ambient(shading_n)) * (1 - fresnel);
    if (nl > 0 && s > 0 && look.specular > 0) {
      const Vec3 hv = normalized(l + v);
      const double norm_factor = (look.shininess + 8) / (8 * std::numbers::pi);
      c += look.key * (s * look.specular * norm_factor * std::pow(std::max(0.0, dot(shading_n, hv)), look.shininess));
    }
    if (fresnel > 0) c += environment(look, d - shading_n * (2 * dot(d, shading_n))) * fresnel;
    return c;
  }

  /// Radiance along the camera ray d; q picks the point of the light.
  Vec3 trace(const Vec3& d, const Vec2& q) const {
    const RayScene::Hit hit = scene.intersect(camera.eye, d, t_far);
    double t_ground = std::numeric_limits<double>::infinity();
    if (look.ground) {
      const double dn = dot(d, look.up);
      if (dn < -1e-9) t_ground = (ground_height - dot(camera.eye, look.up)) / dn;
      if (t_ground < 0) t_ground = std::numeric_limits<double>::infinity();
    }
    if (hit.triangle >= 0 && hit.t <= t_ground) return shade_surface(hit, d, q);
    if (std::isfinite(t_ground)) return shade_ground(camera.eye + d * t_ground, d, q);
    return sky(look, d);
  }
};

}  // namespace

Image render_preview(const PreviewFrame& frame, const PreviewCamera& camera, const Box3& bounds,
                     const PreviewOptions& o) {
  if (o.width <= 0 || o.height <= 0) throw std::invalid_argument("render_preview: empty picture");
  const int W = o.width, H = o.height, spp = std::max(1, o.samples);
  const RayScene scene(frame.mesh.mesh);
  PreviewLook look = o.look;
  look.up = normalized(look.up);
  if (norm(look.up) == 0) look.up = {0, 0, 1};
  const RayCamera cam(camera, double(W) / H);

  Box3 box = bounds;
  if (box.empty()) box = bounding_box(frame.mesh.mesh);
  if (box.empty()) box.extend(camera.target);
  const double diag = std::max(1e-6, norm(box.size()));

  Vec3 light = normalized(look.light_dir);
  if (norm(light) == 0) {
    // From the camera's upper left and a little behind it.
    Vec3 back = -cam.forward;
    back = normalized(back - look.up * dot(back, look.up));
    const Vec3 right = normalized(cross(look.up, back));  // the camera's right, level with the ground
    light = normalized(look.up * 1.25 - right * 0.75 + back * 0.55);
    if (norm(light) == 0) light = look.up;
  }
  const Vec3 lu = perpendicular(light), lv = cross(light, lu);
  look.light_dir = light;

  const Vec3 c = box.center();
  // Height of the box's lowest point along `up` (exact for any up: the lowest corner).
  double ground_height = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 8; ++k) {
    const Vec3 corner{(k & 1) ? box.hi.x : box.lo.x, (k & 2) ? box.hi.y : box.lo.y, (k & 4) ? box.hi.z : box.lo.z};
    ground_height = std::min(ground_height, dot(corner, look.up));
  }
  ground_height -= 1e-4 * diag;  // the liquid rests on it, not in it

  const Shader shader{frame,
                      scene,
                      look,
                      cam,
                      light,
                      lu,
                      lv,
                      std::tan(std::clamp(look.light_angle, 0.0, 30.0) * std::numbers::pi / 180),
                      ground_height,
                      c,
                      1.5 * diag,
                      6.0 * diag,
                      1e-4 * diag,
                      float(1e3 * diag + norm(camera.eye - c)),
                      2 * cam.tan_half / H / std::sqrt(double(spp)),
                      look.bump * frame.radius};

  // Stratified jitter when spp is a square, else hashed points.
  const int grid = int(std::lround(std::sqrt(double(spp))));
  const bool stratified = grid * grid == spp;
  Image out(W, H, 3);
  parallel_for(std::size_t(H), [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (int x = 0; x < W; ++x) {
        Vec3 sum;
        // The light's strata are the pixel's, shifted by a per-pixel offset,
        // so that soft shadows are stratified too but not tied to position.
        const int shift = int(hash64(uint64_t(x), uint64_t(y), 0x5a17) % uint64_t(spp));
        for (int s = 0; s < spp; ++s) {
          const uint64_t h = hash64(uint64_t(x), uint64_t(y), uint64_t(s), 0x9e11);
          double jx = hash_to_unit(hash64(h, 3)), jy = hash_to_unit(hash64(h, 4));
          Vec2 q{hash_to_unit(hash64(h, 1)), hash_to_unit(hash64(h, 2))};
          if (stratified) {
            jx = ((s % grid) + jx) / grid;
            jy = ((s / grid) + jy) / grid;
            const int ls = (s + shift) % spp;
            q = {((ls % grid) + q.x) / grid, ((ls / grid) + q.y) / grid};
          }
          if (spp == 1) jx = jy = 0.5;
          sum += shader.trace(cam.direction(x + jx, double(y) + jy, W, H), q);
        }
        sum *= 1.0 / spp;
        out.at(x, int(y), 0) = float(sum.x);
        out.at(x, int(y), 1) = float(sum.y);
        out.at(x, int(y), 2) = float(sum.z);
      }
  }, 2);
  return out;
}

}  // namespace lapflow
