#!/usr/bin/env python3
"""Runs the authors' PoNQ mesher (`MeshFromPoNQ` of their repository's src/utils/PoNQ_to_mesh.py,
imported from a checkout of it, unmodified) on a PoNQ .npz (points, normals, quadrics, as
`ponq-fit --save-ponq` writes) and writes an OBJ; a side-by-side reference, not part of PoNQ-rs.

    AUTHORS_PONQ=/path/to/PoNQ/src/utils python3 authors_mesh.py IN.npz RES OUT.obj

prints `V .. F .. seconds ..` (meshing only). Needs Debian's python3-torch, python3-scipy,
python3-networkx. v* are the SVD pseudo-inverse with the 0.05 relative cut-off (the paper's
and their default), grid_scale = RES."""
import sys, types, time
import numpy as np, torch
# mesh_tools imports packages the mesher does not use; stand-ins so that it imports.
class Stand(types.ModuleType):
    def __getattr__(self, name):
        return object
for m in ['trimesh', 'igl', 'sklearn', 'sklearn.neighbors', 'skimage', 'skimage.measure']:
    sys.modules.setdefault(m, Stand(m))
import os
sys.path.insert(0, os.environ.get('AUTHORS_PONQ', 'PoNQ/src/utils'))
from PoNQ_to_mesh import MeshFromPoNQ

def vstars_from_quadrics(Q, P, eps=0.05):
    # v* = P + pinv_eps(A) (b - A P): SVD pseudo-inverse, singular values below eps * largest dropped
    A = Q[:, :3, :3]; b = -Q[:, 3, :3]
    u, eigs, vh = torch.linalg.svd(A)
    e2 = torch.zeros_like(eigs); mask = eigs / eigs[:, 0, None] > eps; e2[mask] = 1 / eigs[mask]
    v = P + (vh.transpose(1, 2) @ torch.diag_embed(e2) @ u.transpose(1, 2) @ (b[..., None] - A @ P[..., None])).squeeze(-1)
    return v, eigs

d = np.load(sys.argv[1]); res = int(sys.argv[2])
P = torch.tensor(d['points'], dtype=torch.float64); N = torch.tensor(d['normals'], dtype=torch.float64)
Q = torch.tensor(d['quadrics'], dtype=torch.float64)
t = time.perf_counter()
v, eigs = vstars_from_quadrics(Q, P)
SC = MeshFromPoNQ(v, eigs, Q, N, grid_scale=res)
V, F = SC.get_surface()[:2]
dt = time.perf_counter() - t
with open(sys.argv[3], 'w') as f:
    for p in V: f.write(f"v {p[0]:.10g} {p[1]:.10g} {p[2]:.10g}\n")
    for tri in F: f.write(f"f {tri[0]+1} {tri[1]+1} {tri[2]+1}\n")
print(f"V {len(V)} F {len(F)} seconds {dt:.3f}")
