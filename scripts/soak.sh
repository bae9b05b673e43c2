#!/usr/bin/env bash
# Soak: herbd and herb-loopback (release) packing jobs back to back (`herbctl reset` empties the
# box between jobs), then SIGTERM. Two modes:
#   scripts/soak.sh                    # for SOAK_S seconds (default 1005: 10^6 cycles at 1 kHz), BoxED episodes
#   SOAK_JOBS=100 scripts/soak.sh      # exactly that many one-object jobs (objects in turn), ~15 min
# Reports herbd's cycles, deadline misses, cycle time p50/p99/max and wake-up jitter from its
# final statistics, the jobs completed, and herbd's resident memory (VmRSS) and open file
# descriptors after each completed job. Not part of CI. Writes into a run folder
# (SOAK_OUT, default runs/soak-<time>), never over committed files: soak.json, soak-*.log.
set -euo pipefail
cd "$(dirname "$0")/.."
DURATION=${SOAK_S:-1005}
JOBS=${SOAK_JOBS:-0}
OUT=${SOAK_OUT:-runs/soak-$(date -u +%Y%m%dT%H%M%SZ)}
cargo build --release -p herb-daemon -p herbctl -p herb-loopback --bins
mkdir -p "$OUT"
P=soak$$
target/release/herb-loopback --prefix "$P" > /dev/null 2> "$OUT/soak-loopback.log" &
LB=$!
trap 'kill -TERM $LB 2>/dev/null || true' EXIT
RUN_FOR=$DURATION
[ "$JOBS" -gt 0 ] && RUN_FOR=100000
target/release/herbd --prefix "$P" --run-for "$RUN_FOR" --stats-json "$OUT/soak-herbd.json" \
  > /dev/null 2> "$OUT/soak-herbd.log" &
HD=$!
probe() { # rss_kib fds of herbd
  echo "$(awk '/^VmRSS:/ {print $2}' /proc/$HD/status 2>/dev/null || echo 0) $(ls /proc/$HD/fd 2>/dev/null | wc -l)"
}
sessions=(p1_s1 p28_s2 p12_s3 p40_s1 p7_s2)
objects=(003 005 011 004 006 007 008 010 012 013)
jobs_done=0; jobs_other=0; i=0; probes=""
: > "$OUT/soak-herbctl.log"
while kill -0 "$HD" 2>/dev/null; do
  if [ "$JOBS" -gt 0 ]; then
    [ "$jobs_done" -ge "$JOBS" ] && break
    what=(--objects "${objects[$((i % ${#objects[@]}))]}")
  else
    what=(--session "${sessions[$((i % ${#sessions[@]}))]}")
  fi
  i=$((i + 1))
  if target/release/herbctl --prefix "$P" pack "${what[@]}" --timeout 600 >> "$OUT/soak-herbctl.log" 2>&1; then
    jobs_done=$((jobs_done + 1))
    probes="$probes $(probe | tr ' ' ,)"
  else
    jobs_other=$((jobs_other + 1))
  fi
  kill -0 "$HD" 2>/dev/null || break
  target/release/herbctl --prefix "$P" reset >> "$OUT/soak-herbctl.log" 2>&1 || true
done
kill -TERM "$HD" 2>/dev/null || true
wait "$HD" || true
python3 - "$OUT" "$jobs_done" "$jobs_other" $probes <<'PY'
import json, sys
out_dir, done, other = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
probes = [tuple(map(int, p.split(","))) for p in sys.argv[4:]]
h = json.load(open(f"{out_dir}/soak-herbd.json"))["herbd_final"]
out = {"cycles": h["cycles"], "deadline_misses": h["deadline_misses"],
       "cycle_us": h["cycle_us"], "jitter_us": h["jitter_us"],
       "jobs_completed": done, "jobs_not_completed": other,
       "rss_kib_after_each_job": [p[0] for p in probes],
       "fds_after_each_job": [p[1] for p in probes]}
json.dump(out, open(f"{out_dir}/soak.json", "w"), indent=1)
print(json.dumps(out, indent=1))
PY
