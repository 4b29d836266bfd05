#!/usr/bin/env bash
# Runs every fuzz target for SECONDS (default 600) one after another with cargo-fuzz
# (nightly; `cargo install cargo-fuzz` once), from seeds written by NumPy and meshio
# (seeds.py; ISORAY_PYTHON names a Python with both). A crash stops the run and leaves the
# input in fuzz/artifacts/<target>/: turn it into a regression test of the code it broke,
# next to that code's other tests, so the ordinary suite replays it forever.
#   fuzz/run.sh [SECONDS] [TARGET...]
set -euo pipefail
cd "$(dirname "$0")"
seconds=${1:-600}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(ws_message npy_step raw_step tet_mesh vtk_file points_file surfel_file surfel_scene surfel_step scene_spec)
"${ISORAY_PYTHON:-python3}" seeds.py corpus
for t in "${targets[@]}"; do
  echo "== $t for ${seconds}s"
  # -timeout: an input that takes over 10 s is reported as a hang; -rss_limit_mb: a leak or
  # an allocation bomb is a failure too.
  cargo +nightly fuzz run "$t" "corpus/$t" -- -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -max_len=1048576 -print_final_stats=1 2>&1 | tail -n 25
done
