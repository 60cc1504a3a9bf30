#!/bin/sh
# Whole meshing side by side with another build of `ponq-mesh`, same machine, same minutes.
#   ponq-mesh/benches/mesh_side_by_side.sh OLD_PONQ_MESH [ROUNDS]   (from the repository root)
# OLD_PONQ_MESH: the `ponq-mesh` binary of the other build, e.g. from
#   git worktree add /tmp/old <commit> && (cd /tmp/old && cargo build --release -p ponq-mesh --bin ponq-mesh)
# Writes `mesh_bench`'s synthetic PoNQs (~10k, ~43k, ~109k points) to target/mesh-sbs, then
# alternates the two builds on them (fresh processes, 3 runs each per round, no validity
# check), prints each run's stage times and checks that both builds wrote the same mesh.
set -e
OLD=${1:?usage: mesh_side_by_side.sh OLD_PONQ_MESH [ROUNDS]}
ROUNDS=${2:-3}
DIR="$(pwd)/target/mesh-sbs"   # absolute: cargo runs benches in the package folder
mkdir -p "$DIR"
cargo build -q --release -p ponq-mesh --bin ponq-mesh
NEW="$(pwd)/target/release/ponq-mesh"
cargo bench -q -p ponq-mesh --bench mesh_bench -- --grid 72 --grid 145 --grid 230 --repeat 1 --save "$DIR" > /dev/null
for r in $(seq "$ROUNDS"); do
  for g in 72 145 230; do
    for build in old new; do
      bin=$OLD; [ "$build" = new ] && bin=$NEW
      for k in 1 2 3; do
        "$bin" "$DIR/synthetic_$g.npz" -o "$DIR/$build-$g.obj" --grid-scale "$g" --no-check \
          | grep "time (ms)" | sed "s/^/round $r, $build, grid $g: /"
      done
    done
    cmp -s "$DIR/old-$g.obj" "$DIR/new-$g.obj" && echo "grid $g: same mesh" || echo "grid $g: MESHES DIFFER"
  done
done
