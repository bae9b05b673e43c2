#!/usr/bin/env bash
# The test command (README, CI): the systemd units' check, the Rust tests of the whole
# workspace, then the Python tests (pytest): the training bindings (sim/py), the client
# (clients/python, against the herbd and herb-loopback that cargo test built) and its live view
# (Rerun; in headless Chromium when installed: .ci/run installs it), with maturin, numpy,
# gymnasium, pytest, ray and tqdm (the sweep runner, on a local Ray runtime of 2 CPUs), iceoryx2
# and rerun-sdk in a virtualenv (.venv, or $HERB_VENV).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
# The systemd units' sandbox (exposure) and the sysusers.d/tmpfiles.d files, offline.
scripts/check-units.sh
# Every test target (libraries', binaries' and integration tests), then the doc tests: the
# examples are not built here (clippy --all-targets checks that they compile). One test thread
# more than the cores: the end-to-end tests mostly wait on the arm's real-time motion (on 2
# cores, the loopback's 27 took 253 s on 2 threads and 185 s on 3).
export RUST_TEST_THREADS=${RUST_TEST_THREADS:-$(($(nproc) + 1))}
# The Python packages install while the Rust tests build (pip waits on the network, cargo on
# the cores), and are waited for before any test runs; pip's output is shown if it fails.
VENV=${HERB_VENV:-$ROOT/.venv}
pip_log=$(mktemp)
(
  set -e
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q --disable-pip-version-check maturin numpy gymnasium pytest ray tqdm
  "$VENV/bin/pip" install -q --disable-pip-version-check -e "clients/python[view]"
) >"$pip_log" 2>&1 &
pip_pid=$!
cargo test --workspace --tests --no-run
if ! wait "$pip_pid"; then
  echo "installing the Python packages into $VENV failed:" >&2
  cat "$pip_log" >&2
  exit 1
fi
cargo test --workspace --tests
cargo test --workspace --doc
(cd sim/py && VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH" maturin develop -q)
"$VENV/bin/python" -m pytest -q sim/py/tests clients/python/tests
