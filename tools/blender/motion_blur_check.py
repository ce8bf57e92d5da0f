"""Measures whether Cycles' motion blur of a lapflow bake follows the bake's velocity field.

    blender -b --factory-startup -P tools/blender/motion_blur_check.py -- --bake DIR --frame N --out DIR
        [--shutter 0.5] [--samples 64] [--resolution 640x360] [--tile 32]
        [--camera auto|x,y,z] [--target x,y,z]

Imports the bake through the lapflow_import add-on (lapflow_import.import_bake:
the frame's USD layer, its `velocities` as the point attribute `velocity`, m/s),
gives it a flat emission material (the colour atlas as emitted radiance, no lights,
black world: nothing in the shading depends on time or on the light), puts a fixed
camera on the fast part of the liquid (--camera auto: horizontal-ish, 20 degrees
down, looking across the main horizontal flow) and renders frame N twice with
Cycles: motion blur off (with the Depth and Vector passes) and motion blur on
(shutter --shutter frames, position Center).

Then, per image tile (--tile pixels):
- predicted blur: every vertex visible in the sharp render (its camera depth
  within 3% of the Depth pass at its pixel: depth along the view axis, or
  distance to the eye, whichever the pass matches better) is projected at
  p - v T/2 and p + v T/2 (T = shutter / fps seconds) with the camera (as
  bpy_extras.object_utils.world_to_camera_view does; checked against it); the
  tile's predicted blur vector is the mean of its visible vertices' pixel
  segments. Tiles with fewer than --min-vertices visible vertices, whose
  vertices' segments differ (RMS deviation from the mean above max(1 px, 30%)),
  under 25% liquid, or with too little texture along the flow in the sharp
  render (--min-texture) are left out: these criteria use the sharp render and
  the prediction only, never the blurred render.
- measured blur: the sharp render is convolved with a 1-D box kernel of length
  L along a direction (bilinear samples every max(0.25, Lmax / 128) px,
  trapezoid rule), for L from 0 to Lmax = max(2 x predicted, 4) px in steps of
  two samples (refined by a parabola through the three best) and for 12
  directions (the flow's and every 15 degrees from it); the kernel whose result
  is nearest to the blurred render over the tile (least squares, RGB) gives the
  measured blur. measured_px is the best length along the predicted direction;
  best_angle_to_flow_deg the best direction's angle to it (0-90).
- Cycles' own Vector pass (written with the sharp render: motion to the previous
  and next frame in pixels, from the same velocity attribute) is compared with
  the projected motion per frame, a check of the units (m/s, per frame = / fps).
Summary: correlation of measured and predicted lengths over the measured tiles,
slope (through the origin, and with an intercept), median measured / predicted
on the moving tiles (predicted >= 4 px), the best direction's angle to the flow,
and how much better the kernel along the flow fits than the best one across it.

Writes OUT/sharp.exr, OUT/blurred.exr (multilayer, linear), OUT/sharp.png,
OUT/blurred.png, OUT/side_by_side.png (sharp | blurred | blurred with the
predicted blur per tile in green and the measured one in magenta),
OUT/motion_blur.json (settings, camera, per tile: predicted and measured blur;
summary) and OUT/summary.txt. Needs numpy and OpenImageIO's Python module
(Debian: python3-numpy, python3-openimageio; Blender 3.4 of Debian uses the
system Python). Exit codes: 0 done, 2 bad input.
"""

import argparse
import json
import math
import os
import sys
import time

import bpy
import numpy as np
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # no __pycache__ in the source tree
PROG = "motion_blur_check"
FAST = 0.3  # --camera auto frames the vertices at least this fraction of the top speed


class BadInput(Exception):
    pass


def script_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog=f"blender -b --factory-startup -P tools/blender/{PROG}.py --")
    p.add_argument("--bake", required=True, help="bake folder or NAME.bake.json")
    p.add_argument("--frame", type=int, required=True, help="the baked frame to render")
    p.add_argument("--out", required=True, help="folder for the renders, motion_blur.json and summary.txt")
    p.add_argument("--shutter", type=float, default=0.5, help="shutter in frames (default 0.5)")
    p.add_argument("--samples", type=int, default=64, help="Cycles samples per pixel (default 64)")
    p.add_argument("--resolution", default="640x360", help="WxH (default 640x360)")
    p.add_argument("--tile", type=int, default=32, help="tile size in pixels (default 32)")
    p.add_argument("--camera", default="auto", help="camera position x,y,z or auto")
    p.add_argument("--target", default="", help="point the camera looks at, x,y,z (default: the fast region's centre)")
    p.add_argument("--min-vertices", type=int, default=4, help="visible vertices a tile needs (default 4)")
    p.add_argument("--min-texture", type=float, default=0.02,
                   help="mean |derivative along the flow| of the sharp render a tile needs, relative to the "
                        "image's mean liquid radiance (default 0.02)")
    a = p.parse_args(argv)
    try:
        a.size = tuple(int(v) for v in a.resolution.lower().split("x"))
        assert len(a.size) == 2 and min(a.size) > 0
    except (ValueError, AssertionError):
        raise BadInput(f"--resolution {a.resolution!r}: expected WxH")
    if a.shutter <= 0:
        raise BadInput("--shutter must be > 0")
    return a


def parse_vec(text, what):
    try:
        v = [float(x) for x in text.split(",")]
        assert len(v) == 3
    except (ValueError, AssertionError):
        raise BadInput(f"{what} {text!r}: expected x,y,z")
    return Vector(v)


# ---------------------------------------------------------------------------
# Scene

def emission_material(obj):
    """The add-on's material, its surface replaced by Emission(colour atlas)."""
    mat = obj.data.materials[0]
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    color = nodes["lapflow color"]
    out = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    for n in [n for n in nodes if n.type == "BSDF_PRINCIPLED"]:
        nodes.remove(n)
    em = nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    links.new(color.outputs["Color"], em.inputs["Color"])
    links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def mesh_arrays(obj):
    """World-space points and velocities (m/s) of the object's mesh."""
    me = obj.data
    n = len(me.vertices)
    co = np.zeros(3 * n, np.float32)
    me.vertices.foreach_get("co", co)
    attr = me.attributes.get("velocity")
    if attr is None:
        raise BadInput(f"{obj.name}: the mesh has no 'velocity' attribute (a bake without USD layers?)")
    vel = np.zeros(3 * n, np.float32)
    attr.data.foreach_get("vector", vel)
    m = np.array(obj.matrix_world, dtype=np.float64)
    p = co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    v = vel.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T
    return p, v


def add_camera(scene, args, p, v):
    """A fixed camera on the fast part of the liquid."""
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 50
    cam_data.sensor_fit = "AUTO"
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    s = np.linalg.norm(v, axis=1)
    fast = s >= FAST * s.max()
    lo, hi = p[fast].min(0), p[fast].max(0)
    target = parse_vec(args.target, "--target") if args.target else Vector((lo + hi) / 2)
    info = {"fast_threshold_m_s": float(FAST * s.max()), "fast_vertices": int(fast.sum()),
            "fast_box": [lo.tolist(), hi.tolist()]}
    if args.camera == "auto":
        # Look across the main horizontal flow: the horizontal direction of
        # least (speed-weighted) velocity variance is the viewing direction.
        vh = v[fast][:, :2]
        w = s[fast]
        cov = (vh * w[:, None]).T @ vh / max(w.sum(), 1e-12)
        evals, evecs = np.linalg.eigh(cov)
        d = evecs[:, 0]
        if d[1] < 0 or (abs(d[1]) < 1e-9 and d[0] < 0):
            d = -d                               # a camera on the -y side when it is a toss-up
        view = Vector((d[0], d[1], 0.0)).normalized()
        elev = math.radians(20.0)
        direction = -(view * math.cos(elev)) + Vector((0, 0, math.sin(elev)))  # target -> camera
        direction.normalize()
        right = (-direction).cross(Vector((0, 0, 1))).normalized()
        up = right.cross(-direction)
        w_px, h_px = args.size
        tan_wide = 0.5 * cam_data.sensor_width / cam_data.lens
        tan_x, tan_y = (tan_wide, tan_wide * h_px / w_px) if w_px >= h_px else (tan_wide * w_px / h_px, tan_wide)
        # The nearest camera on this line of sight that sees every fast vertex
        # within the middle 90% of the frame.
        c = p[fast] - np.array(target)
        cr, cu, cd = c @ np.array(right), c @ np.array(up), c @ np.array(direction)

        def fits(dist):
            zc = dist - cd
            return bool((zc > 0).all() and (np.abs(cr / zc) <= 0.9 * tan_x).all()
                        and (np.abs(cu / zc) <= 0.9 * tan_y).all())

        near, far = 0.0, 1.0
        while not fits(far):
            near, far = far, 2 * far
        for _ in range(40):
            mid = 0.5 * (near + far)
            near, far = (near, mid) if fits(mid) else (mid, far)
        position = target + direction * far
        info["flow_axis_horizontal"] = [float(evecs[0, 1]), float(evecs[1, 1])]
        info["flow_variance_horizontal"] = [float(evals[1]), float(evals[0])]
    else:
        position = parse_vec(args.camera, "--camera")
    cam.location = position
    cam.rotation_euler = (target - position).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_start = 0.01
    cam_data.clip_end = 100.0
    info.update({"position": list(position), "target": list(target), "lens_mm": cam_data.lens})
    return cam, info


def setup_render(scene, args):
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = args.samples
    c.use_adaptive_sampling = False       # the same samples in every pixel of both renders
    c.use_denoising = False               # Debian's Blender has no OpenImageDenoise
    c.seed = 0
    c.max_bounces = 0                      # emission seen directly: no light paths needed
    c.motion_blur_position = "CENTER"
    c.rolling_shutter_type = "NONE"
    scene.render.resolution_x, scene.render.resolution_y = args.size
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True   # alpha = liquid coverage; RGB over black
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    s = scene.render.image_settings
    s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "32"
    s.exr_codec = "ZIP"
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world


def render(scene, path, blur, shutter):
    vl = scene.view_layers[0]
    vl.use_pass_z = True
    vl.use_pass_vector = not blur          # Cycles writes the Vector pass only without motion blur
    scene.render.use_motion_blur = blur
    scene.render.motion_blur_shutter = shutter
    scene.render.filepath = path
    t = time.time()
    bpy.ops.render.render(write_still=True)
    return time.time() - t


# ---------------------------------------------------------------------------
# Images

def read_exr(path):
    """channel name -> (H, W) float32 array, row 0 at the top."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise RuntimeError(f"{path}: {oiio.geterror()}")
    spec = inp.spec()
    data = inp.read_image(0, spec.nchannels, "float")
    inp.close()
    data = np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)
    return {name: data[:, :, i] for i, name in enumerate(spec.channelnames)}


def channel(chans, pass_name, comp):
    for name, arr in chans.items():
        parts = name.split(".")
        if len(parts) >= 2 and parts[-2] == pass_name and parts[-1] == comp:
            return arr
    raise KeyError(f"{pass_name}.{comp} not in {sorted(chans)}")


def to_srgb8(rgb):
    x = np.clip(rgb, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (x * 255 + 0.5).astype(np.uint8)


def write_png(path, rgb8):
    import OpenImageIO as oiio
    h, w, c = rgb8.shape
    out = oiio.ImageOutput.create(path)
    out.open(path, oiio.ImageSpec(w, h, c, "uint8"))
    out.write_image(np.ascontiguousarray(rgb8))
    out.close()


def bilinear(img, x, y):
    """img (H, W, C) sampled at continuous pixel-index coordinates (x, y),
    edges clamped."""
    h, w = img.shape[:2]
    x = np.clip(x, 0, w - 1.000001)
    y = np.clip(y, 0, h - 1.000001)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    a = img[y0, x0]
    b = img[y0, x0 + 1]
    c = img[y0 + 1, x0]
    d = img[y0 + 1, x0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def draw_segment(img, x0, y0, x1, y1, color, width=1):
    n = int(max(abs(x1 - x0), abs(y1 - y0)) * 2) + 2
    t = np.linspace(0, 1, n)
    xs = np.round(x0 + (x1 - x0) * t).astype(int)
    ys = np.round(y0 + (y1 - y0) * t).astype(int)
    h, w = img.shape[:2]
    for dx in range(-(width // 2), width // 2 + 1):
        for dy in range(-(width // 2), width // 2 + 1):
            xx, yy = xs + dx, ys + dy
            ok = (xx >= 0) & (xx < w) & (yy >= 0) & (yy < h)
            img[yy[ok], xx[ok]] = color


# ---------------------------------------------------------------------------
# Projection

def project(scene, cam, pts):
    """world_to_camera_view for many points: (x, y) in pixels (x right, y
    down, pixel i covers [i, i+1)) and the depth along the view axis."""
    w, h = scene.render.resolution_x, scene.render.resolution_y
    mi = np.array(cam.matrix_world.normalized().inverted(), dtype=np.float64)
    co = pts @ mi[:3, :3].T + mi[:3, 3]
    frame = [v for v in cam.data.view_frame(scene=scene)]
    if cam.data.type != "ORTHO":
        frame = [-(v / v.z) for v in frame]
    min_x, max_x = frame[2].x, frame[1].x
    min_y, max_y = frame[1].y, frame[0].y
    z = -co[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = (co[:, 0] / z - min_x) / (max_x - min_x)
        yn = (co[:, 1] / z - min_y) / (max_y - min_y)
    return xn * w, (1.0 - yn) * h, z, xn, yn


# ---------------------------------------------------------------------------
# Measurement

DIRECTIONS = np.radians(np.arange(0, 180, 15))  # offsets from the flow direction
STEP = 0.25                                      # px between samples along the kernel (at least)
MAX_HALF_SAMPLES = 64                            # samples on each side of the kernel's centre (at most)


def fit_tile(sharp, blurred, x0, y0, t, angle, l_max):
    """Best box length for each tested direction: returns (lengths (D,),
    errors (D,), error at L=0, error curve along the flow, L grid)."""
    ys, xs = np.mgrid[y0:y0 + t, x0:x0 + t].astype(np.float64)
    target = blurred[y0:y0 + t, x0:x0 + t]
    step = max(STEP, l_max / (2 * MAX_HALF_SAMPLES))
    jmax = max(1, int(math.ceil(l_max / (2 * step))))
    ks = np.arange(-jmax, jmax + 1)
    lengths = 2 * step * np.arange(jmax + 1)            # L_j = 2 j step
    best_l, best_e, curve0 = [], [], None
    e0 = float(((target - sharp[y0:y0 + t, x0:x0 + t]) ** 2).sum())
    for off in DIRECTIONS:
        th = angle + off
        dx, dy = math.cos(th) * step, math.sin(th) * step
        shifted = np.stack([bilinear(sharp, xs + k * dx, ys + k * dy) for k in ks])  # (2J+1, t, t, C)
        c = np.cumsum(shifted, axis=0)
        # C_j = sum_{|k|<=j} S_k = c[J+j] - c[J-j-1]
        mid = jmax
        cj = np.empty((jmax + 1,) + shifted.shape[1:])
        cj[0] = shifted[mid]
        for j in range(1, jmax + 1):
            lo = c[mid - j - 1] if mid - j - 1 >= 0 else 0.0
            cj[j] = c[mid + j] - lo
        j = np.arange(1, jmax + 1)[:, None, None, None]
        box = np.empty_like(cj)
        box[0] = shifted[mid]
        box[1:] = (cj[1:] - 0.5 * (shifted[mid + j[:, 0, 0, 0]] + shifted[mid - j[:, 0, 0, 0]])) / (2 * j)
        err = ((box - target[None]) ** 2).reshape(jmax + 1, -1).sum(1)
        i = int(np.argmin(err))
        l_best = lengths[i]
        if 0 < i < jmax:  # parabola through the three nearest errors
            a, b, cc = err[i - 1], err[i], err[i + 1]
            den = a - 2 * b + cc
            if den > 0:
                l_best += 0.5 * (a - cc) / den * (2 * step)
        best_l.append(float(l_best))
        best_e.append(float(err[i]))
        if curve0 is None:
            curve0 = err
    return np.array(best_l), np.array(best_e), e0, curve0, lengths


def pearson(x, y):
    if len(x) < 3 or np.std(x) == 0 or np.std(y) == 0:
        return float("nan")
    return float(np.corrcoef(x, y)[0, 1])


def fit_line(x, y):
    if len(x) < 2:
        return float("nan"), float("nan"), float("nan")
    through0 = float((x * y).sum() / max((x * x).sum(), 1e-12))
    a = np.vstack([x, np.ones_like(x)]).T
    (slope, icpt), *_ = np.linalg.lstsq(a, y, rcond=None)
    return through0, float(slope), float(icpt)


def analyse(args, scene, cam, p, v, fps, sharp_ch, blur_ch):
    w, h = args.size
    t = args.tile
    T = args.shutter / fps
    sharp = np.dstack([channel(sharp_ch, "Combined", c) for c in "RGB"]).astype(np.float64)
    blurred = np.dstack([channel(blur_ch, "Combined", c) for c in "RGB"]).astype(np.float64)
    alpha = channel(sharp_ch, "Combined", "A")
    depth = channel(sharp_ch, "Depth", "Z")
    lum = sharp @ np.array([0.2126, 0.7152, 0.0722])
    liquid = alpha > 0.5
    mean_level = float(lum[liquid].mean()) if liquid.any() else 1.0

    # Check the vectorised projection against world_to_camera_view.
    px, py, z, xn, yn = project(scene, cam, p)
    check = np.linspace(0, len(p) - 1, min(200, len(p))).astype(int)
    ref = np.array([tuple(world_to_camera_view(scene, cam, Vector(p[i]))) for i in check])
    proj_err = float(np.abs(np.c_[xn[check], yn[check], z[check]] - ref).max())

    # Visibility: the vertex's depth matches the Depth pass at its pixel
    # (Cycles' Depth may be the distance along the view axis or to the eye:
    # take whichever fits the visible surface better).
    inside = (px >= 0) & (px < w) & (py >= 0) & (py < h) & (z > 0)
    ix = np.clip(px.astype(int), 0, w - 1)
    iy = np.clip(py.astype(int), 0, h - 1)
    zpass = depth[iy, ix]
    mi = np.array(cam.matrix_world, dtype=np.float64)
    dist = np.linalg.norm(p - mi[:3, 3], axis=1)
    rel_z = np.abs(zpass - z) / z
    rel_d = np.abs(zpass - dist) / dist
    use_dist = np.median(rel_d[inside]) < np.median(rel_z[inside])
    rel = rel_d if use_dist else rel_z
    visible = inside & (rel < 0.03) & (alpha[iy, ix] > 0.5)

    # Blur segments of the vertices over the shutter, in pixels.
    ax, ay, *_ = project(scene, cam, p - v * T / 2)
    bx, by, *_ = project(scene, cam, p + v * T / 2)
    seg = np.c_[bx - ax, by - ay]

    # Cycles' Vector pass: motion to the previous frame (X, Y) and to the next
    # (Z, W) in pixels (y up); per frame = shutter 1.
    try:
        vec = np.dstack([channel(sharp_ch, "Vector", c) for c in "XYZW"])
    except KeyError:
        vec = None

    tiles = []
    for ty in range(h // t):
        for tx in range(w // t):
            x0, y0 = tx * t, ty * t
            sel = visible & (px >= x0) & (px < x0 + t) & (py >= y0) & (py < y0 + t)
            n = int(sel.sum())
            cover = float(liquid[y0:y0 + t, x0:x0 + t].mean())
            rec = {"tile": [tx, ty], "x": x0, "y": y0, "vertices": n, "coverage": round(cover, 3)}
            if n < args.min_vertices:
                rec["skipped"] = "too few visible vertices"
                tiles.append(rec)
                continue
            b = seg[sel]
            bm = b.mean(0)
            pred = float(np.hypot(*bm))
            spread = float(np.sqrt(((b - bm) ** 2).sum(1).mean()))
            rec.update({"predicted_px": round(pred, 3), "predicted_vector_px": [round(float(x), 3) for x in bm],
                        "spread_px": round(spread, 3),
                        "speed_m_s": round(float(np.linalg.norm(v[sel], axis=1).mean()), 3)})
            if spread > max(1.0, 0.3 * pred):
                rec["skipped"] = "vertices move differently"
                tiles.append(rec)
                continue
            if cover < 0.25:
                rec["skipped"] = "too little liquid"
                tiles.append(rec)
                continue
            angle = math.atan2(bm[1], bm[0]) if pred > 1e-6 else 0.0
            e = np.array([math.cos(angle), math.sin(angle)])
            ys_, xs_ = np.mgrid[y0:y0 + t, x0:x0 + t].astype(np.float64)
            lp = bilinear(lum[..., None], xs_ + e[0], ys_ + e[1])[..., 0]
            lm = bilinear(lum[..., None], xs_ - e[0], ys_ - e[1])[..., 0]
            texture = float(np.abs(lp - lm).mean() / 2 / mean_level)
            rec["texture"] = round(texture, 4)
            if texture < args.min_texture:
                rec["skipped"] = "too little texture along the flow"
                tiles.append(rec)
                continue
            l_max = max(2.0 * pred, 4.0)
            best_l, best_e, e0, curve, lengths = fit_tile(sharp, blurred, x0, y0, t, angle, l_max)
            k = int(np.argmin(best_e))
            off = int(round(math.degrees(DIRECTIONS[k])))
            angle_to_flow = min(off, 180 - off)
            e_pred = float(np.interp(pred, lengths, curve))
            rec.update({
                "measured_px": round(float(best_l[0]), 3),           # along the predicted direction
                "at_limit": bool(best_l[0] >= lengths[-1] - 1e-9),
                "best_direction_offset_deg": off, "best_angle_to_flow_deg": angle_to_flow,
                "best_length_px": round(float(best_l[k]), 3),
                "across_length_px": round(float(best_l[len(DIRECTIONS) // 2]), 3),
                "error_none": e0, "error_flow": float(best_e[0]), "error_predicted": e_pred,
                "error_across": float(best_e[len(DIRECTIONS) // 2]), "error_best": float(best_e[k]),
            })
            if vec is not None:
                m = liquid[y0:y0 + t, x0:x0 + t]
                pv = vec[y0:y0 + t, x0:x0 + t][m]
                # Medians over the tile's liquid pixels, as stored (x right, y up).
                rec["vector_pass_xy_px"] = [round(float(x), 3) for x in np.median(pv[:, 0:2], axis=0)]
                rec["vector_pass_zw_px"] = [round(float(x), 3) for x in np.median(pv[:, 2:4], axis=0)]
            tiles.append(rec)

    used = [r for r in tiles if "measured_px" in r]
    pred = np.array([r["predicted_px"] for r in used])
    meas = np.array([r["measured_px"] for r in used])
    through0, slope, icpt = fit_line(pred, meas)
    moving = [r for r in used if r["predicted_px"] >= 4.0]
    angles = np.array([r["best_angle_to_flow_deg"] for r in moving])
    ratio = np.array([r["measured_px"] / r["predicted_px"] for r in moving])
    improve = np.array([1 - r["error_flow"] / r["error_none"] for r in moving if r["error_none"] > 0])
    across = np.array([r["error_across"] / r["error_flow"] for r in moving if r["error_flow"] > 0])
    skipped = {}
    for r in tiles:
        if "skipped" in r:
            skipped[r["skipped"]] = skipped.get(r["skipped"], 0) + 1
    summary = {
        "tiles": len(tiles), "tiles_measured": len(used), "tiles_skipped": skipped,
        "tiles_moving": len(moving), "moving_threshold_px": 4.0,
        "predicted_px_range": [float(pred.min()), float(pred.max())] if len(pred) else [],
        "correlation": pearson(pred, meas),
        "slope_through_origin": through0, "slope": slope, "intercept_px": icpt,
        "median_ratio_moving": float(np.median(ratio)) if len(ratio) else float("nan"),
        "ratio_quartiles_moving": [float(np.percentile(ratio, 25)), float(np.percentile(ratio, 75))]
        if len(ratio) else [],
        "at_limit": int(sum(r["at_limit"] for r in used)),
        "angle_to_flow_median_deg": float(np.median(angles)) if len(angles) else float("nan"),
        "angle_to_flow_within_15_deg": float((angles <= 15).mean()) if len(angles) else float("nan"),
        "angle_to_flow_counts_deg": {str(int(a)): int((angles == a).sum()) for a in np.unique(angles)},
        "error_drop_along_flow_median": float(np.median(improve)) if len(improve) else float("nan"),
        "error_across_over_along_median": float(np.median(across)) if len(across) else float("nan"),
        "projection_check_max_diff": proj_err,
        "depth_pass_is": "distance to the eye" if use_dist else "depth along the view axis",
        "visible_vertices": int(visible.sum()),
    }
    if vec is not None:
        vv = [r for r in moving if "vector_pass_xy_px" in r]
        if vv:
            # The projected motion per frame, x right, y up (the pass's axes).
            a = np.array([[r["predicted_vector_px"][0], -r["predicted_vector_px"][1]] for r in vv]).ravel()
            a /= args.shutter
            out = {"tiles": len(vv)}
            for key in ("xy", "zw"):
                b = np.array([r[f"vector_pass_{key}_px"] for r in vv]).ravel()
                out[key] = {"correlation": pearson(a, b), "slope_through_origin": fit_line(a, b)[0]}
            summary["vector_pass_vs_projection_per_frame"] = out
    return tiles, summary, sharp, blurred, alpha


# ---------------------------------------------------------------------------

def main():
    t_start = time.time()
    args = script_args()
    os.makedirs(args.out, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sys.path.insert(0, HERE)
    import lapflow_import
    lapflow_import.register()
    scene = bpy.context.scene
    try:
        manifest = lapflow_import.find_manifest(args.bake)
        bake = lapflow_import.get_bake(manifest)
    except lapflow_import.BakeError as e:
        raise BadInput(str(e))
    if args.frame not in bake.frames:
        raise BadInput(f"{manifest}: frame {args.frame} was not baked ({bake.frames[0]}-{bake.frames[-1]})")
    if not os.path.isfile(bake.path("usd", args.frame)):
        raise BadInput(f"{bake.path('usd', args.frame)}: no USD layer for frame {args.frame}: no velocity to blur with")
    scene.frame_set(args.frame)
    try:
        obj = lapflow_import.import_bake(manifest, material="matte", displacement="none")
    except lapflow_import.BakeError as e:
        raise BadInput(str(e))
    scene.frame_set(args.frame)
    emission_material(obj)
    fps = scene.render.fps / scene.render.fps_base
    p, v = mesh_arrays(obj)
    setup_render(scene, args)
    cam, cam_info = add_camera(scene, args, p, v)
    t_setup = time.time() - t_start

    sharp_path = os.path.join(args.out, "sharp.exr")
    blur_path = os.path.join(args.out, "blurred.exr")
    loads0 = lapflow_import.load_count
    t_sharp = render(scene, sharp_path, False, args.shutter)
    loads1 = lapflow_import.load_count
    t_blur = render(scene, blur_path, True, args.shutter)
    loads2 = lapflow_import.load_count
    scene.frame_set(args.frame)
    p2, v2 = mesh_arrays(obj)
    same_mesh = p2.shape == p.shape and bool(np.allclose(p2, p)) and bool(np.allclose(v2, v))

    t0 = time.time()
    sharp_ch, blur_ch = read_exr(sharp_path), read_exr(blur_path)
    tiles, summary, sharp, blurred, alpha = analyse(args, scene, cam, p, v, fps, sharp_ch, blur_ch)
    t_analyse = time.time() - t0

    # Pictures.
    s8, b8 = to_srgb8(sharp), to_srgb8(blurred)
    write_png(os.path.join(args.out, "sharp.png"), s8)
    write_png(os.path.join(args.out, "blurred.png"), b8)
    over = (b8.astype(np.float64) * 0.55).astype(np.uint8)
    t = args.tile
    for r in tiles:
        x0, y0 = r["x"], r["y"]
        over[y0, x0:x0 + t] = np.maximum(over[y0, x0:x0 + t], 40)
        over[y0:y0 + t, x0] = np.maximum(over[y0:y0 + t, x0], 40)
    for r in tiles:
        if "measured_px" not in r:
            continue
        cx, cy = r["x"] + t / 2, r["y"] + t / 2
        bx, by = r["predicted_vector_px"]
        draw_segment(over, cx - bx / 2, cy - by / 2, cx + bx / 2, cy + by / 2, (60, 255, 60), 3)
        ang = math.atan2(by, bx) + math.radians(r["best_direction_offset_deg"])
        L = r["best_length_px"]
        draw_segment(over, cx - L / 2 * math.cos(ang), cy - L / 2 * math.sin(ang),
                     cx + L / 2 * math.cos(ang), cy + L / 2 * math.sin(ang), (255, 0, 255), 1)
    gap = np.full((s8.shape[0], 6, 3), 255, np.uint8)
    write_png(os.path.join(args.out, "side_by_side.png"), np.hstack([s8, gap, b8, gap, over]))

    speeds = np.linalg.norm(v, axis=1)
    facts = {
        "bake": manifest, "frame": args.frame, "fps": fps, "shutter_frames": args.shutter,
        "shutter_s": args.shutter / fps, "samples": args.samples, "resolution": list(args.size),
        "tile_px": args.tile, "vertices": len(p), "max_speed_m_s": float(speeds.max()),
        "mean_speed_m_s": float(speeds.mean()), "camera": cam_info,
        "mesh_reads_during_renders": [loads1 - loads0, loads2 - loads1],
        "mesh_after_renders_is_the_frames": same_mesh,
        "seconds": {"setup": round(t_setup, 1), "render_sharp": round(t_sharp, 1),
                    "render_blurred": round(t_blur, 1), "analysis": round(t_analyse, 1),
                    "total": round(time.time() - t_start, 1)},
        "summary": summary, "tiles": tiles,
        "files": {k: os.path.join(args.out, f) for k, f in
                  (("sharp", "sharp.exr"), ("blurred", "blurred.exr"), ("side_by_side", "side_by_side.png"))},
    }
    with open(os.path.join(args.out, "motion_blur.json"), "w") as f:
        json.dump(facts, f, indent=1)
    s = summary
    lines = [
        f"{PROG}: {os.path.basename(manifest)} frame {args.frame}, shutter {args.shutter} frames "
        f"({1000 * args.shutter / fps:.1f} ms at {fps:g} fps), {args.size[0]}x{args.size[1]}, {args.samples} samples",
        f"max speed {speeds.max():.2f} m/s; tiles {s['tiles']} of {args.tile} px, measured {s['tiles_measured']} "
        f"(skipped: {s['tiles_skipped']}), moving (predicted >= 4 px) {s['tiles_moving']}",
        f"predicted blur {s['predicted_px_range'][0]:.1f}-{s['predicted_px_range'][1]:.1f} px" if s["predicted_px_range"] else "no tiles",
        f"measured vs predicted length: correlation {s['correlation']:.3f}, slope {s['slope_through_origin']:.3f} "
        f"(through 0; with intercept {s['slope']:.3f}, {s['intercept_px']:+.2f} px), "
        f"median ratio (moving) {s['median_ratio_moving']:.3f}, at the search limit {s['at_limit']}",
        f"best direction vs flow (moving): median {s['angle_to_flow_median_deg']:.0f} deg, "
        f"{100 * s['angle_to_flow_within_15_deg']:.0f}% within 15 deg; counts {s['angle_to_flow_counts_deg']}",
        f"error along the flow / no blur: median drop {100 * s['error_drop_along_flow_median']:.0f}%; "
        f"best across / best along: {s['error_across_over_along_median']:.2f}",
    ]
    if "vector_pass_vs_projection_per_frame" in s:
        vp = s["vector_pass_vs_projection_per_frame"]
        lines.append(f"Cycles Vector pass vs projected motion per frame ({vp['tiles']} moving tiles): "
                     f"X,Y slope {vp['xy']['slope_through_origin']:.3f} (r {vp['xy']['correlation']:.3f}), "
                     f"Z,W slope {vp['zw']['slope_through_origin']:.3f} (r {vp['zw']['correlation']:.3f})")
    lines.append(f"time: setup {t_setup:.0f} s, renders {t_sharp:.0f} + {t_blur:.0f} s, analysis {t_analyse:.0f} s, "
                 f"total {time.time() - t_start:.0f} s")
    text = "\n".join(lines)
    with open(os.path.join(args.out, "summary.txt"), "w") as f:
        f.write(text + "\n")
    print(text, flush=True)


if __name__ == "__main__":
    try:
        main()
    except BadInput as e:
        print(f"{PROG}: error: {e}", file=sys.stderr, flush=True)
        sys.exit(2)
    except SystemExit:
        raise
    except BaseException:
        import traceback
        traceback.print_exc()
        sys.exit(1)
