#!/usr/bin/env python3
"""Benchmark of the `ponq` Python module (not a test). Prints two tables:

1. `ponq.mesh` on the arrays of the shared reference PoNQs (`../shared/data/ponq-reference/*.npz`,
   in the [-1,1] frame, grid from the file name), median of --runs calls (and the meshing time
   that the `ponq-mesh` program prints for the same file, median of as many runs), next to the authors'
   Python mesher on the same arrays when AUTHORS_PONQ points at `src/utils` of a checkout of
   their repository (run through `ponq-mesh/benches/authors/authors_mesh.py` with $PYTHON, which
   needs torch, scipy and networkx; its meshing-only time). Without AUTHORS_PONQ that column is
   left out.
2. `ponq.infer` against the `ponq-infer` program on the same grids, median of --runs each: the
   program's wall time (process start, model load, reading, writing, validity check included)
   and its own compute time (network + to PoNQ + meshing + refinement, as it prints it), and
   `ponq.infer(check=False)` (network cached after a warm-up call, array conversion included).
   The binding's overhead is ponq.infer against the program's compute time (goal: within 5%).

    python3 ponq-py/bench/bench_ponq.py [--runs 5] [--threads N] [--large]

Needs the package installed and the release programs (cargo build --release --bins).
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import ponq

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("PONQ_BIN_DIR", ROOT / "target" / "release"))
REFERENCE = ROOT.parent / "shared" / "data" / "ponq-reference"
AUTHORS_SCRIPT = ROOT / "ponq-mesh" / "benches" / "authors" / "authors_mesh.py"


def median_time(fn, runs):
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def table(header, rows):
    w = [max(len(str(r[i])) for r in [header] + rows) for i in range(len(header))]
    line = lambda r: "| " + " | ".join(str(c).rjust(w[i]) for i, c in enumerate(r)) + " |"
    print(line(header))
    print("|" + "|".join("-" * (x + 2) for x in w) + "|")
    for r in rows:
        print(line(r))


def bench_mesh(args, tmp):
    files = sorted(REFERENCE.glob("*.npz"))
    if not files:
        print(f"(no reference PoNQs in {REFERENCE}: table 1 skipped)\n")
        return
    authors = os.environ.get("AUTHORS_PONQ")
    python = os.environ.get("PYTHON", "/usr/bin/python3")
    print(f"## 1. ponq.mesh on {REFERENCE} (median of {args.runs})")
    if not authors:
        print("AUTHORS_PONQ is not set: the authors' mesher column is left out "
              "(set it to src/utils of a checkout of their repository to add it)")
    exe = BIN / "ponq-mesh"
    header = ["file", "grid", "points", "V", "F", "valid", "ponq.mesh ms"]
    if exe.is_file():
        header += ["ponq-mesh meshing ms"]
    if authors:
        header += ["authors s", "speed-up"]
    rows = []
    for f in files:
        m = re.search(r"_(\d+)$", f.stem)
        res = int(m.group(1)) if m else 32
        d = np.load(f)
        p, n, q = d["points"], d["normals"], d["quadrics"]
        kw = dict(grid_scale=res, threads=args.threads, check=False)
        v, fa = ponq.mesh(p, n, q, **kw)
        t = median_time(lambda: ponq.mesh(p, n, q, **kw), args.runs)
        row = [f.stem, res, len(p), len(v), len(fa), "yes" if ponq.check(v, fa)["valid"] else "NO",
               f"{t * 1e3:.1f}"]
        if exe.is_file():
            ms = []
            for _ in range(args.runs):
                r = subprocess.run([str(exe), str(f), "-o", str(tmp / "m.obj"), "--grid-scale", str(res),
                                    "--no-check", *(["--threads", str(args.threads)] if args.threads else [])],
                                   capture_output=True, text=True)
                s = re.search(r"meshing total ([0-9.]+)", r.stdout)
                if r.returncode != 0 or not s:
                    raise SystemExit(f"ponq-mesh failed on {f}: {r.stderr}")
                ms.append(float(s.group(1)))
            row.append(f"{statistics.median(ms):.1f}")
        if authors:
            out = tmp / "authors.obj"
            r = subprocess.run([python, str(AUTHORS_SCRIPT), str(f), str(res), str(out)],
                               capture_output=True, text=True, env={**os.environ, "AUTHORS_PONQ": authors})
            s = re.search(r"seconds ([0-9.]+)", r.stdout)
            if r.returncode == 0 and s:
                a = float(s.group(1))
                row += [f"{a:.3f}", f"{a / t:.1f}x"]
            else:
                row += ["failed", "-"]
                print(f"authors' mesher failed on {f.name}: {r.stderr.strip()[-300:]}", file=sys.stderr)
        rows.append(row)
    table(header, rows)
    print()


TIME_LINE = re.compile(
    r"network ([0-9.]+).*?to PoNQ ([0-9.]+), meshing ([0-9.]+).*?refinement ([0-9.]+)")


def bench_infer(args, tmp):
    exe = BIN / "ponq-infer"
    if not exe.is_file():
        print(f"(no {exe}: build it with cargo build --release --bins; table 2 skipped)")
        return
    grids = [ROOT / "examples" / "csg_sdf_33.npy", ROOT / "examples" / "example001_sdf_65.npy"]
    if args.large:
        big = tmp / "example001_sdf_129.npy"
        v, f = read_obj(ROOT / "examples" / "example001.obj")
        np.save(big, ponq.sdf(v, f, 128))
        grids.append(big)
    print(f"## 2. ponq.infer against the ponq-infer program (median of {args.runs})")
    header = ["grid", "F", "program wall ms", "program compute ms", "ponq.infer ms",
              "overhead vs compute"]
    rows = []
    threads = ["--threads", str(args.threads)] if args.threads else []
    for g in grids:
        out = tmp / "out.obj"
        walls, computes = [], []
        for _ in range(args.runs):
            t = time.perf_counter()
            r = subprocess.run([str(exe), str(g), "-o", str(out), *threads],
                               capture_output=True, text=True)
            walls.append(time.perf_counter() - t)
            m = TIME_LINE.search(r.stdout)
            if r.returncode != 0 or not m:
                raise SystemExit(f"ponq-infer failed on {g}: {r.stderr}{r.stdout}")
            computes.append(sum(float(x) for x in m.groups()) / 1e3)
        sdf = np.load(g)
        v, f = ponq.infer(sdf, threads=args.threads, check=False)  # warm-up: loads the network
        t = median_time(lambda: ponq.infer(sdf, threads=args.threads, check=False), args.runs)
        c = statistics.median(computes)
        rows.append([g.stem, len(f), f"{statistics.median(walls) * 1e3:.1f}", f"{c * 1e3:.1f}",
                     f"{t * 1e3:.1f}", f"{(t / c - 1) * 100:+.1f}%"])
    table(header, rows)


def read_obj(path):
    v, f = [], []
    for line in open(path):
        t = line.split()
        if t and t[0] == "v":
            v.append([float(x) for x in t[1:4]])
        elif t and t[0] == "f":
            f.append([int(x.split("/")[0]) - 1 for x in t[1:4]])
    return np.array(v), np.array(f)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    ap.add_argument("--large", action="store_true", help="add a 129^3 grid of example001 to table 2")
    args = ap.parse_args()
    print(f"ponq {ponq.__version__}, {os.cpu_count()} cores, numpy {np.__version__}\n")
    with tempfile.TemporaryDirectory() as d:
        bench_mesh(args, Path(d))
        bench_infer(args, Path(d))


if __name__ == "__main__":
    main()
