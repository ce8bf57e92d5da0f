"""Checks the lapflow_import add-on in Blender (headless) and prints what it saw.

    blender -b --factory-startup -P tools/blender/lapflow_import_test.py -- --bake DIR --out DIR
        [--install] [--steps 1,2,3] [--render 2,3 | --no-render] [--samples 16] [--resolution 160x120]

Imports the bake in DIR through the add-on's operator (File > Import >
lapflow bake), gives the object transforms and a modifier as an artist would,
steps the scene through the frames of --steps (default: the bake's first
three), then back to the second, to the same frame again, to sub-frames
around it, and to a frame before the bake and one after it, and records per step the mesh's vertex and face counts, which file it came
from, the frame the colour and height textures show, and the `velocity`
attribute. Then (unless --no-render) it renders the frames of --render
(default: the second and third step) as an animation with Cycles, once with
the bake's material (matte, no displacement) and once with an 18% grey
override, into OUT/tex/NAME.NNNN.png and OUT/grey/NAME.NNNN.png, from one
camera framed on all of them (the lighting of blender_lookdev.py, Standard
view, transparent film); and saves the scene, opens it again and steps once
more (the object re-links to its bake on load).

--install zips tools/blender/lapflow_import and installs and enables it
through Blender's preferences (as a user would: set BLENDER_USER_SCRIPTS to
a scratch folder first); without it the package is imported from this folder.

Writes OUT/facts.json and prints it on one line after `lapflow_import_test: `.
Exit codes: 0 done (the facts say what was seen), 2 bad input.
"""

import argparse
import json
import math
import os
import sys
import types
import zipfile

import bpy
import numpy as np
from mathutils import Vector

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # no __pycache__ in the source tree


def script_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender -b -P tools/blender/lapflow_import_test.py --")
    p.add_argument("--bake", required=True, help="bake folder or NAME.bake.json")
    p.add_argument("--out", required=True, help="folder for facts.json, renders and the saved scene")
    p.add_argument("--install", action="store_true", help="install the add-on from a zip through the preferences")
    p.add_argument("--steps", default="", help="frames to step through, e.g. 1,2,3 (default: the first three baked)")
    p.add_argument("--render", default="", help="two frames to render (default: the second and third step)")
    p.add_argument("--no-render", action="store_true")
    p.add_argument("--motion-blur", type=int, default=0, metavar="FRAME",
                   help="also render FRAME with Cycles motion blur, with and without the velocity attribute")
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--resolution", default="160x120")
    a = p.parse_args(argv)
    a.size = tuple(int(v) for v in a.resolution.lower().split("x"))
    return a


def frames_arg(text):
    return [int(x) for x in text.split(",") if x.strip()]


def load_addon(args):
    """The add-on module, enabled as Blender does it."""
    if not args.install:
        sys.path.insert(0, HERE)
        import lapflow_import
        lapflow_import.register()
        return lapflow_import
    zip_path = os.path.join(args.out, "lapflow_import.zip")
    with zipfile.ZipFile(zip_path, "w") as z:
        for root, _dirs, files in os.walk(os.path.join(HERE, "lapflow_import")):
            for f in files:
                if f.endswith(".py"):
                    full = os.path.join(root, f)
                    z.write(full, os.path.relpath(full, HERE))
    bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
    bpy.ops.preferences.addon_enable(module="lapflow_import")
    import lapflow_import
    return lapflow_import


def menu_has(addon):
    draw = bpy.types.TOPBAR_MT_file_import.draw
    return addon.menu_import in getattr(draw, "_draw_funcs", [])


def texture_facts(obj, node_name):
    """The frame and file the node's image user shows now (as evaluated for
    this scene frame: what the renderer and the viewport read)."""
    mat = obj.data.materials[0] if obj.data.materials else None
    if mat is None or node_name not in mat.node_tree.nodes:
        return None, None
    dg = bpy.context.evaluated_depsgraph_get()
    node = mat.evaluated_get(dg).node_tree.nodes[node_name]
    frame = node.image_user.frame_current
    return frame, os.path.basename(node.image.filepath_from_user(image_user=node.image_user))


def velocity_facts(mesh):
    attr = mesh.attributes.get("velocity")
    if attr is None:
        return {"velocity": False}
    v = np.zeros(len(attr.data) * 3, dtype=np.float32)
    attr.data.foreach_get("vector", v)
    v = v.reshape(-1, 3)
    return {"velocity": True, "velocity_type": attr.data_type, "velocity_domain": attr.domain,
            "velocity_count": len(attr.data),
            "velocity_max": float(np.linalg.norm(v, axis=1).max()) if len(v) else 0.0,
            "velocity_first": [float(x) for x in v[0]] if len(v) else [],
            "velocity_last": [float(x) for x in v[-1]] if len(v) else []}


def step_facts(addon, scene, obj, frame, subframe=0.0):
    scene.frame_set(frame, subframe=subframe)
    me = obj.data
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    ev_mesh = ev.to_mesh()
    facts = {"frame": frame, "subframe": subframe, "vertices": len(me.vertices), "faces": len(me.polygons),
             "corners": len(me.loops), "uv": len(me.uv_layers) > 0, "mesh_frame": me.get("lapflow_frame"),
             "source": me.get("lapflow_source"), "loads": addon.load_count,
             "evaluated_vertices": len(ev_mesh.vertices), "evaluated_velocity": "velocity" in ev_mesh.attributes}
    ev.to_mesh_clear()
    facts["color_frame"], facts["color_file"] = texture_facts(obj, "lapflow color")
    facts["disp_frame"], facts["disp_file"] = texture_facts(obj, "lapflow disp")
    facts.update(velocity_facts(me))
    return facts


def kept_facts(obj, mesh_name, material_name):
    return {"object": obj.name, "location": list(obj.location), "rotation": list(obj.rotation_euler),
            "scale": list(obj.scale), "modifiers": [m.type for m in obj.modifiers],
            "mesh_kept": obj.data.name == mesh_name,
            "material_kept": bool(obj.data.materials) and obj.data.materials[0].name == material_name,
            "lock_interface": bpy.context.scene.render.use_lock_interface}


def render(addon, scene, obj, frames, folder, name, seen):
    """Renders `frames` as one animation (the handler swaps the mesh per frame)."""
    scene.frame_start, scene.frame_end = frames[0], frames[-1]
    scene.frame_step = max(1, frames[-1] - frames[0]) if len(frames) > 1 else 1
    scene.render.filepath = os.path.join(folder, name + ".####")

    def record(sc, *_):
        seen.append({"frame": sc.frame_current, "vertices": len(obj.data.vertices),
                     "mesh_frame": obj.data.get("lapflow_frame"), "folder": os.path.basename(folder)})

    bpy.app.handlers.render_post.append(record)
    try:
        bpy.ops.render.render(animation=True)
    finally:
        bpy.app.handlers.render_post.remove(record)
    return [os.path.join(folder, f"{name}.{f:04d}.png") for f in frames]


def setup_render(args, scene, obj, frames):
    """blender_lookdev's sun, sky and camera (framed on `frames`), Standard
    view, transparent film."""
    sys.path.insert(0, HERE)
    import blender_lookdev
    look = types.SimpleNamespace(samples=args.samples, size=args.size, transparent=True,
                                 view_transform="Standard", exposure=-1.0, camera="auto", target="")
    blender_lookdev.setup_scene(look)
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    for f in frames:
        scene.frame_set(f)
        a, b = blender_lookdev.world_bbox([obj])
        lo, hi = Vector(map(min, lo, a)), Vector(map(max, hi, b))
    blender_lookdev.add_camera(scene, look, lo, hi)


def motion_blur(args, scene, obj, frame):
    """Renders `frame` without motion blur, with it, and with it but without
    the velocity attribute (Cycles then has no motion for the mesh)."""
    folder = os.path.join(args.out, "motion_blur")
    scene.frame_set(frame)
    loads = []
    out = {"frame": frame}
    for key, blur in (("still", False), ("blurred", True), ("blurred_without_velocity", True)):
        if key == "blurred_without_velocity":
            obj.data.attributes.remove(obj.data.attributes["velocity"])
        scene.render.use_motion_blur = blur
        scene.render.motion_blur_shutter = 1.0  # a whole frame: the mesh moves by velocity / fps
        scene.render.filepath = os.path.join(folder, key + ".png")
        bpy.ops.render.render(write_still=True)
        out[key] = scene.render.filepath
        loads.append(sys.modules["lapflow_import"].load_count)
    scene.render.use_motion_blur = False
    out["loads"] = loads  # the same three: no mesh was read during the renders
    # Stepping away and back reads the frame again, velocity and all.
    scene.frame_set(frame + 1 if frame + 1 in sys.modules["lapflow_import"].get_bake(obj["lapflow_bake"]).frames
                    else frame - 1)
    scene.frame_set(frame)
    out["velocity_after_reload"] = "velocity" in obj.data.attributes
    return out


def main():
    args = script_args()
    os.makedirs(args.out, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon = load_addon(args)
    scene = bpy.context.scene
    try:
        manifest = addon.find_manifest(args.bake)
        bake = addon.get_bake(manifest)
    except addon.BakeError as e:
        print(f"lapflow_import_test: error: {e}", file=sys.stderr, flush=True)
        sys.exit(2)
    steps = frames_arg(args.steps) if args.steps else bake.frames[:3]
    facts = {"bake": manifest, "name": bake.name, "frames": bake.frames, "addon_file": addon.__file__,
             "menu": menu_has(addon),
             "handler": any(getattr(h, "__name__", "") == "lapflow_frame_change_pre"
                            for h in bpy.app.handlers.frame_change_pre)}

    # Import through the operator, as the menu entry does.
    scene.frame_set(steps[0])
    result = bpy.ops.import_scene.lapflow_bake(filepath=manifest, material="matte", displacement="none")
    facts["operator"] = sorted(result)
    obj = bpy.context.view_layer.objects.active
    facts["objects"] = [o.name for o in bpy.data.objects]
    facts["scene_frames"] = [scene.frame_start, scene.frame_end]
    mesh_name, material_name = obj.data.name, obj.data.materials[0].name
    # The artist's work on the object, which the frame swaps must keep.
    obj.location = (0.05, -0.02, 0.01)
    obj.rotation_euler = (0.0, 0.0, math.radians(20))
    obj.scale = (1.2, 1.2, 1.2)
    obj.modifiers.new("artist", "TRIANGULATE")

    facts["steps"] = [step_facts(addon, scene, obj, f) for f in steps]
    if len(steps) > 1:
        # Back to the second frame, then the same frame again (no reload),
        # and sub-frames (motion-blur steps) around it (the nearest frame).
        facts["steps"].append(step_facts(addon, scene, obj, steps[1]))
        facts["steps"].append(step_facts(addon, scene, obj, steps[1]))
        facts["steps"].append(step_facts(addon, scene, obj, steps[1] - 1, 0.6))
        facts["steps"].append(step_facts(addon, scene, obj, steps[1], 0.4))
    # Before the bake and after it: the first and the last frame held.
    facts["steps"].append(step_facts(addon, scene, obj, bake.frames[0] - 1))
    facts["steps"].append(step_facts(addon, scene, obj, bake.frames[-1] + 2))
    facts["kept"] = kept_facts(obj, mesh_name, material_name)

    if not args.no_render or args.motion_blur:
        frames = frames_arg(args.render) if args.render else steps[1:3]
        setup_render(args, scene, obj, frames + ([args.motion_blur] if args.motion_blur else []))
    if not args.no_render:
        seen = []
        tex = render(addon, scene, obj, frames, os.path.join(args.out, "tex"), bake.name, seen)
        grey = bpy.data.materials.new("grey reference")
        grey.use_nodes = True
        bsdf = grey.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (0.18, 0.18, 0.18, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.5
        bpy.context.view_layer.material_override = grey
        grey_files = render(addon, scene, obj, frames, os.path.join(args.out, "grey"), bake.name, seen)
        bpy.context.view_layer.material_override = None
        facts["renders"] = [{"frame": f, "textured": t, "grey": g} for f, t, g in zip(frames, tex, grey_files)]
        facts["rendered_meshes"] = seen

    if args.motion_blur:
        facts["motion_blur"] = motion_blur(args, scene, obj, args.motion_blur)

    # Saved and opened again: the object re-links to its bake.
    blend = os.path.join(args.out, "scene.blend")
    scene.frame_set(steps[0])
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    obj = next(o for o in bpy.data.objects if "lapflow_bake" in o)
    loads = addon.load_count
    reload = {"frame": scene.frame_current, "vertices": len(obj.data.vertices), "loads_on_open": loads}
    last = steps[-1]
    scene.frame_set(last)
    reload.update({"stepped_to": last, "stepped_vertices": len(obj.data.vertices),
                   "stepped_mesh_frame": obj.data.get("lapflow_frame"), "stepped_color_frame": texture_facts(obj, "lapflow color")[0],
                   "location": list(obj.location), "modifiers": [m.type for m in obj.modifiers]})
    facts["reopened"] = reload

    with open(os.path.join(args.out, "facts.json"), "w") as f:
        json.dump(facts, f, indent=1)
    print("lapflow_import_test: " + json.dumps(facts), flush=True)


if __name__ == "__main__":
    try:
        main()
    except SystemExit:
        raise
    except Exception as e:
        import traceback
        traceback.print_exc()
        print(f"lapflow_import_test: error: {e}", file=sys.stderr, flush=True)
        sys.exit(1)
