#!/bin/sh
# Whole meshing side by side with another build of `ponq-mesh`, same machine, same minutes.
#   ponq-mesh/benches/mesh_side_by_side.sh OLD_PONQ_MESH [ROUNDS]   (from the repository root)
# OLD_PONQ_MESH: the `ponq-mesh` binary of the other build, e.g. from
#   git worktree add /tmp/old <commit> && (cd /tmp/old && cargo build --release -p ponq-mesh --bin ponq-mesh)
# Writes `mesh_bench`'s synthetic PoNQs (~10k, ~43k, ~109k points) to target/mesh-sbs, then
# alternates the two builds on them (fresh processes, 3 runs each per round, no validity
# check), prints each run's stage times and checks that both builds wrote the same mesh; last,
# a summary per build and size: median and range of the Delaunay stage and of the meshing total
# (on a noisy machine, compare medians).
set -e
OLD=${1:?usage: mesh_side_by_side.sh OLD_PONQ_MESH [ROUNDS]}
ROUNDS=${2:-3}
DIR="$(pwd)/target/mesh-sbs"   # absolute: cargo runs benches in the package folder
mkdir -p "$DIR"
: > "$DIR/times.txt"
cargo build -q --release -p ponq-mesh --bin ponq-mesh
NEW="$(pwd)/target/release/ponq-mesh"
cargo bench -q -p ponq-mesh --bench mesh_bench -- --grid 72 --grid 145 --grid 230 --repeat 1 --save "$DIR" > /dev/null
for r in $(seq "$ROUNDS"); do
  for g in 72 145 230; do
    for build in old new; do
      bin=$OLD; [ "$build" = new ] && bin=$NEW
      for k in 1 2 3; do
        "$bin" "$DIR/synthetic_$g.npz" -o "$DIR/$build-$g.obj" --grid-scale "$g" --no-check \
          | grep "time (ms)" | sed "s/^/round $r, $build, grid $g: /" | tee -a "$DIR/times.txt"
      done
    done
    cmp -s "$DIR/old-$g.obj" "$DIR/new-$g.obj" && echo "grid $g: same mesh" || echo "grid $g: MESHES DIFFER"
  done
done
echo "## summary (ms): median (min-max) of the runs"
for g in 72 145 230; do
  for build in old new; do
    for stage in "delaunay" "meshing total"; do
      grep ", $build, grid $g:" "$DIR/times.txt" \
        | sed -n "s/.*$stage \([0-9.]*\).*/\1/p" | sort -n \
        | awk -v what="grid $g, $build, $stage" \
            '{ v[NR] = $1 } END { if (NR == 0) exit; m = (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2;
               printf "%s: %.1f (%.1f-%.1f)\n", what, m, v[1], v[NR] }'
    done
  done
done
