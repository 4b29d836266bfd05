#!/usr/bin/env bash
# The README's "Building for the host CPU" table: the portable release build against the
# x86-64-v3 build (`cargo build-v3`) of the same commit, alternating twice.
# Usage: bash bench/host-cpu.sh > host-cpu.log   (from the repository root)
set -euo pipefail
cargo build --release -p isoray-bench
cargo build-v3 -p isoray-bench
for round in 1 2; do
  for b in target/release/isoray-bench target/x86-64-v3/release/isoray-bench; do
    echo "=== round $round $b $(date -u +%H:%M:%S) load $(cut -d' ' -f1 /proc/loadavg)"
    "$b" metaballs --packets-only --scenes pool,scattered-30k,tornado-128k,molecule --runs 3
    "$b" effects --scenes blobs,pool,molecule,surfel-impact --configs "ray cast,hard shadows" --runs 5
    "$b" surfels --scenes impact --frames 4 --runs 3 --sizes 512x384 --no-tightness \
      --configs rebuild,lazy+cache
  done
done
