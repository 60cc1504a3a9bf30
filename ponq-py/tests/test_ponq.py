"""Tests of the `ponq` Python module against the PoNQ-rs programs and brute force.

Run from the repository root or from ponq-py/ after installing the package:

    python3 -m venv /tmp/ponqvenv
    CARGO_TARGET_DIR=$PWD/target /tmp/ponqvenv/bin/pip install ./ponq-py pytest
    /tmp/ponqvenv/bin/python -m pytest ponq-py/tests

The comparisons with the programs need their release builds (`cargo build --release --bins`);
they are skipped, with a message, when the binaries are missing.
"""

import json
import os
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

import ponq

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
BIN = Path(os.environ.get("PONQ_BIN_DIR", ROOT / "target" / "release"))


def binary(name):
    p = BIN / name
    if not p.is_file():
        pytest.skip(f"{p} is missing: build the programs first (cargo build --release --bins)")
    return p


def run(args, code=0):
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True)
    assert r.returncode == code, f"{args} exited {r.returncode}, expected {code}: {r.stderr}"
    return r.stdout


def read_obj(path):
    """Vertices and triangles of an OBJ file (`v x y z` and `f a b c` lines, 1-based)."""
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            t = line.split()
            if not t:
                continue
            if t[0] == "v":
                v.append([float(x) for x in t[1:4]])
            elif t[0] == "f":
                idx = [int(x.split("/")[0]) - 1 for x in t[1:]]
                for k in range(1, len(idx) - 1):
                    f.append([idx[0], idx[k], idx[k + 1]])
    return np.array(v, dtype=np.float64).reshape(-1, 3), np.array(f, dtype=np.int64).reshape(-1, 3)


def write_obj(path, v, f):
    """An OBJ that reads back exactly (`repr` of a float is its shortest round trip)."""
    with open(path, "w") as fh:
        for p in v:
            fh.write(f"v {float(p[0])!r} {float(p[1])!r} {float(p[2])!r}\n")
        for t in f:
            fh.write(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")


def assert_valid(v, f):
    r = ponq.check(v, f)
    assert r["valid"], r["summary"]
    assert len(f) > 0


def box_sdf(n=17, half=0.6):
    g = np.linspace(-1.0, 1.0, n)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    return np.maximum(np.abs(x), np.maximum(np.abs(y), np.abs(z))) - half


# ------------------------------------------------------------------------------------------
# infer


@pytest.fixture(scope="module")
def cli_infer(tmp_path_factory):
    """`ponq-infer` on each shipped grid: its mesh and its saved PoNQ."""
    exe = binary("ponq-infer")
    out = {}
    d = tmp_path_factory.mktemp("infer")
    for name in ["csg_sdf_33", "example001_sdf_65"]:
        obj, npz = d / f"{name}.obj", d / f"{name}.npz"
        run([exe, EXAMPLES / f"{name}.npy", "-o", obj, "--save-ponq", npz, "-q"])
        out[name] = (read_obj(obj), dict(np.load(npz)))
    return out


@pytest.mark.parametrize("name", ["csg_sdf_33", "example001_sdf_65"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("order", ["C", "F"])
def test_infer_equals_the_program(cli_infer, name, dtype, order):
    (cv, cf), _ = cli_infer[name]
    g = np.load(EXAMPLES / f"{name}.npy")
    g = np.asarray(g, dtype=dtype, order=order)
    assert g.flags.f_contiguous == (order == "F")
    v, f = ponq.infer(g)
    assert v.dtype == np.float64 and f.dtype == np.int64
    assert v.shape == cv.shape and f.shape == cf.shape
    np.testing.assert_array_equal(v, cv)
    np.testing.assert_array_equal(f, cf)
    assert_valid(v, f)


def test_infer_returns_the_saved_ponq(cli_infer):
    _, saved = cli_infer["csg_sdf_33"]
    g = np.load(EXAMPLES / "csg_sdf_33.npy")
    v, f, p = ponq.infer(g, return_ponq=True)
    m = len(saved["points"])
    assert p["points"].shape == (m, 3) and p["normals"].shape == (m, 3)
    assert p["quadrics"].shape == (m, 4, 4) and p["vstars"].shape == (m, 3)
    for k in ["points", "normals", "quadrics", "vstars"]:
        if k in saved:
            np.testing.assert_array_equal(p[k], saved[k], err_msg=k)


def test_infer_options_and_threads():
    g = np.load(EXAMPLES / "csg_sdf_33.npy")
    v, f = ponq.infer(g)
    v1, f1 = ponq.infer(g, threads=1)
    np.testing.assert_array_equal(v, v1)
    np.testing.assert_array_equal(f, f1)
    vl, fl = ponq.infer(g, lite=True)
    assert_valid(vl, fl)
    assert len(vl) < len(v)
    vo, fo = ponq.infer(g, refine="off", merge_smooth=None)
    assert_valid(vo, fo)


def test_infer_from_threads():
    """Calls release the GIL: two threads at once give the single call's mesh."""
    from concurrent.futures import ThreadPoolExecutor

    g = np.load(EXAMPLES / "csg_sdf_33.npy")
    v, f = ponq.infer(g)
    with ThreadPoolExecutor(2) as ex:
        outs = list(ex.map(lambda t: ponq.infer(g, threads=t), [1, 2]))
    for ov, of in outs:
        np.testing.assert_array_equal(ov, v)
        np.testing.assert_array_equal(of, f)


def test_infer_bounds_scale_the_output():
    g = np.load(EXAMPLES / "csg_sdf_33.npy").astype(np.float64)
    v, f = ponq.infer(g, refine="off")
    # The same shape twice as large and moved: distances scale with the box.
    vb, fb = ponq.infer(2.0 * g, bounds=[1, 1, 1, 5, 5, 5], refine="off")
    np.testing.assert_array_equal(f, fb)
    np.testing.assert_allclose(vb, 2.0 * v + 3.0, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------------
# mesh


def test_mesh_equals_the_program(tmp_path):
    exe = binary("ponq-mesh")
    npz = EXAMPLES / "csg_ponq_32.npz"
    d = np.load(npz)
    for extra, kw in [([], {}), (["--lite"], {"lite": True}), (["--merge-smooth", "15"], {"merge_smooth": 15.0})]:
        obj = tmp_path / "m.obj"
        run([exe, npz, "-o", obj, "--grid-scale", "32", "-q", *extra])
        cv, cf = read_obj(obj)
        v, f = ponq.mesh(d["points"], d["normals"], d["quadrics"], grid_scale=32, **kw)
        np.testing.assert_array_equal(v, cv)
        np.testing.assert_array_equal(f, cf)
        assert_valid(v, f)


def test_mesh_takes_float32_and_fortran():
    d = np.load(EXAMPLES / "csg_ponq_32.npz")
    args = [np.asfortranarray(d[k].astype(np.float32)) for k in ["points", "normals", "quadrics"]]
    v, f = ponq.mesh(*args, grid_scale=32)
    ref = ponq.mesh(*[a.astype(np.float64) for a in args], grid_scale=32)
    np.testing.assert_array_equal(v, ref[0])
    np.testing.assert_array_equal(f, ref[1])


# ------------------------------------------------------------------------------------------
# sdf, sample


def point_triangle_distance(p, a, b, c):
    """Distances from points p (N, 3) to the triangle abc: the plane inside it, else the
    nearest of its three edges."""
    n = np.cross(b - a, c - a)
    n = n / np.linalg.norm(n)
    q = p - np.outer((p - a) @ n, n)  # projections onto the plane
    inside = np.ones(len(p), bool)
    for u, w in [(a, b), (b, c), (c, a)]:
        inside &= np.cross(w - u, q - u) @ n >= 0
    d_plane = np.abs((p - a) @ n)

    def seg(u, w):
        t = np.clip(((p - u) @ (w - u)) / ((w - u) @ (w - u)), 0, 1)
        return np.linalg.norm(p - (u + np.outer(t, w - u)), axis=1)

    d_edge = np.minimum(seg(a, b), np.minimum(seg(b, c), seg(c, a)))
    return np.where(inside, d_plane, d_edge)


def cube_mesh(h=0.55):
    v = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], dtype=np.float64)
    # Outward-oriented quads split in two.
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    f = []
    for a, b, c, d in quads:
        f += [[a, b, c], [a, c, d]]
    return v, np.array(f, dtype=np.int64)


def test_sdf_against_brute_force():
    v, f = cube_mesh(0.55)
    assert ponq.check(v, f)["valid"]
    res = 8
    g = ponq.sdf(v, f, res, normalize=False)
    assert g.dtype == np.float32 and g.shape == (res + 1,) * 3
    c = -1 + 2 * np.arange(res + 1) / res
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    d = np.min([point_triangle_distance(pts, *v[t]) for t in f], axis=0)
    inside = np.all(np.abs(pts) < 0.55, axis=1)
    expected = np.where(inside, -d, d).reshape(g.shape)
    np.testing.assert_allclose(g, expected, rtol=1e-6, atol=1e-7)
    assert (g < 0).sum() == inside.sum()
    # Normalised: centre 0 (already), scale 2 / diagonal.
    g2, centre, scale = ponq.sdf(v, f, res, return_transform=True)
    np.testing.assert_allclose(centre, 0, atol=0)
    assert scale == pytest.approx(2 / np.linalg.norm([1.1, 1.1, 1.1]))
    assert g2.min() < 0 < g2.max()


def test_sdf_repairs_broken_meshes_and_reports():
    v, f = cube_mesh(0.55)
    clean = ponq.sdf(v, f, 8)
    # A soup with cracks, a flipped face, a duplicate the other way round and a missing face.
    rng = np.random.default_rng(3)
    sv = v[f.ravel()] + rng.uniform(-1e-7, 1e-7, size=(3 * len(f), 3))
    sf = np.arange(3 * len(f)).reshape(-1, 3)
    sf[2] = sf[2][::-1]
    sf = np.vstack([sf[1:], sf[5][::-1]])
    g, report = ponq.sdf(sv, sf, 8, return_report=True)
    assert report["repaired"] and report["welded_vertices"] > 0
    assert report["holes_filled"] == 1 and report["duplicate_faces"] == 1
    assert set(report) >= {"boundary_edges", "self_intersecting_pairs", "ambiguous_node_share"}
    # The sign is the clean cube's everywhere; the distances within the cracks' size.
    np.testing.assert_array_equal(g < 0, clean < 0)
    np.testing.assert_allclose(g, clean, atol=1e-5)
    # Without the repair the mesh is taken as it is (open: a warning).
    with pytest.warns(UserWarning):
        ponq.sdf(sv, sf, 8, repair=False)
    with pytest.raises(ValueError, match="return_report"):
        ponq.sdf(sv, sf, 8, repair=False, return_report=True)
    # Nothing to reconstruct.
    with pytest.raises(ValueError, match="no volume"):
        ponq.sdf(v[:3], [[0, 1, 2]], 8)


def test_sdf_equals_ponq_prep(tmp_path):
    exe = binary("ponq-prep")
    out = tmp_path / "csg.npy"
    run([exe, "sdf", EXAMPLES / "csg.obj", "-o", out, "--res", "32", "-q"])
    v, f = read_obj(EXAMPLES / "csg.obj")
    g = ponq.sdf(v, f, 32)
    ref = np.load(out)
    assert g.dtype == ref.dtype == np.float32
    np.testing.assert_array_equal(g, ref)
    # And the shipped grid was made the same way.
    np.testing.assert_array_equal(g, np.load(EXAMPLES / "csg_sdf_33.npy"))


def test_sdf_then_infer_maps_back():
    v, f = read_obj(EXAMPLES / "csg.obj")
    g, centre, scale = ponq.sdf(v, f.astype(np.int32), 32, return_transform=True)
    mv, mf = ponq.infer(g)
    mv = mv / scale + centre
    lo, hi = v.min(0), v.max(0)
    assert np.all(mv.min(0) > lo - 0.05 * (hi - lo)) and np.all(mv.max(0) < hi + 0.05 * (hi - lo))


def test_sample():
    v, f = cube_mesh(0.5)
    p, n = ponq.sample(v, f, 1000, seed=3)
    assert p.shape == n.shape == (1000, 3)
    np.testing.assert_allclose(np.abs(p).max(axis=1), 0.5, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-12)
    p2, _ = ponq.sample(v, f, 1000, seed=3)
    np.testing.assert_array_equal(p, p2)


# ------------------------------------------------------------------------------------------
# fit, metrics, check, marching cubes


def test_fit_is_valid_and_in_the_input_frame():
    v, f = read_obj(EXAMPLES / "csg.obj")
    mv, mf, p = ponq.fit(v, f, grid=16, iterations=60, samples=20000, return_ponq=True)
    assert_valid(mv, mf)
    lo, hi = v.min(0), v.max(0)
    assert np.all(mv.min(0) > lo - 0.1 * (hi - lo)) and np.all(mv.max(0) < hi + 0.1 * (hi - lo))
    nv, nf = ponq.fit(v, f, grid=16, iterations=60, samples=20000, normalized=True)
    np.testing.assert_array_equal(nf, mf)
    assert np.abs(nv).max() <= 1.1
    # The returned PoNQ meshes again to the normalised mesh.
    rv, rf = ponq.mesh(p["points"], p["normals"], p["quadrics"], vstars=p["vstars"], grid_scale=16)
    assert_valid(rv, rf)


def test_metrics_equal_the_program(tmp_path):
    exe = binary("ponq-eval")
    gv, gf = read_obj(EXAMPLES / "csg.obj")
    mv, mf = ponq.marching_cubes(np.load(EXAMPLES / "csg_sdf_33.npy"))
    # Into the ground truth's coordinates (the grid frame: bounding-box centre 0, diagonal 2).
    lo, hi = gv.min(0), gv.max(0)
    mv = mv * (np.linalg.norm(hi - lo) / 2) + (lo + hi) / 2
    pred = tmp_path / "mc.obj"
    write_obj(pred, mv, mf)
    out = run([exe, "compare", pred, EXAMPLES / "csg.obj", "--pred-frame", "gt", "--json",
               "--samples", "20000", "--seed", "1"])
    ref = json.loads(out)
    m = ponq.metrics(mv, mf, gv, gf, samples=20000, seed=1)
    for k in ["cd_x1e5", "f1", "nc", "ecd_x1e2", "ef1", "watertight", "vertices", "faces"]:
        assert m[k] == ref[k], k
    # Marching cubes at 33^3 is coarse: a low F1 at 0.003, a small Chamfer distance.
    assert 0.2 < m["f1"] < 1 and m["cd_x1e5"] < 100 and m["watertight"]


def test_marching_cubes_and_check():
    v, f = ponq.marching_cubes(box_sdf())
    r = ponq.check(v, f)
    assert r["valid"] and r["closed"] and not r["self_intersecting"]
    r = ponq.check(v, f[:-1])
    assert not r["valid"] and not r["closed"] and r["boundary_edges"] == 3
    assert ponq.check(np.zeros((0, 3)), [])["valid"]


# ------------------------------------------------------------------------------------------
# bad input


def test_bad_grids():
    g = box_sdf()
    nan = g.copy()
    nan[3, 4, 5] = np.nan
    with pytest.raises(ValueError, match=r"grid value at \[3, 4, 5\] is NaN"):
        ponq.infer(nan)
    with pytest.raises(ValueError, match=r"expected a 3D grid \(rank 3\), found an array of shape \(17, 17\)"):
        ponq.infer(g[0])
    with pytest.raises(ValueError, match="at least 2 nodes along every axis"):
        ponq.infer(np.full((1, 5, 5), -1.0))
    with pytest.raises(ValueError, match="no sign change"):
        ponq.infer(np.abs(g) + 0.1)
    with pytest.raises(ValueError, match="cells are not cubes"):
        ponq.infer(g, bounds=[0, 0, 0, 1, 1, 2])
    with pytest.raises(ValueError, match="bounds: .*6 comma-separated numbers"):
        ponq.infer(g, bounds=[0, 0, 0, 1])
    with pytest.raises(ValueError, match="invalid value 'bogus' for refine"):
        ponq.infer(g, refine="bogus")
    with pytest.raises(ValueError, match="merge_smooth takes an angle"):
        ponq.infer(g, merge_smooth=200)
    with pytest.raises(ValueError, match="open-surface threshold must be in"):
        ponq.infer(g, open=2.0)
    with pytest.raises(ValueError, match="not with lite or coarsen"):
        ponq.infer(g, lite=True, refine="on")
    with pytest.raises(ValueError, match="threads must be at least 1"):
        ponq.infer(g, threads=0)
    with pytest.raises(ValueError, match="expected an array of real numbers"):
        ponq.infer(g.astype(np.complex128))
    with pytest.raises(ValueError, match="weights file"):
        ponq.infer(g, model="/nonexistent/model.bpk")
    with pytest.raises(ValueError, match="grid value at"):
        ponq.marching_cubes(nan)


def test_bad_meshes():
    v, f = cube_mesh()
    bad = f.copy()
    bad[4, 1] = 8
    msg = "face 4 refers to vertex 8 but there are only 8 vertices"
    for fn in [lambda: ponq.sdf(v, bad, 8), lambda: ponq.check(v, bad), lambda: ponq.sample(v, bad, 10),
               lambda: ponq.fit(v, bad), lambda: ponq.metrics(v, bad, v, f)]:
        with pytest.raises(ValueError, match=msg):
            fn()
    neg = f.copy()
    neg[0, 0] = -1
    with pytest.raises(ValueError, match="refers to vertex -1"):
        ponq.check(v, neg)
    with pytest.raises(ValueError, match="expected an array of integers"):
        ponq.check(v, f.astype(np.float64))
    with pytest.raises(ValueError, match=r"array 'vertices': expected shape \(V, 3\), found \(8, 2\)"):
        ponq.check(v[:, :2], f)
    vn = v.copy()
    vn[2, 1] = np.inf
    with pytest.raises(ValueError, match="vertex 2 = .* has a non-finite coordinate"):
        ponq.sdf(vn, f, 8)
    with pytest.raises(ValueError, match="res must be in 2..=1024"):
        ponq.sdf(v, f, 1)
    with pytest.raises(ValueError, match="the ground truth has no face"):
        ponq.metrics(v, f, v, np.zeros((0, 3), np.int64))
    with pytest.raises(ValueError, match="samples must be positive"):
        ponq.metrics(v, f, v, f, samples=0)
    with pytest.raises(ValueError, match="grid must be between 2 and 1024"):
        ponq.fit(v, f, grid=1)


def test_bad_ponq():
    d = np.load(EXAMPLES / "csg_ponq_32.npz")
    p, n, q = d["points"], d["normals"], d["quadrics"]
    with pytest.raises(ValueError, match=r"array 'normals': expected shape \(M, 3\)"):
        ponq.mesh(p, n[:, :2], q, grid_scale=32)
    with pytest.raises(ValueError, match="disagree on the number of points M"):
        ponq.mesh(p, n[:-1], q, grid_scale=32)
    pn = p.copy()
    pn[7, 0] = np.nan
    with pytest.raises(ValueError, match=r"points\[7\] = .* is not finite"):
        ponq.mesh(pn, n, q, grid_scale=32)
    with pytest.raises(ValueError, match="grid_scale must be >= 1"):
        ponq.mesh(p, n, q, grid_scale=0.5)
    with pytest.raises(ValueError, match="coarsen needs lite=True"):
        ponq.mesh(p, n, q, grid_scale=32, coarsen=1)
    with pytest.raises(ValueError, match="merge_smooth and lite exclude each other"):
        ponq.mesh(p, n, q, grid_scale=32, lite=True, merge_smooth=10)
    with pytest.raises(TypeError):
        ponq.mesh(p, n, q)  # grid_scale is required


def test_docstrings():
    assert ponq.__version__ and ponq.DEFAULT_MERGE_SMOOTH == 15.0
    assert "ponq.infer" in ponq.__doc__
    for name in ["infer", "mesh", "sdf", "sample", "fit", "metrics", "check", "marching_cubes"]:
        fn = getattr(ponq, name)
        assert fn.__doc__ and ("Args:" in fn.__doc__ or "Returns:" in fn.__doc__), name
        assert fn.__text_signature__.startswith("(")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ponq.check(*cube_mesh())


def _box_sphere(p):
    """Exact SDF of the union of a box (half size 0.45) and a sphere (radius 0.35 at x=0.4),
    any array of points (N, 3)."""
    p = np.asarray(p, dtype=np.float64)
    q = np.abs(p) - 0.45
    box = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    sphere = np.linalg.norm(p - np.array([0.4, 0.0, 0.0]), axis=1) - 0.35
    return np.minimum(box, sphere)


def test_infer_field_evaluates_near_the_surface_and_meshes_as_the_dense_grid():
    res = 40
    calls = []

    def f(p):
        assert p.shape[1] == 3 and p.dtype == np.float64 and len(p) <= 4096
        calls.append(len(p))
        return _box_sphere(p)

    v, faces, stats = ponq.infer_field(f, res, batch=4096)
    assert stats["calls"] == len(calls) and stats["points"] == sum(calls)
    assert stats["dense_points"] == (res + 1) ** 3
    # The grid's nodes, as the function places them: lo + i * h.
    lo, h = -1.0, 2.0 / res
    ax = lo + np.arange(res + 1) * h
    grid = _box_sphere(np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3))
    vd, fd = ponq.infer(grid.reshape(res + 1, res + 1, res + 1))
    assert np.array_equal(v, vd) and np.array_equal(faces, fd)
    assert ponq.check(v, faces)["valid"]
    # The share of the grid evaluated falls about as 1 / res (the band's thickness in
    # cells stays the same).
    share = []
    for r in (80, 160):
        _, _, s = ponq.infer_field(_box_sphere, r, refine="off")
        share.append(s["points"] / s["dense_points"])
    assert share[1] < 0.4 and share[1] < 0.65 * share[0], share


def test_infer_field_errors_are_clear():
    with pytest.raises(ValueError, match="values for"):
        ponq.infer_field(lambda p: np.zeros(3), 16)
    with pytest.raises(ValueError, match="no sign change"):
        ponq.infer_field(lambda p: np.ones(len(p)), 16)

    def boom(p):
        raise KeyError("from the field")

    with pytest.raises(KeyError, match="from the field"):
        ponq.infer_field(boom, 16)


def test_infer_field_takes_a_torch_module():
    torch = pytest.importorskip("torch", reason="PyTorch is not installed here")

    class Sphere(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.lin = torch.nn.Linear(3, 3)
            with torch.no_grad():
                self.lin.weight.copy_(torch.eye(3))
                self.lin.bias.zero_()

        def forward(self, x):
            return self.lin(x).norm(dim=1) - 0.6

    net = Sphere()
    with torch.no_grad():
        v, faces, stats = ponq.infer_field(
            lambda p: net(torch.from_numpy(p).float()).numpy(), 48, batch=10000
        )
    assert ponq.check(v, faces)["valid"]
    assert stats["points"] < stats["dense_points"]


def _grid_of(f, res):
    lo, h = -1.0, 2.0 / res
    ax = lo + np.arange(res + 1) * h
    pts = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)
    return f(pts).reshape(res + 1, res + 1, res + 1)


def test_infer_reads_fields_in_other_conventions():
    res = 40
    h = 2.0 / res
    d = _grid_of(_box_sphere, res)
    v, f = ponq.infer(d)
    # Inside positive: the same values once the sign is flipped, the same mesh, with a note.
    with pytest.warns(UserWarning, match="sign flipped"):
        vp, fp = ponq.infer(-d)
    assert np.array_equal(v, vp) and np.array_equal(f, fp)
    # inside= says it without a note.
    vp, fp = ponq.infer(-d, inside="positive")
    assert np.array_equal(v, vp)
    # Voxel units, a normalised TSDF, an occupancy (level 0.5, inside high, with a note), a
    # surface at another level: the exact grid's surface.
    cases = [
        (d / h, {}),
        (np.clip(d / (4 * h), -1, 1), {}),
        (d + 0.3, {"level": 0.3}),
    ]
    # (F1 is sampled: a mesh against itself scores below 1; that is the mark.)
    itself = ponq.metrics(v, f, v, f)["f1"]
    for grid, kw in cases:
        vg, fg = ponq.infer(grid, **kw)
        assert ponq.check(vg, fg)["valid"]
        assert ponq.metrics(vg, fg, v, f)["f1"] > itself - 0.02, kw
    with pytest.warns(UserWarning, match="level 0.5"):
        vo, fo = ponq.infer(1.0 / (1.0 + np.exp(d / h)))
    assert ponq.metrics(vo, fo, v, f)["f1"] > itself - 0.05
    # What cannot be told is a ValueError that says what to give.
    with pytest.raises(ValueError, match="both sides of the level"):
        ponq.infer(_grid_of(lambda p: p[:, 0] - 0.1, 16))
    ponq.infer(_grid_of(lambda p: p[:, 0] - 0.1, 16), inside="negative")
    with pytest.raises(ValueError, match="invalid value 'outside' for inside"):
        ponq.infer(d, inside="outside")
    with pytest.raises(ValueError, match="invalid value 'occupancy' for field"):
        ponq.infer(d, field="occupancy")


def test_infer_field_of_an_mlp_in_voxel_units():
    """A small MLP fitted to the box-and-sphere (one hidden layer of 512 tanh units, its
    output layer by least squares), evaluated in voxel units: infer_field measures the unit
    from its first evaluations and meshes what the dense grid of the same field gives."""
    rng = np.random.default_rng(0)
    w = rng.normal(0.0, 3.0, (3, 512))
    b = rng.uniform(-3.0, 3.0, 512)
    x = rng.uniform(-1.0, 1.0, (30000, 3))
    feats = lambda p: np.tanh(p @ w + b)
    coef, *_ = np.linalg.lstsq(feats(x), _box_sphere(x), rcond=None)
    # Evaluated in float32 and in chunks, as a network would be (and fast enough for a test).
    w32, b32, c32 = (a.astype(np.float32) for a in (w, b, coef))

    def net(p):
        p = np.asarray(p, dtype=np.float32)
        out = np.empty(len(p), np.float32)
        for s in range(0, len(p), 32768):
            out[s : s + 32768] = np.tanh(p[s : s + 32768] @ w32 + b32) @ c32
        return out.astype(np.float64)

    res = 96
    h = 2.0 / res
    mlp = lambda p: net(p) / h
    v, f, stats = ponq.infer_field(mlp, res)
    assert "rescaled" in stats["field"], stats["field"]
    vd, fd = ponq.infer(_grid_of(mlp, res))
    assert ponq.check(v, f)["valid"] and ponq.check(vd, fd)["valid"]
    # (F1 is sampled: a mesh against itself scores below 1; that is the mark.)
    assert ponq.metrics(v, f, vd, fd)["f1"] > ponq.metrics(vd, fd, vd, fd)["f1"] - 0.02
    assert stats["points"] < stats["dense_points"]


def test_colours_from_a_grid_and_from_a_field():
    """A colour field (linear in the position) through infer_field equals the same colours as
    a grid through infer: the same mesh, the same colour at every vertex."""
    res = 40
    g = lambda p: np.clip((np.asarray(p) + 1.0) / 2.0, 0.0, 1.0)
    v, f, c, stats = ponq.infer_field(_box_sphere, res, colour=g)
    assert c.shape == v.shape and c.dtype == np.float64
    lo, h = -1.0, 2.0 / res
    ax = lo + np.arange(res + 1) * h
    nodes = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1)
    vg, fg, cg = ponq.infer(_grid_of(_box_sphere, res), colours=g(nodes.reshape(-1, 3)).reshape(nodes.shape))
    assert np.array_equal(v, vg) and np.array_equal(f, fg)
    assert np.abs(c - cg).max() < 1e-5
    assert np.abs(c - g(v)).max() < 1e-5
    # Bytes work too; colours of another shape or out of range are errors.
    vb, fb, cb = ponq.infer(_grid_of(_box_sphere, res), colours=(255 * g(nodes.reshape(-1, 3))).astype(np.uint8).reshape(nodes.shape))
    assert np.abs(cb - cg).max() < 1.0 / 255 + 1e-6
    with pytest.raises(ValueError, match="grid's shape with 3 channels"):
        ponq.infer(_grid_of(_box_sphere, res), colours=np.zeros((3, 3, 3, 3)))
    with pytest.raises(ValueError, match=r"outside \[0, 1\]"):
        ponq.infer(_grid_of(_box_sphere, res), colours=2.0 * np.ones(nodes.shape))
    with pytest.raises(ValueError, match="colours are in"):
        ponq.infer_field(_box_sphere, 24, colour=lambda p: 2.0 * np.ones((len(p), 3)))


def _dataset(tmp_path, count=20):
    """`count` meshes (the shared evaluation meshes where they are, else copies of the
    examples) and one broken file, in a folder."""
    src = ROOT.parent / "shared" / "data" / "meshes"
    files = sorted(p for p in src.rglob("*.obj")) if src.is_dir() else []
    files = files[:count]
    d = tmp_path / "meshes"
    d.mkdir()
    if len(files) < count:
        files = [EXAMPLES / "csg.obj", EXAMPLES / "example001.obj"]
        for i in range(count):
            (d / f"part_{i:02d}.obj").write_bytes(files[i % 2].read_bytes())
    else:
        for f in files:
            (d / f.name).write_bytes(f.read_bytes())
    (d / "broken.obj").write_text("v 0 0 0\nnot a face\n")
    return d


def _npz_files(d):
    return {p.name: p.read_bytes() for p in sorted(Path(d).glob("*.npz"))}


def _npz_tree(d):
    """Every record under `d`, by its path below `d` (hidden temporary files excluded)."""
    return {
        str(p.relative_to(d)): p.read_bytes()
        for p in sorted(Path(d).rglob("*.npz"))
        if not p.name.startswith(".")
    }


def _shapenet(tmp_path):
    """Three different meshes, each `model.obj` in its own folder (a ShapeNet-style layout)."""
    d = tmp_path / "shapenet"
    for folder, src in [("a", "csg.obj"), ("b", "example001.obj")]:
        (d / folder).mkdir(parents=True)
        (d / folder / "model.obj").write_bytes((EXAMPLES / src).read_bytes())
    # The third: example001 with x and y swapped.
    lines = []
    for line in (EXAMPLES / "example001.obj").read_text().splitlines():
        t = line.split()
        lines.append(f"v {t[2]} {t[1]} {t[3]}" if t[:1] == ["v"] else line)
    (d / "c").mkdir()
    (d / "c" / "model.obj").write_text("\n".join(lines) + "\n")
    return d


def test_prepare_meshes_shapenet_layout(tmp_path):
    d = _shapenet(tmp_path)
    meshes = sorted(str(p) for p in d.rglob("*.obj"))
    run([binary("ponq-prep"), "meshes", d, "-o", tmp_path / "cli", "--res", "8", "--samples", "2000", "-q"])
    recs = ponq.prepare_meshes(meshes, str(tmp_path / "py"), res=[8], samples=2000)
    assert sorted(r["name"] for r in recs) == ["a/model", "b/model", "c/model"]
    assert all(r["status"] == "done" and r["shards"] == 1 and r["time"].endswith("Z") for r in recs)
    cli, py = _npz_tree(tmp_path / "cli"), _npz_tree(tmp_path / "py")
    assert sorted(py) == ["a/model.npz", "b/model.npz", "c/model.npz"]
    assert cli == py and len(set(py.values())) == 3
    sharded = tmp_path / "sharded"
    names = [
        {r["name"] for r in ponq.prepare_meshes(meshes, str(sharded), res=[8], samples=2000, shard=(i, 3))}
        for i in range(3)
    ]
    assert sum(len(n) for n in names) == 3 and _npz_tree(sharded) == py
    # Names depend on the root only: one mesh alone, with the dataset's root, keeps its name.
    assert ponq.output_names(meshes[:1], root=str(d)) == ["a/model"]
    assert ponq.mesh_files(d) == (meshes, str(d))
    # Two files that differ only by their extension: refused before any work.
    (d / "a" / "model.stl").write_bytes(b"solid x\nendsolid x\n")
    with pytest.raises(ValueError, match="would both be written"):
        ponq.prepare_meshes(meshes + [str(d / "a" / "model.stl")], str(tmp_path / "twins"))
    assert not (tmp_path / "twins").exists()


def test_prepare_meshes_matches_ponq_prep(tmp_path):
    d = _dataset(tmp_path, count=4)
    meshes = sorted(str(p) for p in d.glob("*.obj"))
    # The broken file fails: exit 2.
    run([binary("ponq-prep"), "meshes", d, "-o", tmp_path / "cli", "--res", "16", "--samples", "3000", "-q"], code=2)
    recs = ponq.prepare_meshes(meshes, str(tmp_path / "py"), res=[16], samples=3000)
    assert _npz_files(tmp_path / "cli") == _npz_files(tmp_path / "py")
    assert sorted(r["status"] for r in recs) == ["done"] * 4 + ["error"]
    again = ponq.prepare_meshes(meshes, str(tmp_path / "py"), res=[16], samples=3000, log=False)
    assert sorted(r["status"] for r in again) == ["already"] * 4 + ["error"]
    # Shards: disjoint and covering.
    names = [
        {r["name"] for r in ponq.prepare_meshes(meshes, str(tmp_path / "s"), res=[16], samples=3000, shard=f"{i}/3")}
        for i in range(3)
    ]
    assert sum(len(n) for n in names) == 5 and set().union(*names) == {Path(m).stem for m in meshes}
    with pytest.raises(ValueError, match="shard"):
        ponq.prepare_meshes(meshes, str(tmp_path / "x"), shard="3/3")


def test_ray_prepare_matches_ponq_prep(tmp_path):
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install ./ponq-py[ray])")
    import importlib.util

    spec = importlib.util.spec_from_file_location("ray_prepare", ROOT / "ponq-py" / "examples" / "ray_prepare.py")
    ray_prepare = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ray_prepare)
    d = _dataset(tmp_path, count=20)
    run([binary("ponq-prep"), "meshes", d, "-o", tmp_path / "cli", "--res", "16", "--samples", "2000", "-q"], code=2)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        meshes, root = ray_prepare.mesh_files(d)
        out = tmp_path / "ray"
        recs = ray_prepare.prepare(meshes, out, root=root, shards=4, res=[16], samples=2000)
        assert _npz_files(tmp_path / "cli") == _npz_files(out)
        assert len(_npz_files(out)) == 20
        errors = [r for r in recs if r["status"] == "error"]
        assert len(errors) == 1 and errors[0]["name"] == "broken" and errors[0]["error"]
        assert sorted(r["name"] for r in recs) == sorted(Path(m).stem for m in meshes)
        # The logs beside the outputs hold the same records; a second run skips everything.
        logged = [json.loads(l) for f in sorted(out.glob("log-shard-*.jsonl")) for l in f.read_text().splitlines()]
        assert len(logged) == 21
        again = ray_prepare.prepare(meshes, out, root=root, shards=4, res=[16], samples=2000)
        assert sorted(r["status"] for r in again) == ["already"] * 20 + ["error"]
        # A ShapeNet-style layout: one output per mesh, as ponq-prep writes them.
        sn = _shapenet(tmp_path)
        run([binary("ponq-prep"), "meshes", sn, "-o", tmp_path / "sn-cli", "--res", "8", "--samples", "2000", "-q"])
        sn_files, sn_root = ray_prepare.mesh_files(sn)
        recs = ray_prepare.prepare(sn_files, tmp_path / "sn-ray", root=sn_root, shards=3, res=[8], samples=2000)
        assert sorted(r["name"] for r in recs) == ["a/model", "b/model", "c/model"]
        assert _npz_tree(tmp_path / "sn-ray") == _npz_tree(tmp_path / "sn-cli")
        # The example's command line exits 2 when a shape failed, 0 when all are done.
        args = [str(d), "-o", str(tmp_path / "ray-cli"), "--res", "16", "--samples", "2000", "--shards", "2"]
        assert ray_prepare.main(args) == 2
        assert ray_prepare.main([str(sn), "-o", str(tmp_path / "sn-ray"), "--res", "8", "--samples", "2000"]) == 0
    finally:
        ray.shutdown()
