#!/usr/bin/env bash
# The main job: builds the release binaries, starts herb-loopback (simulated Baxter, gripper and
# camera) and herbd (the controller, placing with its configured method: BLBF by default), packs
# one BoxED episode (default p1_s1), prints progress, draws the final pack, and stops both
# processes (SIGTERM: herbd brakes, reports and exits 0). Everything it writes goes into a run
# folder (DEMO_OUT, default runs/demo-<time>), never over committed files. DEMO_BIN names a
# folder of binaries already built (the tests run this script so, with cargo test's) instead.
# Usage: scripts/demo.sh [SESSION] [herbctl pack options...]
set -euo pipefail
cd "$(dirname "$0")/.."
SESSION=${1:-p1_s1}
shift || true
BIN=${DEMO_BIN:-target/release}
if [ -z "${DEMO_BIN:-}" ]; then
  cargo build --release -p herb-daemon -p herbctl -p herb-loopback --bins
fi
OUT=${DEMO_OUT:-runs/demo-$(date -u +%Y%m%dT%H%M%SZ)}
mkdir -p "$OUT"
P=demo$$
"$BIN/herb-loopback" --prefix "$P" > "$OUT/demo-loopback.json" 2> "$OUT/demo-loopback.log" &
LB=$!
"$BIN/herbd" --prefix "$P" > "$OUT/demo-herbd.json" 2> "$OUT/demo-herbd.log" &
HD=$!
stop() {
  kill -TERM "$HD" 2>/dev/null || true
  wait "$HD" 2>/dev/null || true
  kill -TERM "$LB" 2>/dev/null || true
  wait "$LB" 2>/dev/null || true
}
trap stop EXIT
set +e
"$BIN/herbctl" --prefix "$P" pack --session "$SESSION" --picture "$OUT/pack.png" "$@"
RC=$?
set -e
stop
trap - EXIT
echo "herbd:    $(tail -1 "$OUT/demo-herbd.json")"
echo "loopback: $(tail -1 "$OUT/demo-loopback.json")"
echo "picture and logs: $OUT/"
exit $RC
