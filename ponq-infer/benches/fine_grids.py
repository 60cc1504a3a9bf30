#!/usr/bin/env python3
"""Fine grids: time per stage and peak resident memory of `ponq-infer` at 129^3 ... 1025^3,
beside scikit-image's marching cubes on the same grids, and the mesh input path.

Each run is its own process; its peak resident memory is the kernel's (`wait4`'s maxrss).
The grids are the shared `bunny.obj`'s: `ponq-prep sdf` (dense) up to --dense-max, then
`ponq-prep sdf --band` (exact within 10 cells of the surface, truncated beyond: what
`ponq-infer` reads is the same, so is the mesh). Prints one markdown table.

    cargo build --release --bins
    python3 -m venv /tmp/bench && /tmp/bench/bin/pip install numpy scikit-image
    /tmp/bench/bin/python ponq-infer/benches/fine_grids.py --res 128 256 512 1024 \\
        --mesh-res 512 1024 --work /tmp/fine

Options: --baseline BIN times another `ponq-infer` build on the same grids (side by side
in the same run; up to --baseline-max); --skip-mc leaves scikit-image out.
"""

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BIN = ROOT / "target" / "release"


def run(cmd, env=None):
    """Runs a command; returns (seconds, peak resident MB, stdout + stderr)."""
    t = time.perf_counter()
    p = subprocess.Popen(
        [str(c) for c in cmd], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env
    )
    out = p.stdout.read().decode(errors="replace")
    _, status, ru = os.wait4(p.pid, 0)
    secs = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"failed: {' '.join(map(str, cmd))}\n{out}")
    return secs, ru.ru_maxrss / 1024.0, out


STAGES = ["read", "read + sdf", "network", "to PoNQ", "meshing", "refinement"]


def stages(out):
    """The stage times (s) of `ponq-infer`'s summary line."""
    line = next((l for l in out.splitlines() if l.startswith("time (ms):")), "")
    got = {}
    for name in STAGES:
        m = re.search(re.escape(name) + r" ([0-9.]+)", line)
        if m:
            got[name] = float(m.group(1)) / 1e3
    if "read + sdf" in got:
        got["read"] = got.pop("read + sdf")
    return got


MC = """
import sys, time, numpy as np
from skimage.measure import marching_cubes
t = time.perf_counter()
g = np.load(sys.argv[1]).astype(np.float32, copy=False)
v, f, _, _ = marching_cubes(g, 0.0)
print(f"mc {time.perf_counter() - t:.3f} {len(v)} {len(f)}")
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, nargs="+", default=[128, 256, 512, 1024])
    ap.add_argument("--mesh-res", type=int, nargs="*", default=[512, 1024])
    ap.add_argument("--dense-max", type=int, default=512)
    ap.add_argument("--mesh", type=Path, default=ROOT.parent / "shared/data/bunny.obj")
    ap.add_argument("--work", type=Path, default=Path("/tmp/ponq-fine-grids"))
    ap.add_argument("--baseline", type=Path, help="another ponq-infer to time side by side")
    ap.add_argument("--baseline-max", type=int, default=512, help="largest --res for it")
    ap.add_argument("--skip-mc", action="store_true")
    a = ap.parse_args()
    a.work.mkdir(parents=True, exist_ok=True)
    rows = []
    for r in a.res:
        grid = a.work / f"{a.mesh.stem}{r}.npy"
        if not grid.exists():
            cmd = [BIN / "ponq-prep", "sdf", a.mesh, "--res", r, "-o", grid, "-q"]
            if r > a.dense_max:
                cmd.append("--band")
            secs, mb, _ = run(cmd)
            print(f"prepared {grid.name}: {secs:.1f} s, {mb:.0f} MB", file=sys.stderr)
        builds = [("ponq-infer", BIN / "ponq-infer")]
        if a.baseline and r <= a.baseline_max:
            builds.append(("baseline", a.baseline))
        for name, exe in builds:
            secs, mb, out = run([exe, grid, "-o", a.work / f"out{r}.obj"])
            rows.append((f"{name} grid", r + 1, secs, mb, stages(out)))
            print(f"{name} {r + 1}^3: {secs:.1f} s {mb:.0f} MB", file=sys.stderr)
        if not a.skip_mc:
            secs, mb, out = run([sys.executable, "-c", MC, grid])
            t_mc = float(out.split()[1])
            rows.append(("marching cubes (scikit-image)", r + 1, secs, mb, {"mc": t_mc}))
            print(f"mc {r + 1}^3: {secs:.1f} s {mb:.0f} MB", file=sys.stderr)
    for r in a.mesh_res:
        secs, mb, out = run(
            [BIN / "ponq-infer", a.mesh, "--res", r, "-o", a.work / f"mesh{r}.obj"]
        )
        rows.append(("ponq-infer mesh", r + 1, secs, mb, stages(out)))
        print(f"mesh {r}: {secs:.1f} s {mb:.0f} MB", file=sys.stderr)
    cols = ["read", "network", "to PoNQ", "meshing", "refinement"]
    print("| run | nodes per side | total (s) | peak memory (MB) | " + " | ".join(cols) + " |")
    print("|---|---:|---:|---:|" + "---:|" * len(cols))
    for name, n, secs, mb, st in rows:
        cells = [f"{st[c]:.2f}" if c in st else "" for c in cols]
        if "mc" in st:
            cells[0] = "(load + mc)"
        print(f"| {name} | {n} | {secs:.2f} | {mb:.0f} | " + " | ".join(cells) + " |")
    # Growth per doubling from 257^3 on (ponq-infer on grids).
    own = {n: (s, m) for name, n, s, m, _ in rows if name == "ponq-infer grid"}
    ns = sorted(own)
    for lo, hi in zip(ns, ns[1:]):
        if lo >= 257:
            print(
                f"\n{lo}^3 -> {hi}^3: time x{own[hi][0] / own[lo][0]:.2f}, "
                f"memory x{own[hi][1] / own[lo][1]:.2f}"
            )


if __name__ == "__main__":
    main()
