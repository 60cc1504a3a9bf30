#!/usr/bin/env bash
# The paper's network (width 128, P = 4, 33^3 grid, batch 1) in PyTorch and in PoNQ-rs
# (Burn's stock layers and the fast CPU kernels, f32 and bf16) on this machine, in alternating
# rounds so that the machine's drift hits all of them alike; ends with a summary (range and
# median of each column over the rounds). PyTorch: Debian's python3-torch
# (`apt-get install python3-torch`), timed by ../shared/tools/torch_ponqnet.py (or
# $TORCH_SCRIPT), which runs three steps: its second and third are reported (the third is the
# steady one).
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
log=$(mktemp)
trap 'rm -f "$log"' EXIT
for r in $(seq 1 "$rounds"); do
  echo "## round $r"
  echo "PyTorch $("$py" -c 'import torch; print(torch.__version__)'), 2 threads:"
  "$py" "$script" 32 | tail -1 | sed 's/^/torch /' | tee -a "$log"
  "$py" "$script" 32 --train | tail -2 | sed 's/^/torch /' | tee -a "$log"
  cargo bench -q -p ponq-train --bench train_bench -- 2 paper | tee -a "$log"
done
"$py" - "$log" <<'PY'
import re, statistics, sys
cols = {}
steps = []
for line in open(sys.argv[1]):
    m = re.match(r"torch forward n=\d+ seconds=([0-9.]+)", line)
    if m:
        cols.setdefault("PyTorch forward", []).append(float(m.group(1)))
    m = re.match(r"torch train_step n=\d+ seconds=([0-9.]+)", line)
    if m:
        steps.append(float(m.group(1)))
    c = [x.strip() for x in line.split("|")]
    if len(c) > 9 and c[1].startswith("paper") and c[5] in ("stock", "fast", "fast-bf16"):
        cols.setdefault(f"ours {c[5]} forward", []).append(float(c[6]))
        cols.setdefault(f"ours {c[5]} step", []).append(float(c[8]))
cols["PyTorch step (second)"] = steps[0::2]
cols["PyTorch step (third, steady)"] = steps[1::2]
print("\n| seconds, paper network 33^3 | min-max | median |\n|---|---|---:|")
for k, v in cols.items():
    if v:
        print(f"| {k} | {min(v):.3f}-{max(v):.3f} | {statistics.median(v):.3f} |")
PY
