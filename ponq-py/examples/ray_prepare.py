#!/usr/bin/env python3
"""Prepare a dataset of meshes on a Ray cluster: one Ray task per shard, each calling
`ponq.prepare_meshes` on its shard (the split of `ponq-prep meshes --shard I/N`), the records
written to one output folder on a shared filesystem, exactly as `ponq-prep meshes` writes them.

Resumable: records already in the output folder (whole) are skipped, so the same command
after a failure (or a lost node) does only what is missing. Output names are those of
`ponq-prep meshes` (the file stem; folders added where stems repeat: OUT/a/model.npz). Exits
2 when any shape failed. Each shard appends its records to
OUT/log-shard-I-of-N.jsonl; `ponq-eval log OUT` summarises them.

    pip install ./ponq-py[ray]
    # on a cluster (ray start --head on one node, ray start --address=HEAD:6379 on the others):
    python ponq-py/examples/ray_prepare.py /shared/meshes -o /shared/records --address auto
    # on this machine only (a local Ray instance with 2 CPUs):
    python ponq-py/examples/ray_prepare.py ../shared/data/meshes -o records --num-cpus 2

Also usable as a module: `prepare(meshes, out, ...)` returns every shape's record.
"""

import argparse
import os
import sys
import time
from pathlib import Path

import ray

import ponq

def mesh_files(dir_or_list):
    """The mesh files of a folder (recursively) or a list file, sorted, and the dataset's
    root: what `ponq-prep meshes` takes (listed by the same code, `ponq.mesh_files`)."""
    return ponq.mesh_files(str(dir_or_list))


@ray.remote(num_cpus=1)
def prepare_shard(meshes, root, out, shard, count, res, samples, sample_seed, repair, threads):
    """One shard of the dataset, in one Ray worker (`threads` cores of it). `meshes` is the
    whole list (names and shards come from all of it); passed as one object of Ray's store,
    it is stored once and read by every task, not copied into each task's arguments."""
    return ponq.prepare_meshes(
        meshes,
        out,
        root=root,
        res=res,
        samples=samples,
        sample_seed=sample_seed,
        repair=repair,
        shard=(shard, count),
        threads=threads,
    )


def prepare(
    meshes,
    out,
    *,
    root=None,
    shards=None,
    res=(32, 64),
    samples=1_000_000,
    sample_seed=0,
    repair=True,
    threads=1,
    progress=None,
):
    """Runs every shard as a Ray task (Ray must be initialised); returns all records. `root`:
    the dataset's folder (output names are the meshes' paths below it); default their
    deepest common folder."""
    # Names checked here, once, before any task runs (ValueError when two meshes would share
    # an output).
    ponq.output_names(list(meshes), root=root)
    os.makedirs(out, exist_ok=True)
    if shards is None:
        # Many small tasks balance shapes of unequal cost; no more tasks than shapes.
        shards = max(1, min(len(meshes), 8 * int(ray.cluster_resources().get("CPU", 1))))
    # The list once in the object store: each task gets a reference (Ray resolves it to
    # the list in the worker), not a copy of its own (shards x meshes).
    meshes_ref = ray.put([str(m) for m in meshes])
    pending = [
        prepare_shard.options(num_cpus=threads).remote(
            meshes_ref, None if root is None else str(root), str(out), i, shards, list(res), samples,
            sample_seed, repair, threads
        )
        for i in range(shards)
    ]
    records = []
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        for r in ray.get(ready):
            records.extend(r)
        if progress:
            progress(shards - len(pending), shards, len(records))
    return records


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("input", help="a folder of meshes (searched recursively) or a list file")
    ap.add_argument("-o", "--output", required=True, help="output folder (shared by the nodes)")
    ap.add_argument("--res", default="32,64", help="grid resolutions, comma-separated")
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--sample-seed", type=int, default=0)
    ap.add_argument("--no-repair", action="store_true")
    ap.add_argument("--shards", type=int, help="Ray tasks [default: 8 per CPU of the cluster, at most one per mesh]")
    ap.add_argument("--threads", type=int, default=1, help="cores per task")
    ap.add_argument("--address", help="Ray cluster address ('auto' for the cluster this node is in); default: a local instance")
    ap.add_argument("--num-cpus", type=int, help="CPUs of the local instance")
    a = ap.parse_args(argv)
    if ray.is_initialized():
        pass  # called from a program that already started Ray
    elif a.address:
        ray.init(address=a.address)
    else:
        ray.init(num_cpus=a.num_cpus, include_dashboard=False)
    try:
        meshes, root = mesh_files(a.input)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if not meshes:
        print(f"error: no mesh (.obj, .ply, .off, .stl) in {a.input}", file=sys.stderr)
        return 2
    t = time.perf_counter()
    try:
        records = prepare(
            meshes,
            a.output,
            root=root,
            shards=a.shards,
            res=[int(r) for r in a.res.split(",")],
            samples=a.samples,
            sample_seed=a.sample_seed,
            repair=not a.no_repair,
            threads=a.threads,
            progress=lambda done, total, n: print(
                f"\r{done}/{total} shards, {n} shapes", end="", file=sys.stderr, flush=True
            ),
        )
    except ValueError as e:
        # Two meshes that would share an output: refused before any task runs.
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(file=sys.stderr)
    by = {}
    for r in records:
        by[r["status"]] = by.get(r["status"], 0) + 1
    print(
        f"{a.output}: {by.get('done', 0)} written, {by.get('already', 0)} already there, "
        f"{by.get('error', 0)} failed, in {time.perf_counter() - t:.1f} s"
    )
    failed = [r for r in records if r["status"] == "error"]
    for r in failed:
        print(f"failed {r['name']}: {r['error']}", file=sys.stderr)
    if failed:
        # Like `ponq-prep meshes`: a batch with a failed shape does not report success.
        print(
            f"error: {len(failed)} of {len(records)} shapes failed (see {a.output}/log-shard-*.jsonl)",
            file=sys.stderr,
        )
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
