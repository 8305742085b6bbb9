"""Leave-one-photographer-out figures of what ships: each fold's *bundle* on all its held-out photos.

``crossing-train --cv source`` scores each fold's checkpoint (one deterministic pass, no test-time
augmentation). A user hears the exported bundle instead: int8, MC dropout in one pass, temperature
and, with ``--mirror``, mirror test-time augmentation in the graph. This script exports each fold
once (as ``scripts/choose_gate.py`` does, calibrated on PTL val without the held-out photographer),
runs it through the runtime's engine on every photo of the photographer the fold never trained on
(the model's argmax, no decision logic), and prints accuracy, bin MAE and far-x error per fold and
their mean +- sd over folds, beside the checkpoint's figures from ``cv.json``. Writes
``CV/cv_bundles{_mirror}.json``.

    .venv/bin/python scripts/cv_bundles.py runs/default/cv --mirror
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from crossing_assist.data_tools.manifest import atomic_write_text, read_manifest
from crossing_assist.models.crossval import fold_stats
from crossing_assist.models.metrics import compute_metrics

sys.path.insert(0, str(Path(__file__).resolve().parent))
from choose_gate import finished_folds, held_out_parser, held_out_rows, tag  # noqa: E402  (sibling scripts)
from gate_scores import fold_outputs  # noqa: E402

ALL = 100_000   # more photos than any photographer has: every held-out photo
METRICS = ("accuracy", "bin_mae", "far_x_error")


def fold_metrics(out: dict, far_x: list[float | None]) -> dict:
    """Accuracy, bin MAE and far-x error over the frames with a crossing (a failed inference counts
    as wrong: probability 1 on ``unknown``)."""
    labels = np.asarray(out["labels"])
    pos = labels != 0
    width = next(len(p) for p in out["probs"] if p is not None)
    probs = np.asarray([p if p is not None else [1.0] + [0.0] * (width - 1) for p in out["probs"]], float)[pos]
    fx = np.asarray([np.nan if x is None else x for x in far_x], float)
    m = compute_metrics(probs, labels[pos], width, fx)
    return {"n": int(pos.sum()), "failed": int(sum(p is None for p in out["probs"])),
            **{k: m[k] for k in METRICS}}


def main(argv=None) -> int:
    ap = held_out_parser(__doc__.split("\n\n")[0], frames=ALL)
    a = ap.parse_args(argv)
    ptl, neg = read_manifest(a.ptl), read_manifest(a.neg)
    used = {r.image for r in read_manifest(a.used_neg).rows}
    folds = []
    for fold, source in finished_folds(a.cv):
        print(f"fold {source}", file=sys.stderr, flush=True)
        pos, _ = held_out_rows(ptl, neg, source, used, a.frames, a.seed)
        out = fold_outputs(fold, source, ptl, neg, used, a.frames, a.seed, a.mirror)
        folds.append({"source": source, **fold_metrics(out, [r.far_x for r in pos])})
    if not folds:
        print(f"error: no finished fold in {a.cv}", file=sys.stderr)
        return 2
    ckpt = json.loads((a.cv / "cv.json").read_text()) if (a.cv / "cv.json").is_file() else {}
    ck_acc = {f.get("source"): f.get("accuracy") for f in ckpt.get("folds", [])}
    print(f"{'held out':<12} {'n':>5} {'bundle acc':>10} {'bin MAE':>8} {'far-x':>7}   {'checkpoint acc':>14}")
    for m in folds:
        ck = ck_acc.get(m["source"])
        print(f"{m['source']:<12} {m['n']:>5} {m['accuracy']:>10.3f} {m['bin_mae']:>8.3f} {m['far_x_error']:>7.4f}   "
              f"{'' if ck is None else f'{ck:.3f}':>14}")
    summary = fold_stats(folds, METRICS)
    print(f"bundle{' (mirror TTA)' if a.mirror else ''} over {len(folds)} folds: "
          + ", ".join(f"{k.replace('_', ' ')} {v['mean']:.4g} +- {v['sd'] or 0:.2g}" for k, v in summary.items()))
    atomic_write_text(a.cv / f"cv_bundles{tag(a.mirror)}.json", json.dumps({"folds": folds, **summary}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
