"""Portrait vs landscape localisation of bundles on one held-out photographer's photos.

For each bundle (exported from a leave-one-photographer-out fold, so the photographer is
unseen): the argmax strip of each photo as taken and of its 3:4 portrait windows (goal in view
only), as accuracy, share >= 2 strips off, bin MAE and the histogram of the strips chosen.
No decision logic: this measures the model's placement, the input to everything else.

    .venv/bin/python scripts/compare_portrait.py --source ptl:john --frames 300 \\
        spatial=runs/default/cv/fold-ptl_john/bundle fine=runs/exp/cv_fine/fold-ptl_john/bundle
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from crossing_assist.data_tools.augment import portrait_views
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.runtime.engine import Engine


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bundles", nargs="+", help="NAME=BUNDLE_DIR")
    ap.add_argument("--ptl", default="runs/data/ptl")
    ap.add_argument("--source", required=True, help="the held-out photographer (e.g. ptl:john)")
    ap.add_argument("--split", default="train", help="their photos the fold never saw (train: PTL's train split)")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    ds = read_manifest(a.ptl)
    rows = [r for r in ds.rows if r.source == a.source and r.split == a.split and r.label != 0]
    if not rows:
        print(f"error: no labelled {a.split} photos of {a.source} in {a.ptl}", file=sys.stderr)
        return 2
    rng = np.random.default_rng(a.seed)
    rows = [rows[i] for i in sorted(rng.choice(len(rows), min(a.frames, len(rows)), replace=False))]
    views = {"landscape": [], "portrait": []}
    for r in rows:
        img = load_frame(ds.image_path(r), r.flags)
        views["landscape"].append((img, r.label))
        views["portrait"] += [(w, lab) for w, _, lab, inside in portrait_views(img, r.far_x, r.label, 3) if inside]
    print(f"{a.source}: {len(rows)} photos, {len(views['portrait'])} portrait windows with the goal in view")
    for spec in a.bundles:
        name, _, path = spec.partition("=")
        eng = Engine(path, threads=1)
        for view, frames in views.items():
            pred = np.array([eng.predict(f).action for f, _ in frames])
            lab = np.array([lab for _, lab in frames])
            err = np.abs(pred - lab)
            hist = np.bincount(pred, minlength=13)
            print(f"  {name:>10} {view:>9}: accuracy {np.mean(err == 0):.3f}, >= 2 strips off {np.mean(err >= 2):.3f}, "
                  f"bin MAE {err.mean():.3f}, unknown {hist[0]}, strips chosen {hist[1:].tolist()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
