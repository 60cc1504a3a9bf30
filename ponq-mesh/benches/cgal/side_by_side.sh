#!/bin/sh
# Delaunay side by side with CGAL (and HXT, if gmsh is installed) on the same points, same
# machine, same minutes.
#   ponq-mesh/benches/cgal/side_by_side.sh [ROUNDS]      (from the repository root)
# Needs a C++ compiler and CGAL (Debian: apt-get install g++ libcgal-dev); HXT, the parallel
# Delaunay inside gmsh, is timed too when Debian's libgmsh-dev is installed
# (ponq-mesh/benches/hxt/delaunay_hxt.cpp). Both are only external yardsticks: nothing of
# them is linked into PoNQ-rs.
# Writes the benchmark's point sets to target/delaunay-points, then alternates rounds of
# `delaunay_bench` (ours: one thread, then all) and CGAL's `Delaunay_triangulation_3` range
# insert (one thread, Epick kernel, spatial sort), best of 5 per set and round.
set -e
ROUNDS=${1:-2}
DIR="$(pwd)/target/delaunay-points"   # absolute: cargo runs benches in the package folder
mkdir -p "$DIR"
g++ -O3 -DNDEBUG ponq-mesh/benches/cgal/delaunay_cgal.cpp -o "$DIR/delaunay_cgal" -lgmp -lmpfr
HXT=""
if [ -f /usr/include/gmsh.h ]; then
  g++ -O3 -DNDEBUG ponq-mesh/benches/hxt/delaunay_hxt.cpp -o "$DIR/delaunay_hxt" -lgmsh
  HXT="$DIR/delaunay_hxt"
fi
cargo bench -p ponq-mesh --bench delaunay_bench --no-run
cargo bench -p ponq-mesh --bench delaunay_bench -- --write "$DIR" > /dev/null
FILES=$(ls "$DIR"/*.f64)
for r in $(seq "$ROUNDS"); do
  echo "## round $r: ponq-mesh"
  cargo bench -q -p ponq-mesh --bench delaunay_bench -- $FILES
  echo "## round $r: CGAL (file, points, finite cells, best ms, us / point)"
  "$DIR/delaunay_cgal" $FILES
  if [ -n "$HXT" ]; then
    echo "## round $r: HXT (file, threads, points, tets, best ms, us / point)"
    "$HXT" $FILES
  fi
done
