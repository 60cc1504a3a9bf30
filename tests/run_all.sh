#!/usr/bin/env bash
# Everything the project checks, in order (the README's test command; CI runs it through
# .ci/run, which installs what it needs first):
#   1. the Rust tests of every crate, with the wgpu backend built in (ponq-py, the Python
#      module, is tested from Python in step 4: its library has no Rust tests);
#   2. a type-check of the CUDA backend (DOCS_RS=1: its LLVM bundler skips its download);
#   3. the README's example commands, as written (tests/readme_examples.sh);
#   4. the Python package, built into a fresh virtual environment, and its pytest suite;
#   5. no word of how the work was organised in the tracked files.
# Set PONQ_REQUIRE_PYTHON=1 to fail instead of skipping step 4 without `python3 -m venv`.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --workspace --exclude ponq-py --features ponq-train/wgpu
DOCS_RS=1 cargo check --workspace --all-targets --features ponq-train/cuda
cargo build --release --bins
tests/readme_examples.sh
if python3 -m venv --help > /dev/null 2>&1; then
  venv="$(mktemp -d)/venv"
  python3 -m venv "$venv"
  # The package builds with maturin (from PyPI) into this repository's target directory, so it
  # reuses the release build above.
  CARGO_TARGET_DIR="$PWD/target" "$venv/bin/pip" install --quiet ./ponq-py pytest
  "$venv/bin/python" -m pytest -q ponq-py/tests
elif [ "${PONQ_REQUIRE_PYTHON:-0}" = 1 ]; then
  echo "python3 with the venv module is required for the Python package's tests" >&2
  exit 1
else
  echo "skipped the Python package's tests: no python3 -m venv here"
fi
# Documentation and code speak of the project, not of the rounds of work that wrote it.
if git grep -il "sess""ion" -- . ':!Cargo.lock'; then
  echo "the files above speak of how the work was organised" >&2
  exit 1
fi
echo "all checks passed"
