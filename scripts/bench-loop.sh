#!/usr/bin/env bash
# Loop benchmark: herbd at 1 kHz for 65 s (or $1 s) with herb-loopback running and a pack job
# in progress; prints herbd's final statistics (cycle time, wake-up jitter, deadline misses,
# decision latency; p50/p99/max) and writes them to results/loop-bench.json.
# Extra arguments after the duration go to herbd (e.g. --spin-us 0).
set -euo pipefail
cd "$(dirname "$0")/.."
DURATION=${1:-65}
shift || true
cargo build --release -p herb-daemon -p herbctl -p herb-loopback --bins
mkdir -p results
P=bench$$
target/release/herb-loopback --prefix "$P" > /dev/null 2> results/loop-bench-loopback.log &
LB=$!
trap 'kill -INT $LB 2>/dev/null || true' EXIT
target/release/herbd --prefix "$P" --run-for "$DURATION" --stats-json results/loop-bench.json "$@" \
  > /dev/null 2> results/loop-bench.log &
HD=$!
target/release/herbctl --prefix "$P" pack --session "${HERB_BENCH_SESSION:-p1_s1}" --timeout "$DURATION" \
  > results/loop-bench-herbctl.log 2>&1 || true &
wait $HD
cat results/loop-bench.json
