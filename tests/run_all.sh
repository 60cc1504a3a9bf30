#!/usr/bin/env bash
# Everything the project checks, in order (the README's test command; CI runs it through
# .ci/run, which installs what it needs first). One release build of the Burn stack serves the
# programs, the tests, the README's examples and the Python package: the workspace-hack crate
# gives every build the same features of the shared dependencies, so no step builds them again.
#   1. the programs and the Rust tests of every crate, in the release profile (ponq-py, the
#      Python module, is tested from Python in step 3: its library has no Rust tests);
#   2. the README's example commands, as written (tests/readme_examples.sh), and a dataset of
#      300 meshes of one file name prepared in 3 shards, killed and resumed
#      (tests/batch_resume.py: the unsharded run's outputs, byte for byte);
#   3. the Python package, built into a fresh virtual environment, and its pytest suite;
#   4. the wgpu tests, in the `gpu-test` profile (no optimisation: the GPU stack is minutes to
#      optimise and the tests need none of it), and the CUDA backend's type-check in the same
#      profile (DOCS_RS=1: its LLVM bundler skips its download);
#   5. no import circle between the files of a crate (tests/module_cycles.py);
#   6. no word of how the work was organised in the tracked files.
# Set PONQ_REQUIRE_PYTHON=1 to fail instead of skipping step 3 without `python3 -m venv`, and
# PONQ_REQUIRE_WGPU=1 to fail instead of skipping the wgpu tests without an adapter.
# Each step prints its time; the whole suite takes about 16 minutes from a cold start on two
# cores (docs/ci.md), about 3 when nothing needs building.
set -euo pipefail
cd "$(dirname "$0")/.."
step() {
  local name="$1"
  shift
  local t0=$SECONDS
  echo "== $name"
  "$@"
  echo "== $name: $((SECONDS - t0)) s"
}
python_tests() {
  if python3 -m venv --help > /dev/null 2>&1; then
    local venv
    venv="$(mktemp -d)/venv"
    python3 -m venv "$venv"
    # The package builds with maturin (from PyPI) into this repository's target directory, so
    # it reuses the release build above.
    CARGO_TARGET_DIR="$PWD/target" "$venv/bin/pip" install --quiet ./ponq-py pytest
    # Ray (an optional extra) for the test of the Ray example; its test is skipped, with the
    # reason printed, only where Ray cannot be installed (no wheel for this Python).
    if ! "$venv/bin/pip" install --quiet "ray>=2.9"; then
      echo "note: Ray could not be installed: the Ray example's test will be skipped"
    fi
    "$venv/bin/python" -m pytest -q -rs ponq-py/tests
  elif [ "${PONQ_REQUIRE_PYTHON:-0}" = 1 ]; then
    echo "python3 with the venv module is required for the Python package's tests" >&2
    return 1
  else
    echo "skipped the Python package's tests: no python3 -m venv here"
  fi
}
gpu_features=(--features ponq-train/wgpu,ponq-infer/wgpu)
step "programs (release)" cargo build --release --bins
step "tests (release)" cargo test --release --workspace --exclude ponq-py
step "README examples" tests/readme_examples.sh
if command -v python3 > /dev/null 2>&1; then
  step "batch resumed after kill -9" python3 tests/batch_resume.py
else
  echo "skipped the batch resume check: no python3 here"
fi
step "Python package" python_tests
# Only the tests whose names say wgpu (one per suite): the rest ran in step 1.
step "wgpu tests (gpu-test profile)" cargo test --profile gpu-test \
  -p ponq-model -p ponq-train -p ponq-infer "${gpu_features[@]}" \
  --test wgpu_backend --test wgpu_training --test infer_cli -- wgpu
step "CUDA type-check" env DOCS_RS=1 cargo check --profile gpu-test --workspace --all-targets \
  --features ponq-train/cuda
if command -v python3 > /dev/null 2>&1; then
  step "import circles" python3 tests/module_cycles.py
else
  echo "skipped the import-circle check: no python3 here"
fi
# Documentation and code speak of the project, not of the rounds of work that wrote it.
if git grep -il "sess""ion" -- . ':!Cargo.lock'; then
  echo "the files above speak of how the work was organised" >&2
  exit 1
fi
echo "all checks passed"
