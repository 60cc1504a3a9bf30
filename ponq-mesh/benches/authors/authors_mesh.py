#!/usr/bin/env python3
"""Runs the authors' PoNQ mesher (`MeshFromPoNQ` of their repository's src/utils/PoNQ_to_mesh.py,
imported from a checkout of it, unmodified) on a PoNQ .npz (points, normals, quadrics, as
`ponq-fit --save-ponq` writes) and writes an OBJ; a side-by-side reference, not part of PoNQ-rs.

    AUTHORS_PONQ=/path/to/PoNQ/src/utils python3 authors_mesh.py IN.npz RES OUT.obj

prints `V .. F .. seconds ..` (meshing only). With AUTHORS_FLOW=bk their `min_cut` gets
networkx's Boykov-Kolmogorov flow, on capacities clipped at 0, instead of its default
preflow-push, whose partition is not always a minimum cut (docs/meshing.md). With
AUTHORS_CLAMP=1 the `arccos` of their module gets its argument clipped to [-1, 1] (their face
scores take the arccos of dot products of unit vectors, which rounding puts just above 1 at
times: NaN capacities). Nothing else of theirs changes. Needs Debian's python3-torch, python3-scipy,
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
if os.environ.get('AUTHORS_FLOW') == 'bk':
    import networkx as nx
    from collections import deque
    def _bk_minimum_cut(G, s, t, **kw):
        # Boykov-Kolmogorov needs capacities >= 0; rounding leaves a few of theirs at about
        # -1e-13 (unclamped quadric terms; ours clamps each term at 0).
        for _, _, data in G.edges(data=True):
            data['capacity'] = max(data['capacity'], 0.0)
        R = nx.algorithms.flow.boykov_kolmogorov(G, s, t)
        # The partition as nx.minimum_cut makes it (the sink side: the nodes that still reach
        # t in the residual network), but with a tolerance: networkx drops only arcs whose
        # flow equals their capacity exactly, and on floats a saturated arc may miss by one
        # rounding, leaving the source on the sink side.
        pred = {}
        for u, v, d in R.edges(data=True):
            if d['capacity'] - d['flow'] > 1e-9 * max(1.0, abs(d['capacity'])):
                pred.setdefault(v, []).append(u)
        sink_side, todo = {t}, deque([t])
        while todo:
            for u in pred.get(todo.popleft(), []):
                if u not in sink_side:
                    sink_side.add(u)
                    todo.append(u)
        return R.graph['flow_value'], (set(G) - sink_side, sink_side)
    nx.minimum_cut = _bk_minimum_cut
import PoNQ_to_mesh
from PoNQ_to_mesh import MeshFromPoNQ
if os.environ.get('AUTHORS_CLAMP') == '1':
    # Their methods read `np` from their module's globals when called.
    clamped = types.ModuleType('numpy_with_clamped_arccos')
    clamped.__dict__.update(np.__dict__)
    clamped.arccos = lambda x, *a, **k: np.arccos(np.clip(x, -1.0, 1.0), *a, **k)
    PoNQ_to_mesh.np = clamped

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
