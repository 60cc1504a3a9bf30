#!/usr/bin/env python3
"""Throughput of dataset preparation: `ponq-prep meshes` alone (1 and all cores) against the
Ray example (`ponq-py/examples/ray_prepare.py`) with 1 and 2 workers of one core each, on the
same meshes, in one run. Prints a markdown table: shapes per second, Ray's overhead per
worker against `ponq-prep meshes --jobs 1`, and the speed-up of 2 workers over 1.

    cargo build --release --bins
    python3 -m venv /tmp/rayb && CARGO_TARGET_DIR=$PWD/target /tmp/rayb/bin/pip install './ponq-py[ray]'
    /tmp/rayb/bin/python ponq-py/bench/ray_throughput.py --count 20

Ray's start (`ray.init`) is timed apart: a cluster starts once for many datasets.
"""

import argparse
import importlib.util
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ray

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location(
    "ray_prepare", ROOT / "ponq-py" / "examples" / "ray_prepare.py"
)
ray_prepare = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ray_prepare)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "meshes")
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument("--res", default="32,64")
    ap.add_argument("--samples", type=int, default=200_000)
    a = ap.parse_args()
    meshes = ray_prepare.mesh_files(a.data)[: a.count]
    work = Path(tempfile.mkdtemp(prefix="ponq-ray-bench-"))
    listing = work / "list.txt"
    listing.write_text("\n".join(meshes) + "\n")
    res = [int(r) for r in a.res.split(",")]
    rows = []

    def prep(jobs):
        out = work / f"cli{jobs}"
        t = time.perf_counter()
        subprocess.run(
            [ROOT / "target/release/ponq-prep", "meshes", listing, "-o", out, "--res", a.res,
             "--samples", str(a.samples), "--jobs", str(jobs), "-q"],
            check=True,
        )
        return time.perf_counter() - t

    for jobs in (1, 2):
        secs = prep(jobs)
        rows.append((f"ponq-prep meshes --jobs {jobs}", jobs, secs, None))
        print(f"ponq-prep --jobs {jobs}: {secs:.1f} s", file=sys.stderr)
    for workers in (1, 2):
        t = time.perf_counter()
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        start = time.perf_counter() - t
        try:
            t = time.perf_counter()
            # The example's default: 8 shards per CPU, at most one per mesh.
            recs = ray_prepare.prepare(
                meshes, work / f"ray{workers}", res=res, samples=a.samples, threads=1
            )
            secs = time.perf_counter() - t
        finally:
            ray.shutdown()
        assert sum(r["status"] == "done" for r in recs) == len(meshes), recs
        rows.append((f"Ray, {workers} worker(s) of 1 core", workers, secs, start))
        print(f"ray {workers}: {secs:.1f} s (+{start:.1f} s start)", file=sys.stderr)
    same = all(
        (work / "cli1" / p.name).read_bytes() == p.read_bytes()
        for d in ("ray1", "ray2", "cli2")
        for p in (work / d).glob("*.npz")
    )
    n = len(meshes)
    print(f"{n} meshes, res {a.res}, {a.samples} samples; outputs identical byte for byte: {same}\n")
    print("| run | cores | seconds | shapes / s | Ray start (s) |")
    print("|---|---:|---:|---:|---:|")
    for name, cores, secs, start in rows:
        print(f"| {name} | {cores} | {secs:.2f} | {n / secs:.3f} | {'' if start is None else f'{start:.2f}'} |")
    base = rows[0][2]
    r1, r2 = rows[2][2], rows[3][2]
    print(f"\nRay overhead per worker (1 worker against --jobs 1): {100 * (r1 / base - 1):+.1f}%")
    print(f"2 workers against 1: {r1 / r2:.2f}x")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
