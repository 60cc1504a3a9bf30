#!/usr/bin/env bash
# ponq-mesh side by side with the authors' own mesher output on the shared reference PoNQ files
# (../shared/data/ponq-reference: each NAME.npz comes with NAME.authors.obj, made by the authors'
# Python mesher), all scored by score.py against the source mesh (docs/meshing.md).
# Needs no checkout of their repository: their outputs ship with the files.
#
#   ponq-mesh/benches/authors/reference.sh [OUT_DIR]
#
# SEEDS=N (default 5): each output scored with N sampling seeds, the tables give the means
# (score.py: on some files the seed alone moves EF1 by 0.001).
# Needs Debian's python3 and release binaries (cargo build --release --bins).
set -euo pipefail
cd "$(dirname "$0")/../../.."
here=ponq-mesh/benches/authors
out=${1:-target/authors-reference}
ref=../shared/data/ponq-reference
py=${PYTHON:-/usr/bin/python3}
bin=target/release
mkdir -p "$out"
for p in "$ref"/*_[36][24].npz; do
  s=$(basename "${p%.npz}")
  r=${s##*_}
  cp "$ref/$s.authors.obj" "$out/$s.authors.obj"
  # Their mesher's time, from the table of the reference files' README.
  awk -F'|' -v s="$s" '$2 ~ "^ *"s" *$" {gsub(/ /, "", $5); print $5}' "$ref/README.md" > "$out/$s.authors.seconds"
  # Our meshing time (the `meshing total` ponq-mesh prints: no reading, writing or check).
  "$bin/ponq-mesh" "$p" -o "$out/$s.ours.obj" --grid-scale "$r" --no-check |
    sed -n 's/.*meshing total \([0-9.]*\).*/\1/p' > "$out/$s.ours.ms"
  "$bin/ponq-mesh" "$p" -o "$out/$s.noflip.obj" --grid-scale "$r" --no-crease-flips -q
  "$bin/ponq-mesh" "$p" -o "$out/$s.paper.obj" --grid-scale "$r" --small-tets-both-ways -q
done
"$py" "$here/score.py" "$out" ../shared/data/meshes "$bin/ponq-eval"
