#!/usr/bin/env bash
# The GPU path checked and timed on a machine with a GPU, in one go (about 8 minutes):
#   1. the network on the GPU against the CPU (outputs and every parameter's gradient, the
#      `wgpu_backend` test), and a short training run on both (the `wgpu_training` test);
#   2. `ponq-infer` on the shipped example on the CPU and on the GPU (vertex / face counts, times);
#   3. the network's forward and training step on the GPU (`train_bench --backend B`) beside
#      the same network in PyTorch on the same GPU (`torch_gpu.py`, CUDA), where PyTorch exists;
#   4. real training epochs (`ponq-train`, the shipped recipe `configs/cpu-w64.toml` and the
#      paper's `configs/phase1.toml`, on freshly generated shapes) on the GPU and on the CPU.
#
#   ponq-train/benches/gpu_check.sh BIN OUT [BACKEND] [SHAPES]
#
# BIN holds release builds made with `--features wgpu` (or `cuda`): ponq-train, ponq-infer,
# train_bench and the test binaries wgpu_backend and wgpu_training (the last three are what
# `cargo bench --no-run` / `cargo test --release --no-run` print; the tests look for this
# repository where it was built, at their CARGO_MANIFEST_DIR). BACKEND: wgpu (default) or
# cuda. SHAPES: procedural shapes generated for step 4 (default 64). Every step has its own
# time limit and a failed step does not stop the others; a step whose binaries are not in BIN
# is skipped (so that the steps can run in separate calls); OUT gets the logs and metrics.
set -u
cd "$(dirname "$0")/../.."
bin=$(realpath "$1")
out=$(realpath "$2")
be=${3:-wgpu}
shapes=${4:-64}
mkdir -p "$out"
t0=$(date +%s)
stamp() { echo "== [$(($(date +%s) - t0)) s] $*"; }
secs() { # seconds taken by the command
  local s
  s=$(date +%s.%N)
  "$@"
  local rc=$?
  echo "wall $(awk "BEGIN { printf \"%.2f\", $(date +%s.%N) - $s }") s (exit $rc): $*"
}

have() { # have NAME...: all in BIN, else say which step is skipped
  for n in "$@"; do
    if [ ! -x "$bin/$n" ]; then
      echo "skipped: no $bin/$n"
      return 1
    fi
  done
}

stamp "machine"
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv 2>&1
nproc
grep -m1 "model name" /proc/cpuinfo

stamp "1. the network on the GPU against the CPU"
have wgpu_backend && (cd ponq-model && PONQ_REQUIRE_WGPU=1 timeout 240 "$bin/wgpu_backend" \
  --test-threads 1 2>&1 | tail -15)
have wgpu_training && (cd ponq-train && PONQ_REQUIRE_WGPU=1 timeout 180 "$bin/wgpu_training" 2>&1 |
  tail -8)

stamp "2. ponq-infer on examples/csg_sdf_33.npy"
meshes=$(mktemp -d)
have ponq-infer && for b in flex "$be" "$be"; do
  secs timeout 120 "$bin/ponq-infer" examples/csg_sdf_33.npy -o "$meshes/$b.obj" \
    --backend "$b" 2>&1 | tail -6
  echo "$b: $(grep -c '^v ' "$meshes/$b.obj") vertices, $(grep -c '^f ' "$meshes/$b.obj") faces"
done

stamp "3. the network's forward and training step: ours ($be) and PyTorch (CUDA)"
have train_bench && timeout 300 "$bin/train_bench" 5 --backend "$be" 2>&1 |
  tee "$out/train_bench.md"
if ! have train_bench; then
  :
elif python3 -c "import torch; assert torch.cuda.is_available()" 2>/dev/null; then
  py=ponq-train/benches/torch_gpu.py
  timeout 60 python3 "$py" --batch 1 2>&1 | tail -1
  timeout 60 python3 "$py" --batch 16 2>&1 | tail -1
  timeout 60 python3 "$py" --width 32 --enc 4 --grid 16 --batch 1 2>&1 | tail -1
  timeout 60 python3 "$py" --width 32 --enc 4 --grid 16 --batch 8 2>&1 | tail -1
  timeout 60 python3 "$py" --width 48 --enc 4 --grid 16 --batch 8 2>&1 | tail -1
  timeout 60 python3 "$py" --width 64 --enc 4 --grid 16 --batch 8 2>&1 | tail -1
else
  echo "no PyTorch with CUDA here: no reference timings"
fi

stamp "4. training epochs on $shapes generated shapes"
if ! have ponq-train; then
  stamp "done"
  exit 0
fi
data=$(mktemp -d)
# The recipes with their data folder, shape count and validation changed (validation every
# 5 epochs on 4 shapes, no meshed validation: the epochs time the training itself).
recipe() { # recipe SOURCE TARGET
  sed -e "s|^dir = .*|dir = \"$data\"|" \
    -e "s|^synth_count = .*|synth_count = $shapes|" \
    -e "s|^synth_samples = .*|synth_samples = 100000|" \
    -e "s|^validation_shapes = .*|validation_shapes = 4|" \
    -e "s|^samples_per_shape = .*|samples_per_shape = 100000|" \
    -e "s|^validate_every = .*|validate_every = 5|" \
    -e "s|^mesh_validate_every = .*|mesh_validate_every = 0|" \
    -e "s|^extra_resolutions = .*|extra_resolutions = [64]|" "$1" >"$2"
}
recipe configs/cpu-w64.toml configs/gpu-check-w64.toml
recipe configs/phase1.toml configs/gpu-check-phase1.toml
# crops draw 16,000 samples per shape in the shipped recipe
sed -i "s|^samples_per_shape = .*|samples_per_shape = 16000|" configs/gpu-check-w64.toml
# The first run generates the shapes (its wall time less its epochs' is the generation's).
run() { # run NAME CONFIG BACKEND MINUTES
  secs timeout 300 "$bin/ponq-train" --config "$2" --out "$data-$1" --backend "$3" \
    --time-limit "$4" --quiet 2>&1 | tail -3
  cp "$data-$1/metrics.csv" "$out/metrics-$1.csv" 2>/dev/null &&
    awk -F, 'NR == 2 { e1 = $3; s1 = $2 } NR > 1 { n = $1; st = $2; t = $3 }
      END { if (n > 1) printf "%s: epoch 1 %.1f s; epochs 2-%d: %.3f s per step, %d steps in %.1f s\n",
        "'"$1"'", e1, n, (t - e1) / (st - s1), st - s1, t - e1 }' "$out/metrics-$1.csv"
}
run w64-$be configs/gpu-check-w64.toml "$be" 1.2
run w64-flex configs/gpu-check-w64.toml flex 1.0
run phase1-$be configs/gpu-check-phase1.toml "$be" 1.2
rm -f configs/gpu-check-w64.toml configs/gpu-check-phase1.toml
stamp "done"
