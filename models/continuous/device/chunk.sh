#!/usr/bin/env bash
# One training chunk on the accelerator machine (run there by the device tool, in the copy of
# the repository, with .whl, .data and runs/<setting> carried). Installs the wheels into a
# temporary site dir, unpacks the meshes, trains ~8 minutes from the last checkpoint, and
# copies the checkpoint, the exported policy and the progress into $OUT.
# Usage: models/continuous/device/chunk.sh <setting> [minutes]   (setting: cs06, cs09, simple, c, cs06-random)
set -euo pipefail
SETTING=$1
MINUTES=${2:-8}
SITE=$(mktemp -d)
python3 -m pip install -q --no-index --no-deps --target "$SITE" .whl/*.whl
export PYTHONPATH="$SITE" PYTHONUNBUFFERED=1
mkdir -p .data/boxed && tar xzf .data/meshes.tgz -C .data/boxed
python3 models/continuous/train.py --config "models/continuous/configs/$SETTING.toml" --out "runs/$SETTING" \
  --boxed .data/boxed --minutes "$MINUTES"
mkdir -p "$OUT/$SETTING"
cp runs/"$SETTING"/{checkpoint-actor.pt,checkpoint-critic.pt,checkpoint-critic-adam.pt,policy.onnx,policy.parity.bin,policy.parity.json,progress.csv} "$OUT/$SETTING/"
