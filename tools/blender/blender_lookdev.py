"""Render a lapflow bake in Blender (Cycles, headless).

    blender -b -P tools/blender/blender_lookdev.py -- --bake DIR [--frames 1,10,20 | A-B]
        [--out DIR] [--samples N] [--resolution WxH] [--displacement-scale S]
        [--displacement bump|true|none] [--camera auto|x,y,z] [--target x,y,z]

It imports the bake with the lapflow_import add-on (tools/blender/lapflow_import:
one object whose mesh is frame N's, from DIR/NAME.usd.NNNN.usda or
DIR/NAME.NNNN.obj, with DIR/NAME.color.NNNN.exr as base colour and
DIR/NAME.disp.NNNN.exr as bump, or true displacement, read as image
sequences), lights it with a sun and a sky, frames a camera on the bounding
box of all chosen frames (the same camera for every frame) and, for every
chosen frame N, renders OUT/NAME.NNNN.png with Cycles.
NAME, the frame list and the patch radius come from DIR/NAME.bake.json, which
every `lapflow bake` writes.

Exit codes: 0 ok, 2 bad input (missing bake, missing frame files, bad option).
Works with Debian's Blender 3.4 (no OpenImageDenoise: denoising is off; use
more samples for a cleaner picture).
"""

import argparse
import glob
import json
import math
import os
import sys

import bpy
from mathutils import Vector

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import lapflow_import  # noqa: E402  (the add-on next to this script)


class BadInput(Exception):
    pass


def script_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender -b -P tools/blender/blender_lookdev.py --",
                                description="Render frames of a lapflow bake with Cycles.")
    p.add_argument("--bake", required=True, help="bake output folder (holds NAME.bake.json)")
    p.add_argument("--name", default="", help="which bake when the folder holds several")
    p.add_argument("--frames", default="", help="frames: 1,10,20 or A-B or a mix (default: the first baked frame)")
    p.add_argument("--out", default="", help="output folder for the PNGs (default: BAKE/lookdev)")
    p.add_argument("--samples", type=int, default=64, help="Cycles samples per pixel (no denoiser here)")
    p.add_argument("--resolution", default="1280x720", help="WxH in pixels")
    p.add_argument("--displacement", choices=["bump", "true", "none"], default="bump",
                   help="how the displacement atlas is used (true = subdivided real displacement, slower)")
    p.add_argument("--displacement-scale", type=float, default=-1.0,
                   help="height of displacement value 1, in scene units (default: 0.1 x the patch radius)")
    p.add_argument("--camera", default="auto", help="camera position x,y,z or auto (framed from the bounding box)")
    p.add_argument("--target", default="", help="point the camera looks at, x,y,z (default: bounding box centre)")
    p.add_argument("--material", choices=["liquid", "matte", "grey"], default="liquid",
                   help="liquid: glossy wet look; matte: rough; grey: flat grey, no texture (a reference)")
    p.add_argument("--no-ground", action="store_true", help="no ground plane under the liquid")
    p.add_argument("--transparent", action="store_true", help="transparent background (alpha in the PNG)")
    p.add_argument("--view-transform", default="Filmic", choices=["Filmic", "Standard"],
                   help="colour management view (Standard keeps the atlas colours as they are)")
    p.add_argument("--exposure", type=float, default=0.0, help="exposure in stops")
    p.add_argument("--up", choices=["z", "y"], default="z", help="up axis of the bake's meshes")
    a = p.parse_args(argv)
    try:
        w, h = (int(v) for v in a.resolution.lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
    except ValueError:
        raise BadInput(f"--resolution {a.resolution}: expected WxH, e.g. 1280x720")
    a.size = (w, h)
    if a.samples < 1:
        raise BadInput("--samples must be at least 1")
    return a


def parse_vec(text, what):
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3:
        raise BadInput(f"{what} {text}: expected x,y,z")
    return Vector(v)


def parse_frames(text, available):
    if not text:
        return [available[0]]
    frames = []
    for part in text.split(","):
        try:
            if "-" in part:
                a, b = (int(x) for x in part.split("-", 1))
                if a > b:
                    raise ValueError
                frames += list(range(a, b + 1))
            else:
                frames.append(int(part))
        except ValueError:
            raise BadInput(f"--frames {text}: expected 1,10,20 or A-B with A <= B")
    missing = [f for f in frames if f not in available]
    if missing:
        raise BadInput(f"--frames: frame(s) {missing} were not baked (the bake has {available[0]}-{available[-1]})")
    return frames


def read_manifest(folder, name):
    if not os.path.isdir(folder):
        raise BadInput(f"{folder}: no such bake folder")
    if name:
        path = os.path.join(folder, name + ".bake.json")
        if not os.path.isfile(path):
            raise BadInput(f"{path}: no such bake manifest")
    else:
        found = sorted(glob.glob(os.path.join(folder, "*.bake.json")))
        if not found:
            raise BadInput(f"{folder}: no *.bake.json in this folder: is it a lapflow bake output?")
        if len(found) > 1:
            raise BadInput(f"{folder}: several bakes ({', '.join(os.path.basename(f) for f in found)}): pick one with --name")
        path = found[0]
    try:
        with open(path) as f:
            m = json.load(f)
        return m["name"], [int(x) for x in m["frames"]], float(m.get("radius", 0.0)), path
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise BadInput(f"{path}: not a readable lapflow bake manifest ({e})")


def check_frame_files(folder, name, frame):
    """The frame's mesh (its USD layer, or else its OBJ) and both atlases are there."""
    files = {"obj": f"{name}.{frame:04d}.obj", "color": f"{name}.color.{frame:04d}.exr",
             "disp": f"{name}.disp.{frame:04d}.exr"}
    files = {k: os.path.join(folder, v) for k, v in files.items()}
    if os.path.isfile(os.path.join(folder, f"{name}.usd.{frame:04d}.usda")):
        del files["obj"]
    for kind, path in files.items():
        if not os.path.isfile(path):
            raise BadInput(f"{path} (frame {frame}): missing {kind} file of the bake")


def world_bbox(objects):
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    for obj in objects:
        for corner in obj.bound_box:
            p = obj.matrix_world @ Vector(corner)
            lo = Vector(map(min, lo, p))
            hi = Vector(map(max, hi, p))
    return lo, hi


def setup_scene(args):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = args.samples
    scene.cycles.use_denoising = False  # Debian's Blender has no OpenImageDenoise
    scene.cycles.max_bounces = 4
    scene.render.resolution_x, scene.render.resolution_y = args.size
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = args.transparent
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA" if args.transparent else "RGB"
    scene.view_settings.view_transform = args.view_transform
    scene.view_settings.look = "None"
    scene.view_settings.exposure = args.exposure

    world = bpy.data.worlds.new("lookdev_sky")
    scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    nodes.clear()
    sky = nodes.new("ShaderNodeTexSky")
    sky.sky_type = "HOSEK_WILKIE"
    sky.sun_direction = Vector((0.4, -0.5, 0.75)).normalized()
    sky.turbidity = 2.5
    bg = nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 0.35
    links.new(sky.outputs["Color"], bg.inputs["Color"])
    links.new(bg.outputs["Background"], nodes.new("ShaderNodeOutputWorld").inputs["Surface"])

    sun_data = bpy.data.lights.new("sun", "SUN")
    sun_data.energy = 3.5
    sun_data.angle = math.radians(3)
    sun = bpy.data.objects.new("sun", sun_data)
    sun.rotation_euler = Vector((0.4, -0.5, 0.75)).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(sun)
    return scene


def add_ground(scene, lo, hi):
    size = 4 * max((hi - lo).length, 1e-3)
    bpy.ops.mesh.primitive_plane_add(size=size, location=((lo.x + hi.x) / 2, (lo.y + hi.y) / 2,
                                                          lo.z - 1e-3 * size))
    ground = bpy.context.active_object
    mat = bpy.data.materials.new("ground")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.12, 0.12, 0.115, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.9
    ground.data.materials.append(mat)


def add_camera(scene, args, lo, hi):
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 40
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    centre = (lo + hi) / 2
    target = parse_vec(args.target, "--target") if args.target else centre
    radius = max((hi - lo).length / 2, 1e-6)
    if args.camera == "auto":
        # From the front-right, above: the classic three-quarter lookdev view,
        # as close as the eight corners of the box allow.
        direction = Vector((0.55, -1.0, 0.65)).normalized()
        right = direction.cross(Vector((0, 0, 1))).normalized() * -1
        up = right.cross(direction) * -1
        w, h = args.size
        tan_wide = 0.5 * cam_data.sensor_width / cam_data.lens  # the sensor fits the wider side
        tan_x, tan_y = (tan_wide, tan_wide * h / w) if w >= h else (tan_wide * w / h, tan_wide)
        distance = 0.0
        for cx in (lo.x, hi.x):
            for cy in (lo.y, hi.y):
                for cz in (lo.z, hi.z):
                    c = Vector((cx, cy, cz)) - target
                    depth = c.dot(direction)
                    distance = max(distance, depth + abs(c.dot(right)) / tan_x, depth + abs(c.dot(up)) / tan_y)
        position = target + direction * (1.08 * distance)
    else:
        position = parse_vec(args.camera, "--camera")
    cam.location = position
    cam.rotation_euler = (target - position).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_start = max(1e-4, 0.01 * radius)
    cam_data.clip_end = 100 * (radius + (position - target).length)


def main():
    args = script_args()
    name, available, radius, manifest = read_manifest(os.path.abspath(args.bake), args.name)
    if not available:
        raise BadInput(f"{manifest}: the bake lists no frames")
    folder = os.path.dirname(manifest)
    frames = parse_frames(args.frames, available)
    for f in frames:  # every file checked before any work
        check_frame_files(folder, name, f)
    out_dir = os.path.abspath(args.out or os.path.join(folder, "lookdev"))
    os.makedirs(out_dir, exist_ok=True)
    disp_scale = args.displacement_scale if args.displacement_scale >= 0 else 0.1 * radius

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = setup_scene(args)
    scene.frame_set(frames[0])
    try:
        # One object; the add-on's frame handler gives it frame f's mesh and
        # textures at scene frame f. A Y-up bake is turned by the object's rotation.
        obj = lapflow_import.import_bake(manifest, material=args.material, displacement=args.displacement,
                                         displacement_scale=disp_scale, up=args.up, set_scene=False)
        lo = Vector((math.inf,) * 3)
        hi = Vector((-math.inf,) * 3)
        for f in frames:
            scene.frame_set(f)
            a, b = world_bbox([obj])
            lo, hi = Vector(map(min, lo, a)), Vector(map(max, hi, b))
    except lapflow_import.BakeError as e:
        raise BadInput(str(e))
    if not args.no_ground:
        add_ground(scene, lo, hi)
    add_camera(scene, args, lo, hi)

    for f in frames:
        scene.frame_set(f)
        path = os.path.join(out_dir, f"{name}.{f:04d}.png")
        scene.render.filepath = path
        bpy.ops.render.render(write_still=True)
        print(f"blender_lookdev: frame {f} -> {path}", flush=True)


if __name__ == "__main__":
    try:
        main()
    except BadInput as e:
        print(f"blender_lookdev: error: {e}", file=sys.stderr, flush=True)
        sys.exit(2)
    except SystemExit:
        raise
    except Exception as e:  # anything else is a bug or a Blender failure
        import traceback
        traceback.print_exc()
        print(f"blender_lookdev: error: {e}", file=sys.stderr, flush=True)
        sys.exit(1)
