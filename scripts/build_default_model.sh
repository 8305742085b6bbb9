#!/usr/bin/env bash
# Build the app's DEFAULT policy (13 actions, EfficientNet-Lite0, its last 4 blocks fine-tuned) into runs/default/.
#
# Data: PTL train (real photos, ../shared/data/ptl) + a few hundred synthetic street corners
# from `crossing-data synth` (with `unknown` frames, so the demo's synthetic clip is understood).
# Selection: fixed epoch count (--select-on last). The recipe (unfreeze 4, 8 epochs) was chosen on
# a photographer-held-out part of PTL train (ptl:heon), not on PTL val (docs/models.md).
#
# Usage: scripts/build_default_model.sh [PTL_DIR]      (run from the repository root)
set -euo pipefail
PTL=${1:-../shared/data/ptl}
PY=${PY:-.venv/bin/python}
HEAD=${HEAD:-spatial}
EPOCHS=${EPOCHS:-8}
UNFREEZE=${UNFREEZE:-4}
mkdir -p runs/data
[ -f runs/data/ptl/manifest.csv ] || $PY -m crossing_assist.data_tools.cli import-ptl "$PTL" --out runs/data/ptl --images reference --quiet
[ -f runs/data/synth/manifest.csv ] || $PY -m crossing_assist.data_tools.cli synth --out runs/data/synth --frames 300 --seed 1 \
    --unknown-fraction 0.25 --val-fraction 0.2 --quiet
rm -rf runs/default
$PY -m crossing_assist.models.cli train --data runs/data/ptl --extra-data runs/data/synth --out runs/default --backbone efficientnet_lite0 \
    --head "$HEAD" --actions 13 --epochs "$EPOCHS" --optimizer adamw --lr 1e-3 --weight-decay 1e-4 --smoothing 0.2 --aux-x 1.0 \
    --unfreeze "$UNFREEZE" --select-on last --seed 0 --threads 1 --quiet
$PY -m crossing_assist.models.cli eval --run runs/default --data runs/data/ptl --split val --threads 1 --quiet
$PY -m crossing_assist.models.cli eval --run runs/default --data runs/data/synth --split val --out runs/default/eval_synth_val --threads 1 --quiet
