#!/usr/bin/env python3
"""Compares the faces of two OBJ triangle meshes whose vertices are the same points (numbered
differently): face_diff.py A.obj B.obj -> one line, `A_faces B_faces unmatched_vertices
only_in_A only_in_B`. Vertices are matched by position (within 1e-6 per coordinate, through a
grid of 1e-4 cells); a face is the cyclic order of its three matched vertices, so the same
triangle with the opposite orientation counts as different. Exit 0 when the face sets are
equal, 1 when not."""
import itertools, sys

def read(path):
    vertices, faces = [], []
    with open(path) as f:
        for line in f:
            if line.startswith('v '):
                vertices.append(tuple(float(x) for x in line.split()[1:4]))
            elif line.startswith('f '):
                faces.append(tuple(int(x.split('/')[0]) - 1 for x in line.split()[1:4]))
    return vertices, faces

def cyclic(face):
    i = face.index(min(face))
    return face[i:] + face[:i]

def main():
    va, fa = read(sys.argv[1])
    vb, fb = read(sys.argv[2])
    cell = lambda p: tuple(round(x * 1e4) for x in p)
    grid = {}
    for j, p in enumerate(vb):
        grid.setdefault(cell(p), []).append(j)
    match, unmatched = [], 0
    for p in va:
        c, best = cell(p), None
        for d in itertools.product((-1, 0, 1), repeat=3):
            for j in grid.get(tuple(c[k] + d[k] for k in range(3)), []):
                e = max(abs(p[k] - vb[j][k]) for k in range(3))
                if e < 1e-6 and (best is None or e < best[0]):
                    best = (e, j)
        if best is None:
            unmatched += 1
            match.append(-1 - len(match))  # a number no vertex of B has
        else:
            match.append(best[1])
    a = {cyclic(tuple(match[i] for i in f)) for f in fa}
    b = {cyclic(f) for f in fb}
    print(len(fa), len(fb), unmatched, len(a - b), len(b - a))
    sys.exit(0 if a == b and len(fa) == len(fb) else 1)


if __name__ == '__main__':
    main()
