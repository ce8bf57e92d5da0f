"""Look at lapflow's patches in Blender: does each patch ride the flow?

    blender -b -P tools/blender/blender_patches.py -- --patches 'DIR/NAME.patches.%04d.ply'
        --frames 1,11,21,31 [--fluid 'DATA/NAME.%04d.ply'] [--core 0.2]
        [--out DIR] [--samples N] [--resolution WxH] [--camera auto|x,y,z]

Reads each frame's patch dump (written by `lapflow patches` or
`lapflow bake --dump-patches`: per-vertex x y z patch_id u v w, per-face
patch_id), keeps each patch's core, the faces whose rest uv lies within
--core of the patch centre (whole patches overlap, and coplanar overlapping
patches would z-fight; the cores are material discs that should deform with
the flow), colours every face by a hash of its patch_id (the same patch
has the same colour in every frame), optionally shows the fluid surface in
grey underneath, and renders every frame from one camera framed on all of
them to OUT/NAME.patches.NNNN.png.

Exit codes: 0 ok, 2 bad input.
"""

import argparse
import colorsys
import os
import struct
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blender_lookdev as lookdev  # noqa: E402  (scene, camera, ground, bbox helpers)

BadInput = lookdev.BadInput

PLY_TYPES = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h",
             "ushort": "H", "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I",
             "float": "f", "float32": "f", "double": "d", "float64": "d"}


def script_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender -b -P tools/blender/blender_patches.py --",
                                description="Render lapflow patch dumps coloured by patch id.")
    p.add_argument("--patches", required=True, help="patch dump pattern with %%04d, e.g. out/dam_break.patches.%%04d.ply")
    p.add_argument("--frames", required=True, help="frames: 1,11,21 or A-B")
    p.add_argument("--fluid", default="", help="fluid mesh pattern (PLY/OBJ) shown in grey under the patches")
    p.add_argument("--core", type=float, default=0.2,
                   help="draw only each patch's core: faces whose rest uv lies within this distance of the centre "
                        "(0.5, 0.5); the patch spans 1, so 0.2 is a disc of 0.4 r. 0 = whole patches (they overlap)")
    p.add_argument("--out", default="", help="output folder (default: the dump's folder)")
    p.add_argument("--samples", type=int, default=32)
    p.add_argument("--resolution", default="960x540")
    p.add_argument("--camera", default="auto", help="camera position x,y,z or auto")
    p.add_argument("--target", default="", help="point the camera looks at, x,y,z (default: bounding box centre)")
    p.add_argument("--no-ground", action="store_true")
    a = p.parse_args(argv)
    try:
        w, h = (int(v) for v in a.resolution.lower().split("x"))
    except ValueError:
        raise BadInput(f"--resolution {a.resolution}: expected WxH")
    a.size = (w, h)
    a.transparent, a.view_transform, a.exposure = False, "Standard", 0.0
    frames = []
    for part in a.frames.split(","):
        try:
            if "-" in part:
                lo, hi = (int(x) for x in part.split("-", 1))
                frames += list(range(lo, hi + 1))
            else:
                frames.append(int(part))
        except ValueError:
            raise BadInput(f"--frames {a.frames}: expected 1,11,21 or A-B")
    a.frame_list = frames
    return a


def read_patch_ply(path):
    """Positions, per-vertex rest-uv distance from the centre, triangles and per-face patch_id of a patch dump."""
    if not os.path.isfile(path):
        raise BadInput(f"{path}: no such patch dump")
    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply") or end < 0:
        raise BadInput(f"{path}: not a PLY file")
    header = data[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise BadInput(f"{path}: only binary little-endian PLY is read (lapflow writes it)")
    elements, current = [], None
    for line in header:
        words = line.split()
        if words[:1] == ["element"]:
            current = {"name": words[1], "count": int(words[2]), "props": []}
            elements.append(current)
        elif words[:1] == ["property"] and current is not None:
            if words[1] == "list":
                current["props"].append((words[4], "list", PLY_TYPES[words[2]], PLY_TYPES[words[3]]))
            else:
                current["props"].append((words[2], PLY_TYPES[words[1]]))
    pos = end + len(b"end_header\n")
    verts, weights, tris, face_ids = [], [], [], []
    for el in elements:
        props = el["props"]
        if all(len(p) == 2 for p in props):  # fixed-size records: unpack all at once
            fmt = "<" + "".join(p[1] for p in props)
            size = struct.calcsize(fmt)
            records = list(struct.iter_unpack(fmt, data[pos:pos + size * el["count"]]))
            pos += size * el["count"]
            names = [p[0] for p in props]
            if el["name"] == "vertex":
                ix, iy, iz, iu, iv = (names.index(n) for n in ("x", "y", "z", "u", "v"))
                verts = [(r[ix], r[iy], r[iz]) for r in records]
                # Distance of the rest uv from the patch centre: where the vertex sits in the exemplar.
                weights = [((r[iu] - 0.5) ** 2 + (r[iv] - 0.5) ** 2) ** 0.5 for r in records]
            continue
        if el["name"] != "face":
            raise BadInput(f"{path}: unexpected list property in element {el['name']}")
        for _ in range(el["count"]):
            face, pid = None, 0
            for p in props:
                if len(p) == 4:
                    (n,) = struct.unpack_from("<" + p[2], data, pos)
                    pos += struct.calcsize(p[2])
                    face = struct.unpack_from(f"<{n}{p[3]}", data, pos)
                    pos += n * struct.calcsize(p[3])
                else:
                    (value,) = struct.unpack_from("<" + p[1], data, pos)
                    pos += struct.calcsize(p[1])
                    if p[0] == "patch_id":
                        pid = value
            if len(face) == 3:
                tris.append(face)
                face_ids.append(pid)
    return verts, weights, tris, face_ids


def patch_colour(pid):
    # splitmix-style integer hash -> a saturated hue, varied value.
    h = (pid * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & 0xFFFFFFFFFFFFFFFF
    h ^= h >> 31
    h = (h * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    h ^= h >> 29
    hue = (h & 0xFFFF) / 65536.0
    val = 0.55 + 0.45 * ((h >> 16) & 0xFF) / 255.0
    sat = 0.65 + 0.35 * ((h >> 24) & 0xFF) / 255.0
    return colorsys.hsv_to_rgb(hue, sat, val)


def build_patch_object(name, verts, rest_radius, tris, face_ids, core, offset):
    keep = [i for i, t in enumerate(tris) if core <= 0 or max(rest_radius[v] for v in t) <= core]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], [tris[i] for i in keep])
    mesh.update()
    colours = mesh.color_attributes.new("patch_colour", "FLOAT_COLOR", "CORNER")
    flat = []
    for i in keep:
        r, g, b = patch_colour(face_ids[i])
        flat += [r, g, b, 1.0] * 3
    colours.data.foreach_set("color", flat)
    ids = mesh.attributes.new("patch_id", "INT", "FACE")
    ids.data.foreach_set("value", [face_ids[i] for i in keep])
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    # Lift the patches a hair off the fluid they lie on, so they never z-fight with it.
    disp = obj.modifiers.new("lift", "DISPLACE")
    disp.strength = offset
    disp.mid_level = 0.0
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "patch_colour"
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.6
    links.new(attr.outputs["Color"], bsdf.inputs["Base Color"])
    mesh.materials.append(mat)
    return obj, len(keep)


def import_fluid(path):
    if not os.path.isfile(path):
        raise BadInput(f"{path}: no such fluid mesh")
    before = set(bpy.data.objects)
    if path.lower().endswith(".obj"):
        bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
    else:
        bpy.ops.import_mesh.ply(filepath=path)
    obj = [o for o in bpy.data.objects if o not in before][0]
    mat = bpy.data.materials.new("fluid_grey")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.5, 0.5, 0.52, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.5
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    return obj


def main():
    args = script_args()
    pattern = os.path.abspath(args.patches)
    if "%" not in pattern:
        raise BadInput(f"--patches {args.patches}: expected a pattern with %04d")
    dumps = {f: pattern % f for f in args.frame_list}
    for f, path in dumps.items():
        if not os.path.isfile(path):
            raise BadInput(f"{path} (frame {f}): no such patch dump")
    out_dir = os.path.abspath(args.out or os.path.dirname(pattern))
    os.makedirs(out_dir, exist_ok=True)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = lookdev.setup_scene(args)
    layers = {}
    for f, path in dumps.items():
        verts, weights, tris, face_ids = read_patch_ply(path)
        objs = []
        if args.fluid:
            objs.append(import_fluid(os.path.abspath(args.fluid % f)))
        lo, hi = lookdev.world_bbox(objs) if objs else (None, None)
        size = (hi - lo).length if objs else 1.0
        obj, kept = build_patch_object(f"patches.{f:04d}", verts, weights, tris, face_ids, args.core, 2e-3 * size)
        objs.append(obj)
        layers[f] = objs
        print(f"blender_patches: frame {f}: {len(set(face_ids))} patches, {kept} of {len(tris)} faces in the cores "
              f"(rest uv within {args.core} of the centre)", flush=True)
    everything = [o for objs in layers.values() for o in objs]
    lo, hi = lookdev.world_bbox(everything)
    if not args.no_ground:
        lookdev.add_ground(scene, lo, hi)
    lookdev.add_camera(scene, args, lo, hi)
    name = os.path.basename(pattern).split(".patches.")[0]
    for f in dumps:
        for g, objs in layers.items():
            for o in objs:
                o.hide_render = g != f
        scene.render.filepath = os.path.join(out_dir, f"{name}.patches.{f:04d}.png")
        bpy.ops.render.render(write_still=True)
        print(f"blender_patches: frame {f} -> {scene.render.filepath}", flush=True)


if __name__ == "__main__":
    try:
        main()
    except BadInput as e:
        print(f"blender_patches: error: {e}", file=sys.stderr, flush=True)
        sys.exit(2)
    except SystemExit:
        raise
    except Exception as e:
        import traceback
        traceback.print_exc()
        print(f"blender_patches: error: {e}", file=sys.stderr, flush=True)
        sys.exit(1)
