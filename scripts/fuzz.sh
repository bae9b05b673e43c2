#!/usr/bin/env bash
# The fuzzed-input properties with a longer budget than CI's (PROPTEST_CASES=256, the default):
# IPC payloads (ipc/tests/fuzz.rs), input files (daemon/tests/fuzz_inputs.rs) and the planner
# under arbitrary policy outputs (daemon/tests/planner_props.rs), invalid payloads mid-job
# (daemon/tests/zero_actions.rs), in the test profile (opt-level 1,
# the physics and tract at 3: the test build is reused).
#   scripts/fuzz.sh [CASES]        # default 20000 cases per property (a quarter for the
#                                  # ONNX and planner properties)
set -euo pipefail
cd "$(dirname "$0")/.."
export PROPTEST_CASES=${1:-20000}
echo "fuzz: $PROPTEST_CASES cases per property"
start=$(date +%s)
cargo test -p herb-ipc --test fuzz
cargo test -p herb-daemon --test fuzz_inputs --test planner_props --test zero_actions
echo "fuzz: done in $(( $(date +%s) - start )) s"
