#!/usr/bin/env bash
# The chaos soak (hw/chaos, `herb-chaos`): herbd with its defaults (the search decides, real
# time, the job journal), herb-loopback and a client packing random BoxED episodes back to back
# for the given minutes (default 60), with a random fault from the whole list every 60 to 120 s,
# an observer on the bus checking the invariants all the time; writes report.md and report.json
# (and every process's log) into runs/chaos-<time>, or CHAOS_OUT. Exits non-zero on any
# violation, any fault not recovered, or a fault kind injected fewer than 3 times in a run of
# 60 minutes or more.
#
#   scripts/chaos.sh [MINUTES] [herb-chaos args...]
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES=${1:-60}
shift || true
cargo build --release -p herb-daemon -p herbctl -p herb-loopback -p herb-chaos --bins
OUT=${CHAOS_OUT:-runs/chaos-$(date -u +%Y%m%dT%H%M%SZ)}
REQUIRE=0
[ "${MINUTES%.*}" -ge 60 ] && REQUIRE=3
exec target/release/herb-chaos --minutes "$MINUTES" --bin target/release --out "$OUT" \
  --require-each "$REQUIRE" "$@"
