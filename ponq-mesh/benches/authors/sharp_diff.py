#!/usr/bin/env python3
"""Which sharp edges two meshes of the same PoNQ disagree on, and why: a diagnostic for an EF1 /
ECD difference between two outputs (ours against the authors', or two of our options).

    sharp_diff.py A.obj B.obj GT.obj [--angle DEG] [--near R]

A and B are in the [-1, 1] frame of GT (bounding-box centre 0, diagonal 2: what ponq-fit, the
meshers and `ponq-eval compare` use). An edge is sharp when its dihedral angle (between the
normals of its two faces) is above DEG (default 30, the metric's threshold). For every edge
sharp in one mesh and not in the other, one line: its dihedral in A and in B (`-` where the
other mesh has no such edge: a flip's new or old diagonal), the distance of its midpoint to
the nearest edge of GT with a dihedral above 5 degrees, and that GT edge's dihedral. The
summary counts the edges whose dihedral is within 3 degrees of DEG in both meshes and whose
GT edge (within R, default 0.01) is too: a crease whose true angle sits at the threshold,
counted or not by the metric on a rounding of the approximation, not a crease one mesh keeps
and the other loses.

Vertices are matched by position (within 1e-6). Needs Debian's python3-numpy and
python3-scipy."""
import argparse

import numpy as np
from scipy.spatial import cKDTree

from face_diff import read


def read_obj(path):
    """(vertices (n, 3), faces (m, 3), 0-based) of an OBJ triangle mesh, by face_diff.py's
    reader."""
    vertices, faces = read(path)
    if not faces:
        raise SystemExit(f'{path}: no faces')
    return np.array(vertices, dtype=float), np.array(faces, dtype=np.int64)


def dihedrals(v, f):
    """{(i, j): degrees} for every edge with exactly two faces (i < j)."""
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1)
    n = n / np.where(length > 0, length, 1)[:, None]
    faces_of = {}
    for fi, face in enumerate(f):
        for k in range(3):
            a, b = int(face[k]), int(face[(k + 1) % 3])
            faces_of.setdefault((min(a, b), max(a, b)), []).append(fi)
    out = {}
    for e, fs in faces_of.items():
        if len(fs) == 2:
            out[e] = float(np.degrees(np.arccos(np.clip(np.dot(n[fs[0]], n[fs[1]]), -1, 1))))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('a')
    ap.add_argument('b')
    ap.add_argument('gt')
    ap.add_argument('--angle', type=float, default=30.0, help='sharp-edge threshold, degrees (default 30)')
    ap.add_argument('--near', type=float, default=0.01, help='GT edges this close count (default 0.01)')
    args = ap.parse_args()
    va, fa = read_obj(args.a)
    vb, fb = read_obj(args.b)
    # B's vertices renumbered as A's where they coincide; the others after A's.
    dist, idx = cKDTree(va).query(vb)
    remap = np.where(dist < 1e-6, idx, len(va) + np.arange(len(vb)))
    da = dihedrals(va, fa)
    db = dihedrals(np.vstack([va, vb]), remap[fb])
    pos = np.vstack([va, vb])
    vg, fg = read_obj(args.gt)
    lo, hi = vg.min(0), vg.max(0)
    vg = (vg - (lo + hi) / 2) * (2 / np.linalg.norm(hi - lo))
    gt_edges = [(e, ang) for e, ang in dihedrals(vg, fg).items() if ang > 5]
    if not gt_edges:
        raise SystemExit(f'{args.gt}: no edge above 5 degrees')
    p0 = np.array([vg[e[0]] for e, _ in gt_edges])
    p1 = np.array([vg[e[1]] for e, _ in gt_edges])
    gt_ang = np.array([ang for _, ang in gt_edges])

    def nearest_gt(m):
        d = p1 - p0
        t = np.clip(np.einsum('ij,ij->i', m - p0, d) / np.maximum(np.einsum('ij,ij->i', d, d), 1e-300), 0, 1)
        dd = np.linalg.norm(p0 + t[:, None] * d - m, axis=1)
        k = int(np.argmin(dd))
        return dd[k], gt_ang[k]

    th = args.angle
    sharp_a = {e for e, ang in da.items() if ang > th}
    sharp_b = {e for e, ang in db.items() if ang > th}
    at_threshold = 0
    for name, only in (('only in A', sorted(sharp_a - sharp_b)), ('only in B', sorted(sharp_b - sharp_a))):
        print(f'{name}: {len(only)} sharp edges')
        for e in only:
            a, b = da.get(e), db.get(e)
            d, g = nearest_gt((pos[e[0]] + pos[e[1]]) / 2)
            fmt = lambda x: '-' if x is None else f'{x:.1f}'
            print(f'  {np.round(pos[e[0]], 4).tolist()} {np.round(pos[e[1]], 4).tolist()}: '
                  f'A {fmt(a)}, B {fmt(b)}, GT edge {d:.4f} away at {g:.1f} degrees')
            if a is not None and b is not None and abs(a - th) < 3 and abs(b - th) < 3 and d < args.near and abs(g - th) < 3:
                at_threshold += 1
    print(f'sharp edges above {th:g} degrees: A {len(sharp_a)}, B {len(sharp_b)}; of the '
          f'{len(sharp_a ^ sharp_b)} in one only, {at_threshold} are creases at the threshold '
          f'(within 3 degrees of it in A, in B and in GT)')


if __name__ == '__main__':
    main()
