#!/usr/bin/env bash
# Runs every parser's fuzz or property test at 10^5 inputs (CI runs them at fewer: see each
# test's default). Usage: bash scripts/fuzz_all.sh [CASES]
set -euo pipefail
cd "$(dirname "$0")/.."
export HYTRACE_FUZZ_CASES="${1:-100000}"
# The .npy and Foundry tests write a file per case: a RAM disk keeps them fast.
if [ -d /dev/shm ] && [ -w /dev/shm ]; then export TMPDIR=/dev/shm; fi
run() {
  echo "== $*"
  /usr/bin/time -f "   %e s, peak %M KB" cargo test -q "$@" -- --nocapture 2>&1 | grep -E "test result|panicked|took|read|rejected|   [0-9.]+ s"
}
run -p hytrace-foundry --test npy_reader
run -p hytrace-volume --test nanovdb_reader fuzzed_files_never_panic
run -p hytrace-volume --test openvdb_reader corrupt_bytes_never_panic
run -p hytrace-tests --test foundry_store random_corruption
run -p hytrace-trace --test gdml_import mutated_files
run -p hytrace-trace --test extreme_input ray_rows
# These run 10^5 inputs in CI already: scene files, GDML expressions, CSG expressions, OBJ/GLB.
run -p hytrace-trace --test extreme_input mutated_scene_files
run -p hytrace-foundry --lib fuzz_never_panics
run -p hytrace-csg --lib arbitrary_input_never_panics
run -p hytrace-trace --test mesh_scene truncated_and_mutated
