#!/usr/bin/env bash
# Export the default run to the embedded default bundle (crossing_assist/assets/default_bundle/).
#
#   scripts/build_default_bundle.sh                 # runs/default -> the embedded bundle
#   RUN=runs/x OUT=/tmp/b scripts/build_default_bundle.sh
#   MEMBERS="runs/default_s1 runs/default_s2" scripts/build_default_bundle.sh   # an ensemble of three seeds
#   MIRROR=0 MAX_INT8_DROP=0.02 RUN=runs/full_s0 MEMBERS="runs/full_s1 runs/full_s2" CV_DIR=runs/res256/cv \
#       scripts/build_default_bundle.sh   # what ships since 2026-12-04 (docs/models.md)
#   GATE_TOP=16 ...   # the held-out thresholds of choose_gate.py --max-scale 16 (gate…_top16….json)
#
# MEMBERS: more runs of the same recipe (other seeds; a folder holding a bundle is taken as it is, an
# ensemble bundle as its members, e.g. the embedded default: a seed added to it), each exported as RUN
# is; the bundle is their ensemble with RUN (crossing-export ensemble: the graphs side by side, what
# they compute alike run once, their samples pooled), its gate thresholds those
# scripts/choose_gate.py --ensemble chose for the ensemble of the K CV runs (CV_DIR/gate…_ensembleK.json,
# K the members counted).
#
# The run is built by scripts/build_default_model.sh (weights/best.pt). Calibration (temperature,
# conformal threshold, gate threshold) is fitted on PTL's val split; its held-out coverage is
# measured by folds of photographers, each with a calibration fitted on the others. An int8
# bundle (static, else weights only) is kept when its accuracy on the val frames its ranges
# never saw is within 1 point of fp32's and it is not slower than fp32 here; otherwise fp32 ships.
# Provenance (command, time, checkpoint SHA-256, calibration data) lands in bundle.json.
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PY:-.venv/bin/python}
RUN=${RUN:-runs/default}
PTL=${PTL:-../shared/data/ptl}
DATA=${DATA:-runs/data/ptl}                       # PTL as a dataset (manifest.csv)
OUT=${OUT:-crossing_assist/assets/default_bundle}
SAMPLES=${SAMPLES:-16}
MIRROR=${MIRROR:-1}                             # mirror test-time augmentation in the graph (0: off)
MIRROR_ARGS=()
GATE_JSON=gate
if [ "$MIRROR" = 1 ]; then MIRROR_ARGS=(--mirror); GATE_JSON=gate_mirror; fi
VIEW_ZOOM=${VIEW_ZOOM:-1}   # > 1: portrait frames shown magnified up to it (crossing-export --view-zoom, bundle schema 4),
                            # for a run trained with --field-zoom; the gate choice is choose_gate.py --zoom's
ZOOM_ARGS=(--view-zoom "$VIEW_ZOOM")
if [ "$VIEW_ZOOM" != 1 ]; then GATE_JSON="${GATE_JSON}_zoom$VIEW_ZOOM"; fi
GATE_JSON="$GATE_JSON.json"
MAX_INT8_DROP=${MAX_INT8_DROP:-0.01}
MAX_INT8_SLOWDOWN=${MAX_INT8_SLOWDOWN:-1.10}   # int8 latency / fp32 latency, one frame, this machine
MIN_CALIB_ARGS=()   # MIN_CALIB=N: crossing-export --min-calib N (toy calibration sets only)
if [ -n "${MIN_CALIB:-}" ]; then MIN_CALIB_ARGS=(--min-calib "$MIN_CALIB"); fi

if [ ! -f "$RUN/weights/best.pt" ]; then
    echo "error: $RUN/weights/best.pt not found; run scripts/build_default_model.sh first" >&2
    exit 2
fi
if [ ! -f "$DATA/manifest.csv" ]; then
    echo "importing PTL from $PTL into $DATA (images referenced, not copied)" >&2
    "$PY" -m crossing_assist.data_tools.cli import-ptl "$PTL" --out "$DATA" --images reference --quiet
fi

# The gate thresholds, one per orientation: the fitted one times the scales chosen on held-out
# photographers (scripts/choose_gate.py over the leave-one-photographer-out folds in $RUN/cv),
# never on photographers the model trained on.
CV_DIR=${CV_DIR:-$RUN/cv}
if [ -z "${GATE_SCALE:-}" ]; then
    if [ -f "$CV_DIR/$GATE_JSON" ]; then
        GATE_SCALE=$("$PY" -c "import json,sys; print(json.load(open(sys.argv[1]))['scale'])" "$CV_DIR/$GATE_JSON")
    else
        GATE_SCALE=1.0
        echo "no $CV_DIR/$GATE_JSON (run scripts/choose_gate.py $CV_DIR ${MIRROR_ARGS[*]}): gate threshold as fitted" >&2
    fi
fi
if [ -z "${GATE_SCALE_PORTRAIT:-}" ] && [ -f "$CV_DIR/$GATE_JSON" ]; then
    GATE_SCALE_PORTRAIT=$("$PY" -c "import json,sys; print(json.load(open(sys.argv[1])).get('portrait', {}).get('scale', ''))" "$CV_DIR/$GATE_JSON")
fi
PORTRAIT_ARGS=()
if [ -n "${GATE_SCALE_PORTRAIT:-}" ]; then PORTRAIT_ARGS=(--gate-scale-portrait "$GATE_SCALE_PORTRAIT"); fi
echo "gate threshold scale: landscape $GATE_SCALE, portrait ${GATE_SCALE_PORTRAIT:-the same}" >&2
# The gate's measure: far_mass (the probability beyond one strip of the argmax) at the thresholds
# choose_gate.py --measure far_mass chose on the same held-out folds, when it has; else entropy.
GATE_MEASURE=${GATE_MEASURE:-far_mass}
STAMP_JSON=$GATE_JSON
if [ "$GATE_MEASURE" != entropy ]; then
    if [ -f "$CV_DIR/${GATE_JSON%.json}_$GATE_MEASURE.json" ]; then
        STAMP_JSON="${GATE_JSON%.json}_$GATE_MEASURE.json"
        echo "gate measure: $GATE_MEASURE, thresholds from $CV_DIR/$STAMP_JSON" >&2
    else
        echo "no $CV_DIR/${GATE_JSON%.json}_$GATE_MEASURE.json (scripts/choose_gate.py $CV_DIR ${MIRROR_ARGS[*]} --measure $GATE_MEASURE): gate on entropy" >&2
    fi
fi
# GATE_TOP=16: the thresholds of a sweep carried past x4 (choose_gate.py --max-scale 16), for a view whose
# choice sat at the old sweep's top (the narrow camera's, 2026-12-06: docs/models.md, "A sweep cut short")
GATE_TOP=${GATE_TOP:-4}
if [ "$GATE_TOP" != 4 ]; then STAMP_JSON="${STAMP_JSON%.json}_top$GATE_TOP.json"; fi

TMP=$(mktemp -d "${TMPDIR:-/tmp}/default_bundle.XXXXXX")
trap 'rm -rf "$TMP"' EXIT

# Keep the first candidate within MAX_INT8_DROP of fp32's accuracy and not slower than
# MAX_INT8_SLOWDOWN x fp32 (the demo must stay real time): static int8 (weights and
# activations), then int8 weights only (fp32 compute), else fp32. export_run RUN DEST sets SRC.
export_run() {
    local run=$1 dest=$2 mode keep
    SRC=""
    for mode in static weights; do
        "$PY" -m crossing_assist.export --run "$run" --out "$dest/$mode" --samples "$SAMPLES" "${MIRROR_ARGS[@]}" \
            --calib-data "$DATA" --calib-split val "${MIN_CALIB_ARGS[@]}" --int8 --int8-mode "$mode" --gate-scale "$GATE_SCALE" "${PORTRAIT_ARGS[@]}" \
            "${ZOOM_ARGS[@]}" --quiet
        keep=$("$PY" - "$dest/$mode/bundle.json" "$MAX_INT8_DROP" "$MAX_INT8_SLOWDOWN" <<'PYEOF'
import json, sys
m = json.load(open(sys.argv[1]))["metrics"]["int8_vs_fp32"]
drop, slow = m["accuracy_fp32"] - m["accuracy_int8"], m["ms_int8"] / m["ms_fp32"]
print("yes" if drop <= float(sys.argv[2]) and slow <= float(sys.argv[3]) else "no")
print(f"int8 ({m['mode']}) {m['accuracy_int8']:.3f} vs fp32 {m['accuracy_fp32']:.3f} on {m['n']} frames "
      f"the int8 ranges never saw, {m['ms_int8']:.1f} / {m['ms_fp32']:.1f} ms a frame, "
      f"size {m['size_int8'] / 1e6:.1f} / {m['size_fp32'] / 1e6:.1f} MB", file=sys.stderr)
PYEOF
)
        if [ "$keep" = "yes" ]; then SRC="$dest/$mode"; return; fi
        echo "int8 ($mode) loses more than $MAX_INT8_DROP accuracy or is slower than $MAX_INT8_SLOWDOWN x fp32" >&2
    done
    echo "shipping fp32" >&2
    "$PY" -m crossing_assist.export --run "$run" --out "$dest/fp32" --samples "$SAMPLES" "${MIRROR_ARGS[@]}" \
        --calib-data "$DATA" --calib-split val "${MIN_CALIB_ARGS[@]}" --gate-scale "$GATE_SCALE" "${PORTRAIT_ARGS[@]}" "${ZOOM_ARGS[@]}" --quiet
    SRC="$dest/fp32"
}
export_run "$RUN" "$TMP/m0"

MEMBERS=${MEMBERS:-}
if [ -n "$MEMBERS" ]; then
    PARTS=("$SRC")
    i=1
    for M in $MEMBERS; do
        if [ -f "$M/bundle.json" ]; then PARTS+=("$M"); else export_run "$M" "$TMP/m$i"; PARTS+=("$SRC"); fi
        i=$((i + 1))
    done
    "$PY" -m crossing_assist.export ensemble "${PARTS[@]}" --out "$TMP/ensemble" --calib-data "$DATA" --calib-split val "${MIN_CALIB_ARGS[@]}" \
        --measure "$GATE_MEASURE" --quiet
    SRC="$TMP/ensemble"
    K=$("$PY" -c "import json,sys; print(json.load(open(sys.argv[1]))['mc']['members'])" "$SRC/bundle.json")
    STAMP_JSON="${STAMP_JSON%.json}_ensemble$K.json"
    if [ -f "$CV_DIR/$STAMP_JSON" ]; then
        echo "an ensemble of $K: gate thresholds from $CV_DIR/$STAMP_JSON" >&2
    else
        echo "no $CV_DIR/$STAMP_JSON (scripts/choose_gate.py $CV_DIR --also ... --ensemble ${MIRROR_ARGS[*]} --measure $GATE_MEASURE): the ensemble's gate as fitted on val" >&2
    fi
fi

# Replace the embedded bundle in one rename (write_bundle validates and swaps atomically).
# bundle.json (and the graph's copy) also carry the leave-one-photographer-out figures.
# With a gate choice, the thresholds are re-derived from the fitted one and the scales stamped beside
# them, so the two agree even if choose_gate.py rewrote the choice while this script ran; with a
# far-mass choice, its measure and held-out thresholds replace the fitted entropy gate.
# A narrow camera (portrait frames at most NARROW_FOV degrees across, e.g. 9:16 video at ~41)
# takes the threshold chosen on the 3:4 windows (40.3-41.0 deg) when that choice met the targets
# (NARROW_FOV= for none). Keep the cut near the windows: portrait phone views at 45 deg were 0.92 %
# confidently wrong at the windows' far-mass threshold (README, "What the user hears").
NARROW_FOV=${NARROW_FOV-42}
# The camera's width, not the frame's orientation, picks the threshold (WIDE_FOV= for orientation):
# frames under WIDE_FOV degrees take the portrait one, e.g. a square frame (~53 deg, the portrait
# phone's width) or a landscape camera zoomed in, which the view crop pads to the training scale
# (docs/results.md, "Square frames, zoomed cameras").
WIDE_FOV=${WIDE_FOV-60}
RESCALE=()
if [ -f "$CV_DIR/$STAMP_JSON" ]; then
    RESCALE=(--rescale-gate)
    if [ -n "$NARROW_FOV" ] && "$PY" -c "import json,sys; sys.exit(not json.load(open(sys.argv[1])).get('portrait_window', {}).get('targets_met'))" "$CV_DIR/$STAMP_JSON"; then
        RESCALE+=(--narrow-fov "$NARROW_FOV")
    fi
fi
[ -n "$WIDE_FOV" ] && RESCALE+=(--wide-fov "$WIDE_FOV")
"$PY" scripts/stamp_bundle.py "$SRC" "$OUT" --cv "$CV_DIR" --gate-json "$STAMP_JSON" "${RESCALE[@]}"
