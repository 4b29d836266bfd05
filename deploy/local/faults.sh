#!/usr/bin/env bash
# The longer fault run (issue 15): kill-and-restart cycles during pushes, as CI runs them
# (tests/tests/deploy/kill_cycles.rs, 3 cycles there) but with more cycles.
#
#   deploy/local/faults.sh [CYCLES [SEED]]     # default: 20 cycles, seed 15
#
# One isoray process on a fixed loopback port and its own store; a pusher adds .npy steps
# (32-640 KB) to a stored scene while two viewers stream it. Each cycle SIGKILLs the process
# at a seeded random moment (after a random number of the cycle's pushes completed, with
# more to send or in flight), restarts it on the same store and port, and checks that every
# viewer saw its connection end, reconnected and received a frame, and that every step whose
# push got a 2xx is listed with its checksum; at the end every completed step is read back
# byte for byte. It prints: faults injected, sessions recovered, completed steps lost (must
# be 0), and fails otherwise. Runs the debug build under `nice`; set CARGO_TARGET_DIR as usual.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cycles=${1:-20}
seed=${2:-15}
cd "$root"
log=$(mktemp -t isoray-faults.XXXXXX)
status=0
ISORAY_FAULT_CYCLES=$cycles ISORAY_FAULT_SEED=$seed nice -n 10 \
  cargo test -p isoray-tests --test root -- --exact \
  deploy::kill_cycles::sigkill_and_restart_cycles_during_pushes_lose_no_completed_step \
  --nocapture > "$log" 2>&1 || status=$?
if [ "$status" -ne 0 ]; then
  cat "$log" >&2
  echo "the fault run failed (log: $log)" >&2
  exit "$status"
fi
grep -E '^kill-and-restart:' "$log"
rm -f "$log"
