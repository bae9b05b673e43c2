#!/usr/bin/env bash
# Soak: herbd and herb-loopback (release) for at least 10^6 loop cycles (1,000 s at the default
# 1 kHz; SOAK_S overrides the duration), packing BoxED episodes back to back (`herbctl reset`
# empties the box between jobs). Reports herbd's cycles, deadline misses, cycle time p50/p99/max
# and wake-up jitter from its final statistics, the jobs completed, and herbd's resident memory
# and open file descriptors after each completed job (growth: last against first; a job cut
# short by the end of the run is not probed, herbd is shutting down then). Not part of CI.
# Writes results/soak.json and results/soak-*.log.
#   scripts/soak.sh                 # about 17 minutes
set -euo pipefail
cd "$(dirname "$0")/.."
DURATION=${SOAK_S:-1005}
cargo build --release -p herb-daemon -p herb-loopback --bins
mkdir -p results
P=soak$$
target/release/herb-loopback --prefix "$P" > /dev/null 2> results/soak-loopback.log &
LB=$!
trap 'kill -TERM $LB 2>/dev/null || true' EXIT
target/release/herbd --prefix "$P" --run-for "$DURATION" --stats-json results/soak-herbd.json \
  > /dev/null 2> results/soak-herbd.log &
HD=$!
probe() { # rss_kib fds of herbd
  echo "$(awk '/^VmRSS:/ {print $2}' /proc/$HD/status 2>/dev/null || echo 0) $(ls /proc/$HD/fd 2>/dev/null | wc -l)"
}
sessions=(p1_s1 p28_s2 p12_s3 p40_s1 p7_s2)
jobs_done=0; jobs_other=0; i=0; probes=""
: > results/soak-herbctl.log
while kill -0 "$HD" 2>/dev/null; do
  s=${sessions[$((i % ${#sessions[@]}))]}
  i=$((i + 1))
  if target/release/herbctl --prefix "$P" pack --session "$s" --timeout 600 >> results/soak-herbctl.log 2>&1; then
    jobs_done=$((jobs_done + 1))
    probes="$probes $(probe | tr ' ' ,)"
  else
    jobs_other=$((jobs_other + 1))
  fi
  kill -0 "$HD" 2>/dev/null || break
  target/release/herbctl --prefix "$P" reset >> results/soak-herbctl.log 2>&1 || true
done
wait "$HD" || true
python3 - "$jobs_done" "$jobs_other" $probes <<'PY'
import json, sys
done, other = int(sys.argv[1]), int(sys.argv[2])
probes = [tuple(map(int, p.split(","))) for p in sys.argv[3:]]
h = json.load(open("results/soak-herbd.json"))["herbd_final"]
out = {"cycles": h["cycles"], "deadline_misses": h["deadline_misses"],
       "cycle_us": h["cycle_us"], "jitter_us": h["jitter_us"],
       "jobs_completed": done, "jobs_not_completed": other,
       "rss_kib_after_each_job": [p[0] for p in probes],
       "fds_after_each_job": [p[1] for p in probes]}
json.dump(out, open("results/soak.json", "w"), indent=1)
print(json.dumps(out, indent=1))
PY
