#!/usr/bin/env bash
# Runs, as written, every command line of the README's ```sh blocks that follow a line
# `<!-- example -->`, from the repository root, and removes the files they wrote. Exits non-zero
# at the first command that fails. Usage: tests/readme_examples.sh [README]
set -euo pipefail
cd "$(dirname "$0")/.."
readme="${1:-README.md}"
[ -f "$readme" ] || { echo "no $readme" >&2; exit 2; }
# The example command lines (comments and blank lines dropped), one per line.
commands=$(awk '
  /^<!-- example -->[[:space:]]*$/ { want = 1; next }
  /^```sh[[:space:]]*$/ { if (want) { inblock = 1 }; want = 0; next }
  /^```[[:space:]]*$/ { inblock = 0; next }
  inblock && !/^[[:space:]]*(#|$)/ { print }
' "$readme")
if [ -z "$commands" ]; then
  echo "no example block in $readme" >&2
  exit 2
fi
before=$(mktemp)
trap 'rm -f "$before"' EXIT
git ls-files --others --directory --no-empty-directory | sort > "$before"
cleanup() {
  # Remove what the examples wrote: paths untracked now that were not before and that the
  # commands name (a file written meanwhile by anyone else, a new source file, is kept).
  git ls-files --others --directory --no-empty-directory | sort | comm -13 "$before" - |
    grep -v '^target/$' | while IFS= read -r p; do
      if grep -qwF -- "${p%/}" <<< "$commands"; then rm -rf -- "$p"; fi
    done
}
trap 'cleanup; rm -f "$before"' EXIT
n=0
while IFS= read -r line; do
  n=$((n + 1))
  t0=$(date +%s.%N)
  if ! bash -euo pipefail -c "$line" > /tmp/readme_example_$$.log 2>&1; then
    echo "[$n] $line"
    cat /tmp/readme_example_$$.log
    rm -f /tmp/readme_example_$$.log
    echo "README example failed: $line" >&2
    exit 1
  fi
  # Each command with its time (seconds), so that a slow example shows in CI's log.
  echo "[$n] $(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f s", b - a }')  $line"
done <<< "$commands"
rm -f /tmp/readme_example_$$.log
echo "all $n README example commands ran"
