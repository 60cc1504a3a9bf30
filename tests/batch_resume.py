#!/usr/bin/env python3
"""A dataset that loses shapes if anything can: 300 meshes all named `model.obj`, in folders
whose names repeat too (`s0/f000/model.obj`, `s1/f000/model.obj`, ... 3 x 100), prepared by
`ponq-prep meshes` in 3 concurrent shards that are killed (`kill -9`) mid-run, then resumed.
Checks that the result is the unsharded run's, byte for byte, 300 outputs, and that
`ponq-eval log` counts each shape once, done.

    python3 tests/batch_resume.py [--bin target/release] [--keep DIR]

Needs the release programs (`cargo build --release --bins`). Exit code 0 when every check
holds; prints a small table of what it did.
"""

import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def make_dataset(d: Path) -> int:
    """300 different meshes: the shipped parts, each sheared by its own amount."""
    srcs = []
    for name in ["example001.obj", "csg.obj"]:
        v, rest = [], []
        for line in (ROOT / "examples" / name).read_text().splitlines():
            t = line.split()
            if t[:1] == ["v"]:
                v.append([float(x) for x in t[1:4]])
            elif t[:1] == ["f"]:
                rest.append(line)
        srcs.append((v, rest))
    n = 0
    for s in range(3):
        for f in range(100):
            v, faces = srcs[(s + f) % 2]
            k = 0.002 * (1 + f + 100 * s)
            out = d / f"s{s}" / f"f{f:03d}"
            out.mkdir(parents=True)
            lines = [f"v {x + k * y:.9f} {y} {z}" for x, y, z in v] + faces
            (out / "model.obj").write_text("\n".join(lines) + "\n")
            n += 1
    return n


def tree(d: Path):
    """Every record below d by its path, temporary files excluded."""
    return {
        str(p.relative_to(d)): p.read_bytes()
        for p in sorted(d.rglob("*.npz"))
        if not p.name.startswith(".")
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target" / "release"))
    ap.add_argument("--keep", help="work in this folder and keep it")
    a = ap.parse_args()
    prep = str(Path(a.bin) / "ponq-prep")
    evaluate = str(Path(a.bin) / "ponq-eval")
    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="ponq-batch-resume-"))
    if a.keep and work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    args = ["--res", "16", "--samples", "20000", "--jobs", "1", "-q"]
    try:
        data = work / "data"
        n = make_dataset(data)
        t0 = time.perf_counter()
        r = subprocess.run([prep, "meshes", str(data), "-o", str(work / "whole")] + args)
        t_whole = time.perf_counter() - t0
        assert r.returncode == 0, f"the unsharded run exited {r.returncode}"
        whole = tree(work / "whole")
        assert len(whole) == n, f"{len(whole)} outputs of {n}"
        assert len(set(whole.values())) == n, "two shapes share a record"
        # Three shards at once, killed mid-run.
        out = work / "sharded"
        t0 = time.perf_counter()
        procs = [
            subprocess.Popen([prep, "meshes", str(data), "-o", str(out), "--shard", f"{i}/3"] + args)
            for i in range(3)
        ]
        time.sleep(max(0.5, 0.4 * t_whole / 3))
        for p in procs:
            p.send_signal(signal.SIGKILL)
        for p in procs:
            p.wait()
        killed_with = len(tree(out)) if out.exists() else 0
        partials = len([p for p in out.rglob(".*partial-*")]) if out.exists() else 0
        # Resume: the same commands, run to the end.
        procs = [
            subprocess.Popen([prep, "meshes", str(data), "-o", str(out), "--shard", f"{i}/3"] + args)
            for i in range(3)
        ]
        codes = [p.wait() for p in procs]
        t_sharded = time.perf_counter() - t0
        assert codes == [0, 0, 0], f"resumed shards exited {codes}"
        got = tree(out)
        assert got == whole, (
            f"{len(got)} outputs; {sum(1 for k in got if got[k] != whole.get(k))} differ from the "
            "unsharded run"
        )
        left = [p for p in out.rglob(".*partial-*")]
        assert not left, f"temporary files left: {left[:3]}"
        summary = subprocess.run([evaluate, "log", str(out)], capture_output=True, text=True, check=True).stdout
        # A shape whose output was committed just before the kill, and its record not yet
        # written, is "already" there on resume: done or already, one record each, nothing else.
        counts = dict(
            (k.strip(), int(v)) for k, v in re.findall(r"^\s+(\w+): (\d+)$", summary, re.M)
        )
        assert f"{n} shapes" in summary, summary
        assert counts.get("done", 0) + counts.get("already", 0) == n, summary
        assert set(counts) <= {"done", "already"}, summary
        print("| run | outputs | seconds | notes |")
        print("|---|---:|---:|---|")
        print(f"| unsharded | {len(whole)} | {t_whole:.1f} | |")
        print(
            f"| 3 shards, kill -9, resumed | {len(got)} | {t_sharded:.1f} | {killed_with} whole and "
            f"{partials} temporary files when killed; equal byte for byte; summary: {n} shapes, done or already there {n} |"
        )
        print("all checks passed")
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
