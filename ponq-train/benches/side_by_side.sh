#!/usr/bin/env bash
# The paper's network (width 128, P = 4, 33^3 grid, batch 1) in PyTorch and in PoNQ-rs
# (Burn's stock layers and the fast CPU kernels) on this machine, in alternating rounds so that
# the machine's drift hits all of them alike. PyTorch: Debian's python3-torch
# (`apt-get install python3-torch`), timed by ../shared/tools/torch_ponqnet.py (or $TORCH_SCRIPT).
#
#   ponq-train/benches/side_by_side.sh [ROUNDS]      (default 3)
#
# The PyTorch training step uses a plain squared loss; ours computes the paper's six losses
# (kd-tree assignments included), so it carries that work on top.
set -euo pipefail
cd "$(dirname "$0")/../.."
rounds=${1:-3}
py=${PYTHON:-/usr/bin/python3}
script=${TORCH_SCRIPT:-../shared/tools/torch_ponqnet.py}
if ! "$py" -c "import torch" 2>/dev/null; then
  echo "PyTorch not found for $py: apt-get install python3-torch (or set PYTHON)" >&2
  exit 1
fi
if [ ! -f "$script" ]; then
  echo "no PyTorch timing script at $script (set TORCH_SCRIPT)" >&2
  exit 1
fi
cargo bench -q -p ponq-train --bench train_bench --no-run
for r in $(seq 1 "$rounds"); do
  echo "## round $r"
  echo "PyTorch $("$py" -c 'import torch; print(torch.__version__)'), 2 threads (its last 2 of 3 runs; the first warms up):"
  "$py" "$script" 32 | tail -2
  "$py" "$script" 32 --train | tail -2
  cargo bench -q -p ponq-train --bench train_bench -- 2 paper
done
