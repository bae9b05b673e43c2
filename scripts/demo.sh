#!/usr/bin/env bash
# The main job: builds the release binaries, starts herb-loopback (simulated Baxter, gripper and
# camera) and herbd (the controller, placing with its configured method: by default the search in
# the job's twin, 1 s a decision, hidden behind the pick), packs
# one BoxED episode (default p1_s1), prints progress, draws the final pack, and stops both
# processes (SIGTERM: herbd brakes, reports and exits 0). Everything it writes goes into a run
# folder (DEMO_OUT, default runs/demo-<time>), never over committed files. DEMO_BIN names a
# folder of binaries already built (the tests run this script so, with cargo test's) instead.
# DEMO_DECISION=policy makes herbd place with its policy alone ([decision] method = "policy":
# BLBF); DEMO_DECISION=search-heightmap searches in the twin built from the heightmap alone
# ([decision] twin = "heightmap"); DEMO_DECISION=search (or search-job) is the default.
# DEMO_VIEW=web also serves the live 3D view (python -m herb_client.view) on localhost:9090 and
# opens it in a browser; DEMO_VIEW=save records it into the run folder (job.rrd) instead. The
# view needs the Python client with Rerun: the test command's virtualenv (.venv, or HERB_VENV),
# or `pip install -e 'clients/python[view]'`.
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
HERBD_ARGS=()
case "${DEMO_DECISION:-}" in
  "" | search | search-job) ;;
  policy)
    printf '[decision]\nmethod = "policy"\n' > "$OUT/herbd.toml"
    HERBD_ARGS=(--config "$OUT/herbd.toml")
    ;;
  search-heightmap)
    printf '[decision]\nmethod = "search"\ntwin = "heightmap"\n' > "$OUT/herbd.toml"
    HERBD_ARGS=(--config "$OUT/herbd.toml")
    ;;
  *) echo "DEMO_DECISION=$DEMO_DECISION: expected search, search-job, search-heightmap or policy" >&2; exit 2 ;;
esac
"$BIN/herbd" --prefix "$P" "${HERBD_ARGS[@]}" > "$OUT/demo-herbd.json" 2> "$OUT/demo-herbd.log" &
HD=$!
VIEW=
if [ -n "${DEMO_VIEW:-}" ]; then
  PY=${HERB_VENV:-.venv}/bin/python
  [ -x "$PY" ] || PY=python3
  case "$DEMO_VIEW" in
    web) VIEW_ARGS=() ;;
    save) VIEW_ARGS=(--save "$OUT/job.rrd" --until-job-end) ;;
    *) echo "DEMO_VIEW=$DEMO_VIEW: expected web or save" >&2; exit 2 ;;
  esac
  HERB_BIN_DIR="$BIN" "$PY" -m herb_client.view --prefix "$P" "${HERBD_ARGS[@]}" "${VIEW_ARGS[@]}" > "$OUT/view.log" 2>&1 &
  VIEW=$!
  sleep 3
  grep -h "viewer:" "$OUT/view.log" || true
fi
stop() {
  # A recording ends with the job (the view stops by itself).
  if [ -n "$VIEW" ] && [ "${DEMO_VIEW:-}" = save ]; then wait "$VIEW" 2>/dev/null || true; fi
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
[ "${DEMO_VIEW:-}" = save ] && echo "recording: $OUT/job.rrd (open it with: rerun $OUT/job.rrd)"
echo "picture and logs: $OUT/"
if [ -n "$VIEW" ] && [ "${DEMO_VIEW:-}" = web ]; then
  echo "the view keeps serving the job: $(grep -ho 'http://[^ ]*' "$OUT/view.log" | head -1) (Ctrl-C ends it)"
  wait "$VIEW" 2>/dev/null || true
fi
exit $RC
