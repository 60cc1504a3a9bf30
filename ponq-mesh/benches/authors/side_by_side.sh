#!/usr/bin/env bash
# ponq-mesh side by side with the authors' Python mesher on new PoNQ files made from shared CAD
# meshes (`ponq-fit --save-ponq` at 32^3 and 64^3), both scored by `ponq-eval compare` against the
# source mesh and checked by `ponq-eval check` (docs/meshing.md).
#
#   AUTHORS_PONQ=/path/to/PoNQ/src/utils ponq-mesh/benches/authors/side_by_side.sh [OUT_DIR] [MESH ...]
#
# MESH: paths under ../shared/data/meshes/cad without .obj (default: the eight of the README),
# or one of the README's other sets by name: `holdout` (eight other CAD meshes), `third` (ten
# more, the set that checked the no-sliver flip rule) or `fourth` (ten more, the set that checked
# the normal-term flip rule of 2026-12-06).
# SEEDS=N (default 5): each output scored with N sampling seeds, the tables give the means
# (score.py: on some files the seed alone moves EF1 by 0.001).
# Needs a checkout of the authors' repository (github.com/nissmar/PoNQ) and Debian's
# python3-torch, python3-scipy, python3-networkx; release binaries (cargo build --release --bins).
set -euo pipefail
cd "$(dirname "$0")/../../.."
here=ponq-mesh/benches/authors
out=${1:-target/authors-side-by-side}
shift || true
meshes=("$@")
if [ ${#meshes[@]} -eq 1 ] && [ "${meshes[0]}" = holdout ]; then
  meshes=(openscad_examples/Old_example008 openscad_examples/Old_example011
    openscad_examples/Old_example013 openscad_examples/Basics_CSG-modules
    freecad_fcstd/fcstd_geomop_14 freecad_fcstd/fcstd_drilling_plate_final gmsh/gmsh_lever
    freecad_step/freecad_idf_SOT23)
elif [ ${#meshes[@]} -eq 1 ] && [ "${meshes[0]}" = third ]; then
  meshes=(openscad_examples/Old_example009 openscad_examples/Old_example014
    openscad_examples/Old_example016 openscad_examples/Old_example021 openscad_examples/Basics_CSG
    openscad_examples/Parametric_candleStand freecad_fcstd/fcstd_toolbit_ballend
    freecad_step/freecad_idf_SOT404 gmsh/gmsh_component8 pyvista/pyvista_nut)
elif [ ${#meshes[@]} -eq 1 ] && [ "${meshes[0]}" = fourth ]; then
  meshes=(openscad_examples/Old_example012 openscad_examples/Old_example018
    openscad_examples/Old_example019 openscad_examples/Old_example020
    openscad_examples/Old_example022 openscad_examples/Basics_linear_extrude
    freecad_fcstd/fcstd_geomop_5 freecad_fcstd/fcstd_toolbit_chamfer
    freecad_step/freecad_idf_SOT428_DPAK gmsh/gmsh_t13_data)
fi
if [ ${#meshes[@]} -eq 0 ]; then
  meshes=(openscad_examples/Old_example002 openscad_examples/Old_example003
    openscad_examples/Old_example004 openscad_examples/Old_example005
    openscad_examples/Old_example007 openscad_examples/Old_example010
    openscad_examples/Basics_rotate_extrude freecad_step/freecad_idf_EPL22_6_16)
fi
py=${PYTHON:-/usr/bin/python3}
if ! "$py" -c "import torch, scipy, networkx" 2>/dev/null; then
  echo "$py lacks torch / scipy / networkx: apt-get install python3-torch python3-scipy python3-networkx" >&2
  exit 1
fi
mkdir -p "$out"
src=../shared/data/meshes/cad
bin=target/release
for m in "${meshes[@]}"; do
  n=$(basename "$m")
  for r in 32 64; do
    p="$out/${n}_$r.npz"
    [ -f "$p" ] || "$bin/ponq-fit" "$src/$m.obj" -o "$out/fit.obj" --grid "$r" --save-ponq "$p" -q
    a=$("$py" "$here/authors_mesh.py" "$p" "$r" "$out/${n}_$r.authors.obj" | tail -1)
    echo "$n $r authors: $a"
    echo "${a##* }" > "$out/${n}_$r.authors.seconds"
    # Our meshing time (the `meshing total` ponq-mesh prints: no reading, writing or check).
    "$bin/ponq-mesh" "$p" -o "$out/${n}_$r.ours.obj" --grid-scale "$r" --no-check |
      sed -n 's/.*meshing total \([0-9.]*\).*/\1/p' > "$out/${n}_$r.ours.ms"
    "$bin/ponq-mesh" "$p" -o "$out/${n}_$r.noflip.obj" --grid-scale "$r" --no-crease-flips -q
    "$bin/ponq-mesh" "$p" -o "$out/${n}_$r.paper.obj" --grid-scale "$r" --small-tets-both-ways -q
  done
done
"$py" "$here/score.py" "$out" "$src" "$bin/ponq-eval"
