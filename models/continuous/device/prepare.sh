#!/usr/bin/env bash
# Prepares a training run on the accelerator machine (../shared/TRAINING.md), here:
# - .whl/: the herb_sim abi3 wheel (stripped, ~7 MB) and the pure-Python wheels the trainer
#   needs that the machine lacks (gymnasium and its dependencies), for CPython 3.12;
# - .data/meshes.tgz: the BoxED object meshes (~9 MB compressed), unpacked there by chunk.sh.
# Both folders are git-ignored; name them in the device tool's `carry` together with the run
# folder (runs/<setting>) holding the checkpoints.
set -euo pipefail
cd "$(dirname "$0")/../../.."
VENV=${HERB_VENV:-$PWD/.venv}
[ -x "$VENV/bin/maturin" ] || { python3 -m venv "$VENV"; "$VENV/bin/pip" install -q maturin; }
rm -rf .whl && mkdir -p .whl .data
(cd sim/py && "$VENV/bin/maturin" build --release --strip -o ../../.whl)
"$VENV/bin/pip" download -q --no-deps --only-binary=:all: --python-version 3.12 -d .whl \
  gymnasium cloudpickle farama-notifications typing-extensions
BOXED=${HERB_BOXED:-../shared/boxed}
tar czf .data/meshes.tgz -C "$BOXED" meshes
du -sh .whl .data
