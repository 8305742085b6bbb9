"""Portrait vs landscape localisation of bundles: where the model puts the goal.

For each bundle: the argmax strip of each photo as taken and of its 3:4 portrait windows (goal
in view only; each window a narrower camera, read at its own FOV as choose_gate.py and
crossing-eval read it), as accuracy, share >= 2 strips off, bin MAE and the histogram of the
strips chosen, beside the histogram of the true strips. No decision logic: this measures the model's
placement, the input to everything else.
With ``--source`` the photos are one photographer's (bundles exported from leave-one-photographer-
out folds, so the photographer is unseen); without it, every photo of ``--split``.

    .venv/bin/python scripts/compare_portrait.py --split val default=crossing_assist/assets/default_bundle
    .venv/bin/python scripts/compare_portrait.py --source ptl:john --split train --frames 300 \\
        spatial=runs/default/cv/fold-ptl_john/bundle fine=runs/exp/cv_fine/fold-ptl_john/bundle
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from crossing_assist.data_tools.augment import portrait_views
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.geometry import window_fov
from crossing_assist.runtime.engine import Engine


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bundles", nargs="+", help="NAME=BUNDLE_DIR")
    ap.add_argument("--ptl", default="runs/data/ptl")
    ap.add_argument("--source", help="one photographer only (e.g. ptl:john, held out by the bundles' folds)")
    ap.add_argument("--split", default="val", help="split of the photos (a held-out photographer's: train)")
    ap.add_argument("--frames", type=int, default=0, help="a random sample of this many photos (0: all)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    ds = read_manifest(a.ptl)
    rows = [r for r in ds.rows if a.source in (None, r.source) and r.split == a.split and r.label != 0]
    if not rows:
        print(f"error: no labelled {a.split} photos{f' of {a.source}' if a.source else ''} in {a.ptl}", file=sys.stderr)
        return 2
    if a.frames:
        rng = np.random.default_rng(a.seed)
        rows = [rows[i] for i in sorted(rng.choice(len(rows), min(a.frames, len(rows)), replace=False))]
    views = {"landscape": [], "portrait": []}
    for r in rows:
        img = load_frame(ds.image_path(r), r.flags)
        views["landscape"].append((img, r.label, None))   # None: the camera's FOV is the bundle's landscape one
        views["portrait"] += [(w, lab, w.shape[1] / img.shape[1])
                              for w, _, lab, inside in portrait_views(img, r.far_x, r.label, 3) if inside]
    print(f"{a.source or a.split}: {len(rows)} photos, {len(views['portrait'])} portrait windows with the goal in view")
    for view, frames in views.items():
        print(f"  {'truth':>10} {view:>9}: strips {np.bincount([lab for _, lab, _ in frames], minlength=13)[1:].tolist()}")
    for spec in a.bundles:
        name, _, path = spec.partition("=")
        eng = Engine(path, threads=1)
        for view, frames in views.items():
            # a window of a fraction of the photo's width sees that part of the training camera's FOV
            pred = np.array([eng.predict(f, None if frac is None else window_fov(frac, eng.bundle.geometry.train_fov_deg)).action
                             for f, _, frac in frames])
            lab = np.array([lab for _, lab, _ in frames])
            err = np.abs(pred - lab)
            hist = np.bincount(pred, minlength=13)
            print(f"  {name:>10} {view:>9}: accuracy {np.mean(err == 0):.3f}, >= 2 strips off {np.mean(err >= 2):.3f}, "
                  f"bin MAE {err.mean():.3f}, unknown {hist[0]}, strips chosen {hist[1:].tolist()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
