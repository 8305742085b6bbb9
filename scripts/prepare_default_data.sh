#!/usr/bin/env bash
# The default model's datasets under runs/data/ (idempotent): PTL imported by reference, its
# negatives (unknown views above the far kerb; every other photo kept), synthetic corners, and the same
# corners with half of those without a crossing showing a zebra look-alike (stairs, a crossing's picture).
set -euo pipefail
PTL=${1:-../shared/data/ptl}
PY=${PY:-.venv/bin/python}
mkdir -p runs/data
[ -f runs/data/ptl/manifest.csv ] || $PY -m crossing_assist.data_tools.cli import-ptl "$PTL" --out runs/data/ptl --images reference --quiet
[ -f runs/data/neg/manifest.csv ] || $PY -m crossing_assist.data_tools.cli negatives runs/data/ptl --out runs/data/neg --quiet
[ -f runs/data/neg_half/manifest.csv ] || $PY - <<'PYEOF'
from pathlib import Path
from crossing_assist.data_tools.manifest import read_manifest, write_manifest
ds = read_manifest("runs/data/neg")
out = Path("runs/data/neg_half")
out.mkdir(parents=True, exist_ok=True)
if not (out / "images").exists():
    (out / "images").symlink_to((Path("runs/data/neg") / "images").resolve())
write_manifest(out, [r for i, r in enumerate(ds.rows) if i % 2 == 0])
PYEOF
[ -f runs/data/synth/manifest.csv ] || $PY -m crossing_assist.data_tools.cli synth --out runs/data/synth --frames 600 --seed 1 \
    --unknown-fraction 0.4 --val-fraction 0.2 --quiet
[ -f runs/data/synth_look/manifest.csv ] || $PY -m crossing_assist.data_tools.cli synth --out runs/data/synth_look --frames 600 \
    --seed 1 --unknown-fraction 0.4 --lookalike-fraction 0.5 --val-fraction 0.2 --quiet
