#!/usr/bin/env python3
"""Where one ray of a benchmark's ray file meets a mesh, in exact rational arithmetic.

    python3 bench/exact_hit.py MESH.ply RAYS.f32 INDEX

For settling a difference between Snell's hit counts and Embree's (`bench/vs_embree.sh`
flags one): MESH is the mesh both programs read (`WORK/NAME.ply` or `.bin`, which
`mesh_tools.py` writes; it reads them here too, from SNELL_SCENES/../bench, by default
../shared/bench beside the checkout), RAYS a dumped ray file (six float32 per ray: origin,
direction), INDEX the ray in question. The
float32 inputs are taken as exact rationals; every triangle that the ray could touch (a
float64 pre-filter with a generous tolerance) is tested exactly: the three edge
functions d . ((a - o) x (b - o)), and the distance to the triangle's plane. A triangle is
crossed where the three signs agree or are zero. Prints each candidate and the nearest
crossing with t > 0 (or that there is none). Needs numpy.
"""
import os
import sys
from fractions import Fraction

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.environ.get("SNELL_SCENES", os.path.join(HERE, "..", "..", "shared", "scenes"))
sys.path.insert(0, os.path.join(SCENES, "..", "bench"))
try:
    import mesh_tools
except ImportError:
    sys.exit(f"mesh_tools.py not found in {os.path.join(SCENES, '..', 'bench')} (set SNELL_SCENES)")


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__.split("\n\n")[1])
    v, idx = mesh_tools.read_any(sys.argv[1])
    rays = np.fromfile(sys.argv[2], dtype="<f4").reshape(-1, 6)
    i = int(sys.argv[3])
    if not 0 <= i < len(rays):
        sys.exit(f"{sys.argv[2]}: {len(rays)} rays, no ray {i}")
    ray = rays[i]
    print(f"ray {i}: origin {ray[:3].tolist()} direction {ray[3:].tolist()}")
    # Float64 pre-filter: edge functions of every triangle, kept where all three agree in
    # sign up to a tolerance far above float64's rounding here.
    o, d = ray[:3].astype(np.float64), ray[3:].astype(np.float64)
    p = v.astype(np.float64)[idx] - o
    e = np.stack([np.einsum("j,ij->i", d, np.cross(p[:, k], p[:, (k + 1) % 3])) for k in range(3)], axis=1)
    tol = 1e-9 * np.abs(e).max(axis=1, initial=0.0).max(initial=1.0)
    cand = np.nonzero(np.all(e >= -tol, axis=1) | np.all(e <= tol, axis=1))[0]
    of = [Fraction(float(x)) for x in ray[:3]]
    df = [Fraction(float(x)) for x in ray[3:]]

    def sub(a, b):
        return [a[k] - b[k] for k in range(3)]

    def cross(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    def dot(a, b):
        return sum(a[k] * b[k] for k in range(3))

    best = None
    for t in cand:
        q = [[Fraction(float(x)) for x in v[k]] for k in idx[t]]
        edges = [dot(df, cross(sub(q[k], of), sub(q[(k + 1) % 3], of))) for k in range(3)]
        signs = [(x > 0) - (x < 0) for x in edges]
        n = cross(sub(q[1], q[0]), sub(q[2], q[0]))
        den = dot(n, df)
        crossed = den != 0 and (all(s >= 0 for s in signs) or all(s <= 0 for s in signs))
        dist = dot(n, sub(q[0], of)) / den if den != 0 else None
        mark = ""
        if crossed and dist > 0:
            mark = "crossed"
            if best is None or dist < best[1]:
                best = (t, dist)
        print(f"  triangle {t} {idx[t].tolist()}: edge functions {' '.join(f'{float(x):+.3g}' for x in edges)}, t {float(dist) if dist is not None else '-'} {mark}")
    if best is None:
        print("no triangle crossed: a miss")
    else:
        print(f"nearest crossing: triangle {best[0]} at t = {float(best[1])!r}")


if __name__ == "__main__":
    main()
