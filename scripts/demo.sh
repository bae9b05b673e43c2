#!/usr/bin/env bash
# The main job: builds the release binaries, starts herb-loopback (simulated Baxter, gripper and
# camera) and herbd (the controller), packs one BoxED episode (default p1_s1) with the shipped
# policy, prints progress, writes results/pack.png (the final heightmap of the box), and stops
# both processes (SIGTERM: herbd brakes, reports and exits 0).
# Usage: scripts/demo.sh [SESSION] [herbctl pack options...]
set -euo pipefail
cd "$(dirname "$0")/.."
SESSION=${1:-p1_s1}
shift || true
cargo build --release -p herb-daemon -p herbctl -p herb-loopback --bins
mkdir -p results
P=demo$$
target/release/herb-loopback --prefix "$P" > results/demo-loopback.json 2> results/demo-loopback.log &
LB=$!
target/release/herbd --prefix "$P" > results/demo-herbd.json 2> results/demo-herbd.log &
HD=$!
stop() {
  kill -TERM "$HD" 2>/dev/null || true
  wait "$HD" 2>/dev/null || true
  kill -TERM "$LB" 2>/dev/null || true
  wait "$LB" 2>/dev/null || true
}
trap stop EXIT
set +e
target/release/herbctl --prefix "$P" pack --session "$SESSION" --picture results/pack.png "$@"
RC=$?
set -e
stop
trap - EXIT
echo "herbd:    $(tail -1 results/demo-herbd.json)"
echo "loopback: $(tail -1 results/demo-loopback.json)"
echo "logs: results/demo-herbd.log, results/demo-loopback.log"
exit $RC
