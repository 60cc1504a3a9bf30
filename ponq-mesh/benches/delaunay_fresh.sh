#!/bin/sh
# The Delaunay's one-thread insertion stage on fresh and on reused memory, per input.
#   ponq-mesh/benches/delaunay_fresh.sh [ROUNDS] [FILE ...]     (from the repository root)
# FILE: PoNQ .npz files (the points the mesher triangulates for them: v* and the protective
# box's corners) or raw point files (f64 x, y, z); default: the shared reference PoNQs
# (../shared/data/ponq-reference/*.npz). For each file and round, two new processes of
# `delaunay_bench` on one thread with the ponq-* programs' allocator setting:
#   fresh   `--runs 1`: the process's first call, whose tet arena is memory new from the system
#           (a page fault on each first touch of a 4 KB page), as in a `ponq-mesh` run;
#   reused  the best of 5 calls (the later calls' arenas reuse the memory freed by the earlier).
# Prints the median (and range) over the rounds, in microseconds per inserted point.
set -e
ROUNDS=${1:-3}
[ $# -gt 0 ] && shift
if [ $# -eq 0 ]; then
  set -- "$(pwd)"/../shared/data/ponq-reference/*.npz
fi
cargo bench -q -p ponq-mesh --bench delaunay_bench --no-run 2>/dev/null
OUT=$(mktemp)
for r in $(seq "$ROUNDS"); do
  for f in "$@"; do
    case $f in /*) ;; *) f="$(pwd)/$f" ;; esac   # cargo runs benches in the package folder
    for mode in fresh reused; do
      if [ $mode = fresh ]; then runs=1; else runs=5; fi
      RAYON_NUM_THREADS=1 cargo bench -q -p ponq-mesh --bench delaunay_bench -- \
        --keep-freed-memory --runs $runs "$f" | grep '^| /' |
        awk -F'|' -v m=$mode '{ gsub(/ /, "", $2); gsub(/ /, "", $3); gsub(/ /, "", $7); print m, $2, $3, $7 }'
    done
  done
done > "$OUT"
echo "| input | points | fresh (first call) | reused (best of 5) |"
echo "|---|---:|---|---|"
# Per file (in the order given): the median and range of each mode over the rounds.
awk '
  { key = $2 SUBSEP $1; v[key, ++n[key]] = $4; pts[$2] = $3; if (!($2 in seen)) { seen[$2] = 1; order[++files] = $2 } }
  function stat(key,   i, j, t, m, a) {
    m = n[key]
    for (i = 1; i <= m; i++) a[i] = v[key, i]
    for (i = 2; i <= m; i++) { t = a[i]; for (j = i - 1; j >= 1 && a[j] > t; j--) a[j + 1] = a[j]; a[j + 1] = t }
    return sprintf("%.2f [%.2f-%.2f]", (m % 2) ? a[(m + 1) / 2] : (a[m / 2] + a[m / 2 + 1]) / 2, a[1], a[m])
  }
  END {
    for (k = 1; k <= files; k++) {
      f = order[k]; name = f; sub(/.*\//, "", name)
      printf "| %s | %s | %s | %s |\n", name, pts[f], stat(f SUBSEP "fresh"), stat(f SUBSEP "reused")
    }
  }' "$OUT"
rm -f "$OUT"
