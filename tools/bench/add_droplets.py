#!/usr/bin/env python3
"""Writes a mesh frame plus N icosphere droplets as an ASCII PLY: a stand-in
for frames with over a thousand atlas charts (a spray of droplets), which the
shared scenes do not have (docs/atlas.md, "Numbers").

    python3 tools/bench/add_droplets.py ../shared/data/splash/splash.0030.ply 150 out.ply

Droplets: radius 4-20 mm, subdivided once (two of three) or twice, centred
in x in [-0.8, 0.8], y in [-0.6, 0.6], z in [0.3, 1.0] m, from a fixed seed.
Reads binary little-endian PLY with float x y z first in the vertex and a
uchar/int face list (the shared scenes' layout); writes positions only.
"""
import math
import random
import struct
import sys


def read_ply(path):
    data = open(path, 'rb').read()
    end = data.index(b'end_header\n') + len(b'end_header\n')
    header = data[:end].decode().splitlines()
    if 'format binary_little_endian 1.0' not in header:
        sys.exit(f'{path}: only binary little-endian PLY')
    counts, props, element = {}, {}, None
    for line in header:
        words = line.split()
        if words[:1] == ['element']:
            element = words[1]
            counts[element] = int(words[2])
            props[element] = []
        elif words[:1] == ['property'] and element:
            props[element].append(words[1:])
    vertex_size = sum({'float': 4, 'double': 8, 'uchar': 1, 'int': 4}[p[0]] for p in props['vertex'])
    vertices, offset = [], end
    for _ in range(counts['vertex']):
        vertices.append(struct.unpack_from('<3f', data, offset))
        offset += vertex_size
    faces = []
    for _ in range(counts['face']):
        k = data[offset]
        faces.append(struct.unpack_from(f'<{k}i', data, offset + 1))
        offset += 1 + 4 * k
    return vertices, faces


def icosphere(subdivisions):
    t = (1 + 5 ** 0.5) / 2
    vs = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
          (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    vs = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in vs]
    fs = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
          (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
          (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        middle, finer = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in middle:
                m = [(vs[a][i] + vs[b][i]) / 2 for i in range(3)]
                length = math.sqrt(sum(x * x for x in m))
                vs.append(tuple(x / length for x in m))
                middle[key] = len(vs) - 1
            return middle[key]

        for a, b, c in fs:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            finer += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        fs = finer
    return vs, fs


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    vertices, faces = read_ply(sys.argv[1])
    rng = random.Random(1)
    for i in range(int(sys.argv[2])):
        vs, fs = icosphere(1 if i % 3 else 2)
        r = 0.004 + 0.016 * rng.random()
        c = (rng.uniform(-0.8, 0.8), rng.uniform(-0.6, 0.6), rng.uniform(0.3, 1.0))
        base = len(vertices)
        vertices += [tuple(c[k] + r * v[k] for k in range(3)) for v in vs]
        faces += [tuple(base + x for x in f) for f in fs]
    with open(sys.argv[3], 'w') as out:
        out.write('ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n'
                  'element face %d\nproperty list uchar int vertex_indices\nend_header\n' % (len(vertices), len(faces)))
        for v in vertices:
            out.write('%.7g %.7g %.7g\n' % v)
        for f in faces:
            out.write('%d %s\n' % (len(f), ' '.join(map(str, f))))


if __name__ == '__main__':
    main()
