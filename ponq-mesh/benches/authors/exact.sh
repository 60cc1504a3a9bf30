#!/usr/bin/env bash
# Does `ponq-mesh --authors-mesher` reproduce the authors' mesher face for face? Runs their
# Python mesher (their repository's src/utils) with two fixes applied from outside
# (authors_mesh.py): networkx's Boykov-Kolmogorov flow (AUTHORS_FLOW=bk: an exact minimum cut;
# their default preflow-push partition is not always minimal) and, unless AUTHORS_CLAMP=0,
# arccos arguments clipped to [-1, 1] (no NaN capacities); then ours on the same PoNQ files,
# and compares the faces (face_diff.py: vertices matched by position). docs/meshing.md.
#
#   AUTHORS_PONQ=/path/to/PoNQ/src/utils ponq-mesh/benches/authors/exact.sh [OUT_DIR] [PONQ.npz ...]
#
# PONQ: files named NAME_RES.npz (default: the shared reference files). Needs Debian's
# python3-torch, python3-scipy, python3-networkx and a release ponq-mesh.
set -euo pipefail
cd "$(dirname "$0")/../../.."
here=ponq-mesh/benches/authors
out=${1:-target/authors-exact}
shift || true
files=("$@")
if [ ${#files[@]} -eq 0 ]; then
  files=(../shared/data/ponq-reference/*_[36][24].npz)
fi
py=${PYTHON:-/usr/bin/python3}
mkdir -p "$out"
echo "| file | faces (authors, exact cut) | faces (ours) | only in ours | only in theirs | identical |"
echo "|---|---:|---:|---:|---:|---|"
for p in "${files[@]}"; do
  s=$(basename "${p%.npz}")
  r=${s##*_}
  if ! AUTHORS_FLOW=bk AUTHORS_CLAMP=${AUTHORS_CLAMP:-1} "$py" "$here/authors_mesh.py" "$p" "$r" "$out/$s.authors_bk.obj" \
    > /dev/null 2> "$out/$s.authors_bk.log"; then
    echo "| $s | their mesher failed: $(tail -1 "$out/$s.authors_bk.log" | cut -c1-80) | | | | |"
    continue
  fi
  target/release/ponq-mesh "$p" -o "$out/$s.authors_mesher.obj" --grid-scale "$r" --authors-mesher -q
  set +e
  read -r fo fa unmatched oo oa < <("$py" "$here/face_diff.py" "$out/$s.authors_mesher.obj" "$out/$s.authors_bk.obj")
  set -e
  same=no
  [ "$unmatched" = 0 ] && [ "$oo" = 0 ] && [ "$oa" = 0 ] && [ "$fo" = "$fa" ] && same=yes
  echo "| $s | $fa | $fo | $oo | $oa | $same |"
done
