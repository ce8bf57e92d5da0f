#!/usr/bin/env python3
"""The cost model of docs/performance.md (issue 15): least-squares fits of
each bake step's seconds per frame against what it should scale with, over
every frame but the first of the NAME.stats.jsonl files given (several
scenes and resolutions together). Standard library only.

    python3 tools/bench/cost_model.py A/NAME.stats.jsonl B/NAME.stats.jsonl ...
"""
import json
import statistics
import sys

UNITS = {'tri': (1e5, '100k triangles'), 'patches': (1e3, '1k patches'), 'texels': (1e7, '10M output texels'),
         'ttexels': (1e6, '1M tracking texels')}


def solve(a, b):
    """Gaussian elimination with partial pivoting for a small dense system."""
    n = len(b)
    m = [row[:] + [b[i]] for i, row in enumerate(a)]
    for c in range(n):
        p = max(range(c, n), key=lambda r: abs(m[r][c]))
        m[c], m[p] = m[p], m[c]
        for r in range(n):
            if r != c and m[c][c] != 0:
                f = m[r][c] / m[c][c]
                m[r] = [x - f * y for x, y in zip(m[r], m[c])]
    return [m[i][n] / m[i][i] if m[i][i] else 0.0 for i in range(n)]


def fit(rows, name, key, cols):
    xs = [[r[c] for c in cols] for r in rows]
    ys = [r['s'].get(key, 0.0) for r in rows]
    ata = [[sum(x[i] * x[j] for x in xs) for j in range(len(cols))] for i in range(len(cols))]
    aty = [sum(x[i] * y for x, y in zip(xs, ys)) for i in range(len(cols))]
    coef = solve(ata, aty)
    pred = [sum(c * v for c, v in zip(coef, x)) for x in xs]
    err = [abs(p - y) for p, y in zip(pred, ys)]
    mean = statistics.fmean(ys)
    total = sum((y - mean) ** 2 for y in ys)
    r2 = 1 - sum((p - y) ** 2 for p, y in zip(pred, ys)) / total if total > 0 else 1.0
    terms = ' + '.join(f'{c * UNITS[k][0]:.3f} s per {UNITS[k][1]}' for c, k in zip(coef, cols))
    print(f'| {name} | {terms} | {r2:.2f} | {statistics.median(err):.2f} / {max(err):.2f} s | {mean:.2f} s |')


def main(paths):
    rows = []
    for path in paths:
        lines = [json.loads(line) for line in open(path)]
        for d in lines[1:]:  # the first frame seeds and waits for its atlas
            rows.append({'tri': d['triangles'], 'patches': d['patches']['alive'], 'texels': d['chart_texels'],
                         'ttexels': d['tracking']['chart_texels'], 's': d['seconds']})
    print(f'{len(rows)} frames from {len(paths)} files')
    print('| step | fit | R² | median / worst error | mean |')
    print('|---|---|---|---|---|')
    fit(rows, 'advection', 'advect', ['patches', 'tri'])
    fit(rows, 'weights', 'weights', ['patches'])
    fit(rows, 'both atlases (ahead)', 'atlas', ['tri', 'texels', 'ttexels'])
    fit(rows, 'tracking raster', 'track', ['ttexels', 'patches'])
    fit(rows, 'output draw', 'draw', ['texels', 'patches'])
    fit(rows, 'output holes', 'holes', ['texels'])
    fit(rows, 'output resolve', 'resolve', ['texels'])
    fit(rows, 'dilate', 'dilate', ['texels'])
    fit(rows, 'write (behind)', 'write', ['texels', 'tri'])


if __name__ == '__main__':
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
