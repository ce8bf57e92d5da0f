"""lapflow bake importer for Blender (written for and tested with Debian's Blender 3.4).

Brings a whole lapflow bake in as one animated mesh object:

- per frame, the object's mesh is refilled from the frame's USD layer
  (NAME.usd.NNNN.usda: points, faces, indexed st, velocities) or, when a frame
  has none, from its OBJ (NAME.NNNN.obj: no velocity then); the swap runs in a
  persistent frame_change_pre handler, so playback and renders follow the
  scene frame;
- the velocity becomes the point attribute ``velocity`` (FLOAT_VECTOR, m/s),
  from which Cycles computes motion blur;
- the material reads NAME.color.NNNN.exr and NAME.disp.NNNN.exr as image
  sequences synced to the scene frame;
- the object, its transforms, modifiers and material slots stay: only the
  mesh's geometry changes.

Install: zip the ``lapflow_import`` folder and use Edit > Preferences >
Add-ons > Install, or put the folder in an add-ons path. Then File > Import >
lapflow bake (.bake.json). From Python::

    import lapflow_import
    obj = lapflow_import.import_bake("/path/to/bake/NAME.bake.json")

(``import_bake`` installs the frame handler itself when the add-on is not
enabled.)
"""

bl_info = {
    "name": "lapflow bake importer",
    "author": "lapflow",
    "version": (1, 0, 0),
    "blender": (3, 4, 0),
    "location": "File > Import > lapflow bake (.bake.json)",
    "description": "Import a lapflow bake as one animated object: per-frame mesh, "
                   "atlas image sequences, velocity for motion blur",
    "category": "Import-Export",
}

import bisect
import glob
import json
import math
import os
import re

import bpy
import numpy as np
from bpy.app.handlers import persistent

PROP_BAKE = "lapflow_bake"      # on the object: the manifest's path
PROP_FRAME = "lapflow_frame"    # on the mesh: the bake frame its geometry holds
PROP_SOURCE = "lapflow_source"  # on the mesh: "usd" or "obj"
PROP_STAMP = "lapflow_stamp"    # on the mesh: the loaded file's size and mtime
UV_NAME = "UVMap"
LOG = "lapflow_import"

# Meshes filled since the module was loaded (a count, for tests and profiling).
load_count = 0


class BakeError(Exception):
    """A bake that cannot be read: missing manifest or frame files, bad data."""


def _log(msg):
    print(f"{LOG}: {msg}", flush=True)


# ---------------------------------------------------------------------------
# The bake: manifest and file names

class Bake:
    """What the importer needs from NAME.bake.json."""

    def __init__(self, manifest):
        self.manifest = manifest
        self.folder = os.path.dirname(manifest)
        try:
            with open(manifest) as f:
                m = json.load(f)
            self.name = str(m["name"])
            self.frames = sorted(int(x) for x in m["frames"])
            self.fps = float(m.get("fps", 24.0))
            self.radius = float(m.get("radius", 0.0))
            settings = m.get("settings") or {}
            self.up = str(settings.get("up_axis", "z")).lower() if isinstance(settings, dict) else "z"
            if self.up not in ("y", "z"):
                self.up = "z"
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise BakeError(f"{manifest}: not a readable lapflow bake manifest ({e})")
        if not self.frames:
            raise BakeError(f"{manifest}: the bake lists no frames")

    def path(self, kind, frame):
        """kind: obj, usd, color or disp."""
        if kind == "obj":
            base = f"{self.name}.{frame:04d}.obj"
        elif kind == "usd":
            base = f"{self.name}.usd.{frame:04d}.usda"
        else:
            base = f"{self.name}.{kind}.{frame:04d}.exr"
        return os.path.join(self.folder, base)

    def frame_for(self, scene_frame):
        """The baked frame shown at a scene frame (sub-frames count as their
        whole frame, as for image sequences): that frame, or the last baked
        frame before it (the first before the bake starts)."""
        f = int(math.floor(scene_frame + 1e-4))
        i = bisect.bisect_right(self.frames, f) - 1
        return self.frames[max(i, 0)]


def find_manifest(filepath):
    """The manifest's absolute path from a manifest path or a bake folder."""
    path = os.path.abspath(bpy.path.abspath(filepath))
    if os.path.isdir(path):
        found = sorted(glob.glob(os.path.join(path, "*.bake.json")))
        if not found:
            raise BakeError(f"{path}: no *.bake.json in this folder: is it a lapflow bake output?")
        if len(found) > 1:
            names = ", ".join(os.path.basename(f) for f in found)
            raise BakeError(f"{path}: several bakes ({names}): pick one manifest")
        return found[0]
    if not os.path.isfile(path):
        raise BakeError(f"{path}: no such bake manifest")
    return path


_bakes = {}  # manifest path -> (mtime, Bake)


def get_bake(manifest):
    manifest = os.path.abspath(bpy.path.abspath(manifest))
    try:
        mtime = os.stat(manifest).st_mtime_ns
    except OSError:
        raise BakeError(f"{manifest}: no such bake manifest")
    cached = _bakes.get(manifest)
    if cached and cached[0] == mtime:
        return cached[1]
    bake = Bake(manifest)
    _bakes[manifest] = (mtime, bake)
    return bake


# ---------------------------------------------------------------------------
# Reading one frame

class FrameData:
    """One frame's geometry: points (n, 3), face sizes, per-corner point
    indices, per-corner uv (or None), per-point velocity in m/s (or None)."""

    def __init__(self, points, counts, indices, uv, velocity, source):
        self.points, self.counts, self.indices = points, counts, indices
        self.uv, self.velocity, self.source = uv, velocity, source


_PUNCT = str.maketrans("(),", "   ")
_DECL = re.compile(r"\s*(?:(?:uniform|custom)\s+)*[A-Za-z_]\w*\[\]\s+([\w:]+?)(?:\.timeSamples)?\s*=")


def _numbers(text, dtype):
    return np.fromstring(text.translate(_PUNCT), dtype=dtype, sep=" ")


def _usda_arrays(text):
    """name -> the raw text inside the [...] of every array attribute."""
    out = {}
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        i += 1
        m = _DECL.match(line[:256])
        if not m:
            continue
        start = line.find("[", m.end())
        if start < 0:
            continue
        body = line[start + 1:]
        while "]" not in body and i < len(lines):  # an array over several lines
            body += " " + lines[i]
            i += 1
        end = body.find("]")
        if end < 0:
            raise BakeError(f"attribute {m.group(1)}: unterminated array")
        out[m.group(1)] = body[:end]
    return out


def read_usda(path):
    """The mesh of a lapflow USD text layer (one Mesh, arrays as time samples)."""
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as e:
        raise BakeError(f"{path}: cannot read ({e})")
    if not text.startswith("#usda"):
        raise BakeError(f"{path}: not a USD text layer (no #usda header)")
    arrays = _usda_arrays(text)
    for key in ("points", "faceVertexCounts", "faceVertexIndices"):
        if key not in arrays:
            raise BakeError(f"{path}: no {key}")
    points = _numbers(arrays["points"], np.float32)
    counts = _numbers(arrays["faceVertexCounts"], np.int64)
    indices = _numbers(arrays["faceVertexIndices"], np.int64)
    if points.size % 3:
        raise BakeError(f"{path}: points: {points.size} numbers, not a multiple of 3")
    points = points.reshape(-1, 3)
    n = len(points)
    if counts.sum() != indices.size or (counts.size and counts.min() < 3):
        raise BakeError(f"{path}: faceVertexCounts add up to {counts.sum()}, faceVertexIndices has {indices.size}")
    if indices.size and (indices.min() < 0 or indices.max() >= n):
        raise BakeError(f"{path}: faceVertexIndices out of range 0..{n - 1}")
    uv = None
    if "primvars:st" in arrays:
        st = _numbers(arrays["primvars:st"], np.float32)
        if st.size % 2:
            raise BakeError(f"{path}: primvars:st: {st.size} numbers, not a multiple of 2")
        st = st.reshape(-1, 2)
        if "primvars:st:indices" in arrays:
            st_idx = _numbers(arrays["primvars:st:indices"], np.int64)
            if st_idx.size != indices.size:
                raise BakeError(f"{path}: primvars:st:indices has {st_idx.size} entries for {indices.size} corners")
            if st_idx.size and (st_idx.min() < 0 or st_idx.max() >= len(st)):
                raise BakeError(f"{path}: primvars:st:indices out of range 0..{len(st) - 1}")
            uv = st[st_idx]
        elif len(st) == indices.size:   # faceVarying, not indexed
            uv = st
        elif len(st) == n:              # per point
            uv = st[indices]
        else:
            raise BakeError(f"{path}: primvars:st has {len(st)} values for {n} points and {indices.size} corners")
    velocity = None
    if "velocities" in arrays:
        v = _numbers(arrays["velocities"], np.float32)
        if v.size != 3 * n:
            raise BakeError(f"{path}: velocities has {v.size // 3} values for {n} points")
        velocity = v.reshape(-1, 3)
    return FrameData(points, counts.astype(np.int32), indices.astype(np.int32), uv, velocity, "usd")


def _obj_numbers(lines, width, path, what):
    """The first `width` numbers of each line."""
    flat = np.fromstring(" ".join(lines), dtype=np.float32, sep=" ")
    if flat.size == width * len(lines):
        return flat.reshape(-1, width)
    try:  # lines with extra components (w, colours)
        return np.array([[float(x) for x in l.split()[:width]] for l in lines], dtype=np.float32).reshape(-1, width)
    except ValueError:
        raise BakeError(f"{path}: unreadable {what} line")


def _obj_index(a, n, path, what):
    a = np.where(a < 0, a + n, a - 1)  # 1-based, or negative = relative to the end
    if a.size and (a.min() < 0 or a.max() >= n):
        raise BakeError(f"{path}: face {what} index out of range 1..{n}")
    return a.astype(np.int32)


def read_obj(path):
    """The mesh of a Wavefront OBJ (v, vt, f; normals are left to Blender)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
    except OSError as e:
        raise BakeError(f"{path}: cannot read ({e})")
    v_lines, vt_lines, f_lines = [], [], []
    for line in text.splitlines():
        if line.startswith("v "):
            v_lines.append(line[2:])
        elif line.startswith("vt "):
            vt_lines.append(line[3:])
        elif line.startswith("f "):
            f_lines.append(line[2:])
    points = _obj_numbers(v_lines, 3, path, "v")
    st = _obj_numbers(vt_lines, 2, path, "vt") if vt_lines else np.zeros((0, 2), np.float32)
    counts = np.fromiter((len(l.split()) for l in f_lines), dtype=np.int32, count=len(f_lines))
    corners = int(counts.sum())
    joined = " ".join(f_lines)
    slashes = joined.count("/")
    try:
        if "//" not in joined and slashes == 2 * corners:    # v/vt/vn
            t = np.fromstring(joined.replace("/", " "), dtype=np.int64, sep=" ").reshape(-1, 3)
            vi, ti = t[:, 0], t[:, 1]
        elif "//" not in joined and slashes == corners:      # v/vt
            t = np.fromstring(joined.replace("/", " "), dtype=np.int64, sep=" ").reshape(-1, 2)
            vi, ti = t[:, 0], t[:, 1]
        else:                                                # v, v//vn or a mix
            parts = [c.split("/") for c in joined.split()]
            vi = np.array([int(p[0]) for p in parts], dtype=np.int64)
            ti = None
            if all(len(p) > 1 and p[1] for p in parts):
                ti = np.array([int(p[1]) for p in parts], dtype=np.int64)
    except ValueError:
        raise BakeError(f"{path}: unreadable f line")
    if vi.size != corners:
        raise BakeError(f"{path}: unreadable f line")
    if counts.size and counts.min() < 3:
        raise BakeError(f"{path}: a face with fewer than 3 corners")
    indices = _obj_index(vi, len(points), path, "v")
    uv = st[_obj_index(ti, len(st), path, "vt")] if ti is not None and len(st) else None
    return FrameData(points, counts, indices, uv, None, "obj")


_no_usd_said = set()       # bakes whose missing USD layers were reported
_no_velocity_said = set()  # bakes whose USD layers without velocities were reported


def read_frame(bake, frame):
    usd = bake.path("usd", frame)
    if os.path.isfile(usd):
        data = read_usda(usd)
        if data.velocity is None and bake.manifest not in _no_velocity_said:
            _no_velocity_said.add(bake.manifest)
            _log(f"{bake.name}: {os.path.basename(usd)} has no velocities (no 'velocity' attribute, "
                 "no motion blur from it)")
        return data, usd
    obj = bake.path("obj", frame)
    if not os.path.isfile(obj):
        raise BakeError(f"{obj} (frame {frame}): neither {os.path.basename(usd)} nor the OBJ is there")
    if bake.manifest not in _no_usd_said:
        _no_usd_said.add(bake.manifest)
        _log(f"{bake.name}: no USD layer ({os.path.basename(usd)}): reading the OBJ, "
             "which has no velocity (no 'velocity' attribute, no motion blur from it)")
    return read_obj(obj), obj


def _stamp(path):
    st = os.stat(path)
    return f"{st.st_size}:{st.st_mtime_ns}"


def fill_mesh(mesh, data):
    """Replaces the geometry of `mesh` (materials and the datablock stay)."""
    global load_count
    mesh.clear_geometry()
    nv, nf, nl = len(data.points), len(data.counts), len(data.indices)
    mesh.vertices.add(nv)
    mesh.vertices.foreach_set("co", np.ascontiguousarray(data.points, dtype=np.float32).ravel())
    mesh.loops.add(nl)
    mesh.loops.foreach_set("vertex_index", data.indices)
    mesh.polygons.add(nf)
    starts = np.zeros(nf, dtype=np.int32)
    if nf:
        np.cumsum(data.counts[:-1], out=starts[1:])
    mesh.polygons.foreach_set("loop_start", starts)
    mesh.polygons.foreach_set("loop_total", data.counts)
    mesh.polygons.foreach_set("use_smooth", np.ones(nf, dtype=bool))
    if data.uv is not None:
        uv = mesh.uv_layers.new(name=UV_NAME)
        uv.data.foreach_set("uv", np.ascontiguousarray(data.uv, dtype=np.float32).ravel())
    mesh.update(calc_edges=True)
    if data.velocity is not None:
        attr = mesh.attributes.new("velocity", "FLOAT_VECTOR", "POINT")
        attr.data.foreach_set("vector", np.ascontiguousarray(data.velocity, dtype=np.float32).ravel())
    load_count += 1


def _fill_frame(mesh, data, frame, path):
    fill_mesh(mesh, data)
    mesh[PROP_FRAME] = frame
    mesh[PROP_SOURCE] = data.source
    mesh[PROP_STAMP] = _stamp(path)


def show_frame(obj, scene_frame, force=False):
    """Fills `obj`'s mesh with the baked frame shown at `scene_frame`
    unless it already holds it. Returns the bake frame."""
    bake = get_bake(obj[PROP_BAKE])
    mesh = obj.data
    held = mesh.get(PROP_FRAME)
    if not force and held is not None and abs(scene_frame - round(scene_frame)) > 1e-4 and \
            abs(scene_frame - held) < 1:
        # A sub-frame (a motion-blur step of Cycles around the frame being
        # rendered): keep the frame's mesh, whose velocity makes the blur.
        return held
    frame = bake.frame_for(scene_frame)
    if not force and mesh.get(PROP_FRAME) == frame and mesh.get(PROP_SOURCE):
        # Same frame: reload only if its file changed on disk (a re-bake).
        src = bake.path(mesh[PROP_SOURCE], frame)
        try:
            if os.path.isfile(bake.path("usd", frame)) == (mesh[PROP_SOURCE] == "usd") and \
                    mesh.get(PROP_STAMP) == _stamp(src):
                return frame
        except OSError:
            pass
    data, path = read_frame(bake, frame)
    _fill_frame(mesh, data, frame, path)
    return frame


# ---------------------------------------------------------------------------
# Handlers

_failed = set()  # (object name, frame) already reported


def _bake_objects():
    # Not in edit mode (leaving it would write the old edit mesh back), not
    # linked from a library (read-only).
    return [o for o in bpy.data.objects
            if o.type == "MESH" and PROP_BAKE in o and o.data is not None
            and o.mode != "EDIT" and o.data.library is None and o.data.override_library is None]


def _update_all(scene, force=False):
    t = scene.frame_current + scene.frame_subframe
    done = set()
    for obj in _bake_objects():
        if obj.data.name in done:  # linked duplicates share the mesh
            continue
        done.add(obj.data.name)
        try:
            show_frame(obj, t, force)
        except (BakeError, OSError) as e:
            key = (obj.name, int(t))
            if key not in _failed:
                _failed.add(key)
                _log(f"{obj.name}: frame {t:g}: {e} (the mesh keeps what it had)")


@persistent
def lapflow_frame_change_pre(scene, depsgraph=None):
    _update_all(scene)


@persistent
def lapflow_load_post(*_args):
    # A saved .blend: the objects carry their bake's path; read the current
    # frame again from the bake (it may have been re-baked since).
    _failed.clear()
    _bakes.clear()
    for scene in bpy.data.scenes:
        if any(PROP_BAKE in o for o in scene.objects):
            scene.render.use_lock_interface = True
    if bpy.context.scene is not None:
        _update_all(bpy.context.scene, force=True)


_HANDLERS = ((bpy.app.handlers.frame_change_pre, lapflow_frame_change_pre),
             (bpy.app.handlers.load_post, lapflow_load_post))


def _remove_handlers():
    for lst, fn in _HANDLERS:
        for h in list(lst):
            if getattr(h, "__name__", "") == fn.__name__:  # also those of an older copy of the module
                lst.remove(h)


def ensure_handlers():
    """Installs the frame and load handlers (once)."""
    for lst, fn in _HANDLERS:
        if fn not in lst:
            for h in list(lst):
                if getattr(h, "__name__", "") == fn.__name__:
                    lst.remove(h)
            lst.append(fn)


# ---------------------------------------------------------------------------
# Material

def _colorspace(img, names):
    for name in names:
        try:
            img.colorspace_settings.name = name
            return
        except TypeError:
            continue


def _sequence_image(bake, kind, colorspaces):
    first = bake.frames[0]
    path = bake.path(kind, first)
    if not os.path.isfile(path):
        raise BakeError(f"{path} (frame {first}): missing {kind} atlas of the bake")
    img = bpy.data.images.load(path, check_existing=False)
    img.source = "SEQUENCE"
    _colorspace(img, colorspaces)
    # The atlas's alpha only marks chart texels; keep the colour as stored.
    img.alpha_mode = "CHANNEL_PACKED"
    return img


def _sync_to_scene(node, bake):
    """Texture frame = scene frame over the bake's frames, held at the first
    before them and at the last after them, as the mesh is. Blender shows
    file number clamp(scene - start + 1, 0, duration) + offset (and nothing
    when duration is 0)."""
    first, last = bake.frames[0], bake.frames[-1]
    iu = node.image_user
    if last > first:
        iu.frame_start = first + 1
        iu.frame_offset = first
        iu.frame_duration = last - first
        iu.use_cyclic = False
    else:  # one frame: a cycle of one shows it at every scene frame
        iu.frame_start = first
        iu.frame_offset = first - 1
        iu.frame_duration = 1
        iu.use_cyclic = True
    iu.use_auto_refresh = True


def make_material(bake, material="liquid", displacement="bump", displacement_scale=None):
    """liquid (glossy, wet), matte, or grey (18% grey, no texture: a
    reference); displacement bump, true or none."""
    if displacement_scale is None:
        displacement_scale = 0.1 * bake.radius
    mat = bpy.data.materials.new(bake.name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    out.location = (400, 0)
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    if material == "grey":
        bsdf.inputs["Base Color"].default_value = (0.18, 0.18, 0.18, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.5
        return mat
    uv = nodes.new("ShaderNodeUVMap")
    uv.uv_map = UV_NAME
    uv.location = (-700, 0)
    color = nodes.new("ShaderNodeTexImage")
    color.name = color.label = "lapflow color"
    color.location = (-450, 150)
    # The atlas holds linear values already: no colour decoding.
    color.image = _sequence_image(bake, "color", ("Linear", "Linear Rec.709"))
    color.interpolation = "Linear"
    color.extension = "EXTEND"
    _sync_to_scene(color, bake)
    links.new(uv.outputs["UV"], color.inputs["Vector"])
    links.new(color.outputs["Color"], bsdf.inputs["Base Color"])
    if material == "liquid":
        # Wet: a sharp clear coat over a moderately glossy base.
        bsdf.inputs["Roughness"].default_value = 0.25
        bsdf.inputs["Specular"].default_value = 0.5
        bsdf.inputs["Clearcoat"].default_value = 0.8
        bsdf.inputs["Clearcoat Roughness"].default_value = 0.04
    else:
        bsdf.inputs["Roughness"].default_value = 0.8
        bsdf.inputs["Specular"].default_value = 0.2
    if displacement == "none" or displacement_scale <= 0:
        return mat
    disp = nodes.new("ShaderNodeTexImage")
    disp.name = disp.label = "lapflow disp"
    disp.location = (-450, -200)
    disp.image = _sequence_image(bake, "disp", ("Non-Color",))
    disp.interpolation = "Linear"
    disp.extension = "EXTEND"
    _sync_to_scene(disp, bake)
    links.new(uv.outputs["UV"], disp.inputs["Vector"])
    if displacement == "bump":
        bump = nodes.new("ShaderNodeBump")
        bump.location = (-200, -200)
        bump.inputs["Distance"].default_value = displacement_scale
        links.new(disp.outputs["Color"], bump.inputs["Height"])
        links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
        links.new(bump.outputs["Normal"], bsdf.inputs["Clearcoat Normal"])
    else:
        node = nodes.new("ShaderNodeDisplacement")
        node.location = (150, -250)
        node.inputs["Scale"].default_value = displacement_scale
        node.inputs["Midlevel"].default_value = 0.5
        links.new(disp.outputs["Color"], node.inputs["Height"])
        links.new(node.outputs["Displacement"], out.inputs["Displacement"])
        mat.cycles.displacement_method = "BOTH"
    return mat


# ---------------------------------------------------------------------------
# Import

MATERIALS = ("liquid", "matte", "grey")
DISPLACEMENTS = ("bump", "true", "none")


def import_bake(filepath, *, name=None, material="liquid", displacement="bump", displacement_scale=None,
                up=None, set_scene=True, collection=None, context=None):
    """Imports the bake whose manifest (NAME.bake.json) or folder is
    `filepath` as one mesh object and returns it.

    material: liquid | matte | grey; displacement: bump | true (a 2-level
    simple Subdivision modifier and true displacement) | none;
    displacement_scale: height of displacement value 1 (default 0.1 x the
    bake's patch radius); up: "z" (Z up, as Blender) or "y" (a Y-up bake,
    turned +90 degrees about X by the object's rotation); None: the
    manifest's settings.up_axis (z when absent); set_scene: set the
    scene's frame range and fps to the bake's; collection: where to link the
    object (default: the context's collection)."""
    if material not in MATERIALS:
        raise ValueError(f"material {material!r}: expected one of {MATERIALS}")
    if displacement not in DISPLACEMENTS:
        raise ValueError(f"displacement {displacement!r}: expected one of {DISPLACEMENTS}")
    if up not in (None, "z", "y"):
        raise ValueError(f"up {up!r}: expected 'z', 'y' or None")
    context = context or bpy.context
    scene = context.scene
    bake = get_bake(find_manifest(filepath))
    up = up or bake.up
    # Everything that can fail before anything is made.
    frame = bake.frame_for(scene.frame_current + scene.frame_subframe)
    data, path = read_frame(bake, frame)
    if material != "grey":
        for kind in ("color", "disp") if displacement != "none" else ("color",):
            if not os.path.isfile(bake.path(kind, bake.frames[0])):
                raise BakeError(f"{bake.path(kind, bake.frames[0])} (frame {bake.frames[0]}): "
                                f"missing {kind} atlas of the bake")
    ensure_handlers()

    mesh = bpy.data.meshes.new(name or bake.name)
    obj = bpy.data.objects.new(name or bake.name, mesh)
    obj[PROP_BAKE] = bake.manifest
    mat = make_material(bake, material, displacement, displacement_scale)
    mesh.materials.append(mat)
    if displacement == "true" and material != "grey":
        mod = obj.modifiers.new("subdivide", "SUBSURF")
        mod.subdivision_type = "SIMPLE"
        mod.levels = mod.render_levels = 2
    if up == "y":
        obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
    if set_scene:
        scene.frame_start, scene.frame_end = bake.frames[0], bake.frames[-1]
        fps = max(1, int(round(bake.fps)))
        scene.render.fps, scene.render.fps_base = fps, fps / bake.fps if bake.fps > 0 else 1.0
    # Renders change the mesh in frame_change_pre: keep the UI off the data then.
    scene.render.use_lock_interface = True
    _fill_frame(mesh, data, frame, path)
    (collection or context.collection or scene.collection).objects.link(obj)
    view_layer = getattr(context, "view_layer", None)
    if view_layer is not None:
        try:  # not when the collection is outside this view layer
            for o in view_layer.objects:
                o.select_set(False)
            obj.select_set(True, view_layer=view_layer)
            view_layer.objects.active = obj
        except (RuntimeError, ValueError):
            pass
    return obj


# ---------------------------------------------------------------------------
# Operator and menu

class IMPORT_SCENE_OT_lapflow_bake(bpy.types.Operator):
    """Import a lapflow bake as one animated object (mesh per frame, atlas image sequences, velocity)"""
    bl_idname = "import_scene.lapflow_bake"
    bl_label = "Import lapflow bake"
    bl_options = {"REGISTER", "UNDO"}

    filepath: bpy.props.StringProperty(subtype="FILE_PATH")
    filter_glob: bpy.props.StringProperty(default="*.bake.json", options={"HIDDEN"})
    material: bpy.props.EnumProperty(
        name="Material",
        items=(("liquid", "Liquid", "Glossy base with a sharp clear coat: the wet look"),
               ("matte", "Matte", "Rough, no clear coat"),
               ("grey", "Grey", "Flat 18% grey without texture (a reference)")),
        default="liquid")
    displacement: bpy.props.EnumProperty(
        name="Displacement",
        items=(("bump", "Bump", "The height atlas as bump"),
               ("true", "True", "True displacement on a 2-level simple subdivision (slower)"),
               ("none", "None", "No displacement")),
        default="bump")
    displacement_scale: bpy.props.FloatProperty(
        name="Displacement Scale", default=-1.0, min=-1.0,
        description="Height of displacement value 1 in scene units (-1: 0.1 x the bake's patch radius)")
    up: bpy.props.EnumProperty(name="Up Axis", items=(("auto", "From Bake", "The bake's up axis (its manifest's)"),
                                                       ("z", "Z", "Z up, as Blender: the mesh as it is"),
                                                       ("y", "Y", "Y up: turned +90 degrees about X")),
                               default="auto")
    set_scene: bpy.props.BoolProperty(name="Set Frame Range and FPS", default=True,
                                      description="Set the scene's frame range and fps to the bake's")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        try:
            obj = import_bake(self.filepath, material=self.material, displacement=self.displacement,
                              displacement_scale=None if self.displacement_scale < 0 else self.displacement_scale,
                              up=None if self.up == "auto" else self.up, set_scene=self.set_scene, context=context)
        except BakeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, f"lapflow bake {obj.name}: frames {get_bake(obj[PROP_BAKE]).frames[0]}-"
                              f"{get_bake(obj[PROP_BAKE]).frames[-1]}")
        return {"FINISHED"}


def menu_import(self, context):
    self.layout.operator(IMPORT_SCENE_OT_lapflow_bake.bl_idname, text="lapflow bake (.bake.json)")


def register():
    bpy.utils.register_class(IMPORT_SCENE_OT_lapflow_bake)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    ensure_handlers()


def unregister():
    _remove_handlers()
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    bpy.utils.unregister_class(IMPORT_SCENE_OT_lapflow_bake)


if __name__ == "__main__":
    register()
