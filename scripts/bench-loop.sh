#!/usr/bin/env bash
# Loop benchmark: herbd's 1 kHz loop with and without real time, idle and beside a CPU hog on
# every core, in one run. Each case starts herb-loopback and herbd (its defaults: the search
# decides) under a prefix of its own and packs a BoxED episode (p1_s1, or $HERB_BENCH_SESSION)
# for $1 seconds (default 65); herbd's own histograms give the cycle work, the wake-up jitter,
# the deadline misses and the time objects were held waiting for decisions.
#
#   scripts/bench-loop.sh [SECONDS] [CASES] [herbd args...]
#
# CASES: a comma-separated subset of rt-idle, nort-idle, rt-hog, nort-hog (default: all four,
# in that order). "rt" is herbd's default [rt] (SCHED_FIFO 80, mlockall, the CPU latency
# request); "nort" the same configuration with [rt] off. "hog": one busy-looping process per
# core at normal priority for the whole case. Writes results/loop-bench/<case>.json (herbd's
# final statistics and what real time herbd said it got) and results/loop-bench/summary.md;
# never runs a case as real time without saying whether the system granted it. BENCH_BIN
# names a folder of release binaries already built (no build then).
set -euo pipefail
cd "$(dirname "$0")/.."
DURATION=${1:-65}
CASES=${2:-rt-idle,nort-idle,rt-hog,nort-hog}
shift 2 2>/dev/null || shift $# || true
BIN=${BENCH_BIN:-target/release}
if [ -z "${BENCH_BIN:-}" ]; then
  cargo build --release -p herb-daemon -p herbctl -p herb-loopback --bins
fi
OUT=results/loop-bench
mkdir -p "$OUT"
nort=$(mktemp --suffix=.toml)
printf '[rt]\nmlockall = false\nfifo_priority = 0\ncpu_latency = false\n' > "$nort"
hogs=()
stop_hogs() { for h in "${hogs[@]}"; do kill "$h" 2>/dev/null || true; done; hogs=(); }
trap 'stop_hogs; rm -f "$nort"' EXIT

run_case() { # name [herbd args...]
  local name=$1 P=bench$$${1//-/}
  shift
  local cfg=()
  [[ $name == nort-* ]] && cfg=(--config "$nort")
  if [[ $name == *-hog ]]; then
    for _ in $(seq "$(nproc)"); do (while :; do :; done) & hogs+=($!); done
  fi
  # The time the hypervisor took the virtual CPUs away (steal, /proc/stat, in USER_HZ ticks):
  # a loop cannot run while its CPU is not there.
  local steal0
  steal0=$(awk '/^cpu / {print $9}' /proc/stat)
  "$BIN"/herb-loopback --prefix "$P" > /dev/null 2> "$OUT/$name-loopback.log" &
  local lb=$!
  "$BIN"/herbd "${cfg[@]}" --prefix "$P" --run-for "$DURATION" \
    --stats-json "$OUT/$name.stats.json" "$@" > /dev/null 2> "$OUT/$name-herbd.log" &
  local hd=$!
  "$BIN"/herbctl --prefix "$P" pack --session "${HERB_BENCH_SESSION:-p1_s1}" \
    --timeout "$DURATION" > "$OUT/$name-herbctl.log" 2>&1 &
  local ctl=$!
  wait "$hd" || true
  local stolen_ms=$(( ($(awk '/^cpu / {print $9}' /proc/stat) - steal0) * 1000 / $(getconf CLK_TCK) ))
  kill -INT "$lb" "$ctl" 2>/dev/null || true
  wait "$lb" "$ctl" 2>/dev/null || true
  stop_hogs
  # What real time herbd got: its `real_time` line, or the warning naming what was refused.
  local rt
  rt=$(grep -m1 -o 'event=real_time.*\|event=warning what="real time refused[^"]*"' \
    "$OUT/$name-herbd.log" || echo "none asked")
  python3 - "$OUT/$name.stats.json" "$name" "$rt" "$OUT/$name.json" "$stolen_ms" <<'PY'
import json, sys
stats, name, rt, out, stolen = sys.argv[1:]
h = json.load(open(stats))["herbd_final"]
json.dump({"case": name, "real_time": rt, "stolen_ms_all_cpus": int(stolen), **h},
          open(out, "w"), indent=1)
PY
  echo "$name: $(python3 -c "import json,sys; h=json.load(open(sys.argv[1])); print(f\"misses {h['deadline_misses']}/{h['cycles']}, jitter p99 {h['jitter_us']['p99']} us, cycle max {h['cycle_us']['max']} us\")" "$OUT/$name.json")"
}

for c in ${CASES//,/ }; do
  case $c in
    rt-idle|nort-idle|rt-hog|nort-hog) run_case "$c" "$@" ;;
    *) echo "bench-loop.sh: unknown case '$c' (rt-idle, nort-idle, rt-hog, nort-hog)" >&2; exit 2 ;;
  esac
done

python3 - "$OUT" ${CASES//,/ } <<'PY'
import json, sys
out, cases = sys.argv[1], sys.argv[2:]


def slow(h):
    c = h.get("slowest_cycle")
    if not c:
        return "-"
    return f"{c['minor_faults'] + c['major_faults']}, {c['blocked']}, {c['preempted']}"


rows = ["| case | real time | cycles | deadline misses | wake-up jitter p50 / p99 / max (us) | cycle work p50 / p99 / max (us) | slowest cycle: faults, blocked, preempted | CPU time stolen by the hypervisor (ms, both CPUs) | decision wait (ms) |",
        "| --- | --- | ---: | ---: | --- | --- | --- | ---: | ---: |"]
for c in cases:
    h = json.load(open(f"{out}/{c}.json"))
    j, w = h["jitter_us"], h["cycle_us"]
    pct = 100.0 * h["deadline_misses"] / max(h["cycles"], 1)
    rows.append(f"| {c} | {h['real_time']} | {h['cycles']} | {h['deadline_misses']} ({pct:.3f} %) | "
                f"{j['p50']:.1f} / {j['p99']:.1f} / {j['max']:.1f} | {w['p50']:.1f} / {w['p99']:.1f} / {w['max']:.1f} | "
                f"{slow(h)} | {h['stolen_ms_all_cpus']} | {h['decision_wait_ms']} |")
text = "\n".join(rows) + "\n"
open(f"{out}/summary.md", "w").write(text)
print(text)
PY
