#!/usr/bin/env python3
"""Writes the fuzzers' seed corpus (tests/fuzz/corpus/<target>/): small files
made by hand in every layout the readers accept, plus the first faces of a
shared frame cut down to a few kilobytes. Run from anywhere:
    python3 tests/fuzz/make_corpus.py [/work/shared/data]
The result is committed; rerun it only to change the seeds. The regress_*
files beside them are inputs the fuzzers found (each a fixed bug, named in
docs/robustness.md): they are kept by hand, not written here."""
import json
import os
import struct
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "..", "..", "..", "shared", "data")
OUT = os.path.join(HERE, "corpus")


def put(target, name, data):
    os.makedirs(os.path.join(OUT, target), exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(OUT, target, name), "wb") as f:
        f.write(data)


# ---- PLY ------------------------------------------------------------------
TET_V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TET_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def ply_header(fmt, nv, nf, vprops, face="property list uchar int vertex_indices", extra=""):
    h = f"ply\nformat {fmt} 1.0\ncomment lapflow fuzz seed\nelement vertex {nv}\n"
    h += "".join(f"property {t} {n}\n" for t, n in vprops)
    h += extra
    h += f"element face {nf}\n{face}\nend_header\n"
    return h


def binary_ply(endian, verts, faces, vel=True, vtype="float", itype="int", ctype="uchar"):
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    props = [(vtype, a) for a in "xyz"] + ([(vtype, a) for a in ("vx", "vy", "vz")] if vel else [])
    code = {"float": "f", "double": "d"}[vtype]
    icode = {"int": "i", "uint": "I", "short": "h", "ushort": "H"}[itype]
    ccode = {"uchar": "B", "int": "i", "ushort": "H"}[ctype]
    out = ply_header(fmt, len(verts), len(faces), props, f"property list {ctype} {itype} vertex_indices").encode()
    for i, p in enumerate(verts):
        vals = list(p) + ([0.1 * i, -0.2, 0.3] if vel else [])
        out += struct.pack(endian + code * len(vals), *vals)
    for f in faces:
        out += struct.pack(endian + ccode + icode * len(f), len(f), *f)
    return out


put("ply", "tet_ascii.ply",
    ply_header("ascii", 4, 4, [("float", a) for a in ("x", "y", "z", "vx", "vy", "vz")])
    + "".join(f"{x} {y} {z} 0.1 0 -0.5\n" for x, y, z in TET_V)
    + "".join("3 " + " ".join(map(str, f)) + "\n" for f in TET_F))
put("ply", "quad_ascii_novel.ply",
    ply_header("ascii", 4, 1, [("double", "x"), ("double", "y"), ("double", "z")])
    + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
put("ply", "tet_le.ply", binary_ply("<", TET_V, TET_F))
put("ply", "tet_be_double.ply", binary_ply(">", TET_V, TET_F, vtype="double", itype="uint"))
put("ply", "tet_le_short_index.ply", binary_ply("<", TET_V, TET_F, vel=False, itype="short", ctype="ushort"))
put("ply", "velocity_names.ply",
    ply_header("ascii", 3, 1, [("float", a) for a in ("x", "y", "z", "velocity_x", "velocity_y", "velocity_z")],
               extra="")
    + "0 0 0 1 2 3\n1 0 0 1 2 3\n0 1 0 1 2 3\n3 0 1 2\n")
put("ply", "extra_elements.ply",
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "property uchar red\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n"
    "element face 1\nproperty list uchar int vertex_index\nproperty list uchar float texcoord\nend_header\n"
    "0 0 0 255\n1 0 0 0\n0 1 0 7\n0 1\n3 0 1 2 6 0 0 1 0 0 1\n")


def cut_shared_ply(path, max_faces):
    """The first faces of a shared frame (binary LE, float x y z vx vy vz) and the vertices they use."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    nv = int(header.split("element vertex ")[1].split()[0])
    nf = int(header.split("element face ")[1].split()[0])
    verts = [struct.unpack_from("<6f", data, end + 24 * i) for i in range(nv)]
    pos = end + 24 * nv
    faces = []
    for _ in range(min(nf, max_faces)):
        n = data[pos]
        faces.append(struct.unpack_from("<%di" % n, data, pos + 1))
        pos += 1 + 4 * n
    used = sorted({v for f in faces for v in f})
    remap = {v: i for i, v in enumerate(used)}
    out = ply_header("binary_little_endian", len(used), len(faces),
                     [("float", a) for a in ("x", "y", "z", "vx", "vy", "vz")]).encode()
    for v in used:
        out += struct.pack("<6f", *verts[v])
    for f in faces:
        out += struct.pack("<B3i", 3, *(remap[v] for v in f))
    return out, [verts[v][:3] for v in used], [tuple(remap[v] for v in f) for f in faces]


shared = {}
for scene, faces in (("dam_break", 120), ("viscous_drop", 60)):
    path = os.path.join(DATA, scene, f"{scene}.0001.ply")
    if os.path.exists(path):
        data, verts, tris = cut_shared_ply(path, faces)
        put("ply", f"{scene}_0001_cut.ply", data)
        shared[scene] = (verts, tris)

# ---- OBJ ------------------------------------------------------------------
put("obj", "tet.obj", "# tetrahedron\n" + "".join(f"v {x} {y} {z}\n" for x, y, z in TET_V)
    + "".join("f " + " ".join(str(i + 1) for i in f) + "\n" for f in TET_F))
put("obj", "quad_negative.obj", "o quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\ng g0\ns off\nf -4 -3 -2 -1\n")
put("obj", "uv_mesh.obj",
    "mtllib fuzz.mtl\nusemtl fuzz\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0.1 0.1\nvt 0.9 0.1\nvt 0.1 0.9\n"
    "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1/1 2/2 4/3\n")
put("obj", "forward_reference.obj", "f 1 2 3\nv 0 0 0\nv 1e-3 0 0\nv 0 1e-3 0\nl 1 2\n")
if "dam_break" in shared:
    verts, tris = shared["dam_break"]
    put("obj", "dam_break_0001_cut.obj", "".join(f"v {x:.6g} {y:.6g} {z:.6g}\n" for x, y, z in verts[:90])
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in tris if max(a, b, c) < 90))

# ---- TOML scene files -----------------------------------------------------
put("scene", "readme.toml", 'mesh = "sim/dam_break.%04d.ply"\nexemplar = "pebbles"\nradius = 0.04\n'
    'resolution = 4096\nout = "baked"\naov = true\n')
put("scene", "bake_table.toml", '# a comment\ntitle = "shot 12"\n[bake]\nmesh = "/abs/fluid.$F4.ply"\n'
    'frames = "1-24"\nvelocity_vdb = "vel.####.vdb"\nmin_speed = 0.05\nhold = false\nhold-margin = 5e-2\n'
    'small_hole = 0.25\nmerge = 0.1\nseed = 7\nthreads = 2\n[other]\nx = 1\n')
put("scene", "arrays_and_strings.toml", "exemplar = 'lava'\nfeature = \"\"\"multi\nline\"\"\"\n"
    "orientation = \"world:1,0,0\"\nfps = 2.4e1\nlist = [1, 2.5, \"three\", true]\n"
    "when = 1979-05-27T07:32:00Z\ninline = { a = 1 }\n")

# ---- bake manifests --------------------------------------------------------
manifest = {
    "lapflow_bake": 1, "name": "dam_break", "mesh": "/data/dam_break/dam_break.%04d.ply", "velocity_vdb": "",
    "velocity_grid": "", "frames": [1, 2, 3], "fps": 24.0, "min_speed": 0.0, "allow_zero_velocity": False,
    "exemplar": {"color": "/x/pebbles.color.png", "feature": "/x/pebbles.feature.png", "displacement": ""},
    "mode": "erosion", "radius": 0.047, "epsilon": 0.1, "hold": False, "hold_margin": 0.05, "small_hole": 0.0,
    "merge": 0.0, "delta_max": 3.0, "resolution": 1024, "seed": 1, "aov": True, "dump_patches": False}
put("manifest", "dam_break.bake.json", json.dumps(manifest, indent=2) + "\n")
minimal = {"lapflow_bake": 1, "name": "m", "frames": [7]}
put("manifest", "minimal.bake.json", json.dumps(minimal))
put("manifest", "blend_floats.bake.json",
    json.dumps(dict(manifest, mode="blend", frames=list(range(10, 14)), seed=18446744073709551615, fps=30,
                    resolution=512.0)))
