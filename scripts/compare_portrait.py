"""Portrait vs landscape localisation of bundles: where the model puts the goal.

For each bundle: the argmax strip of each photo as taken, of its 3:4 portrait windows (a narrower
camera) and of the views of a phone held in portrait at the bundle's portrait FOV (goal in view
only; each view read at its own FOV, as choose_gate.py and crossing-eval read it), as accuracy,
share >= 2 strips off, bin MAE and the histogram of the strips chosen, beside the histogram of the
true strips, and the placement's error in degrees (the chosen strip's centre read at the view's
FOV, against the labelled far point). For the portrait views also the photo's own placement
carried into each view (``x' = (x - x0) / w'``, from the argmax strip's centre, and refined by the
probabilities of the strips beside it): what a view would score if it placed the goal, in
degrees, as well as the whole photo does, i.e. how much of its lower accuracy is its strips being
narrower. No decision logic: this measures the model's placement, the input to everything else.
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

from crossing_assist.actions import DEFAULT_FOV_DEG, N_BINS, UNKNOWN, bin_center_x, get_space, heading_to_x, x_to_heading
from crossing_assist.bundle import read_bundle
from crossing_assist.data_tools.augment import phone_views, portrait_views
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.geometry import window_fov
from crossing_assist.runtime.belief import belief_heading
from crossing_assist.runtime.engine import Engine

_STRIPS = get_space(N_BINS + 1)


def placed_x(probs: np.ndarray, refine: bool) -> float:
    """Where ``probs`` (unknown first, then the strips left to right) put the goal, as a fraction of
    the frame's width, unknown left aside: the most likely strip's centre, or with ``refine`` the
    place the runtime plays (:func:`~crossing_assist.runtime.belief.belief_heading`: the mean of
    that strip's and its neighbours' centres weighted by their probabilities)."""
    p = np.asarray(probs, dtype=np.float64).copy()
    p[UNKNOWN] = 0.0
    if not refine:
        return bin_center_x(int(np.argmax(p)))
    _, heading = belief_heading(p, _STRIPS, DEFAULT_FOV_DEG)   # any FOV: read back at the same one
    return heading_to_x(heading, DEFAULT_FOV_DEG)


def carried_bin(x: float, x0: float, width: float) -> int:
    """The strip of a window (left edge ``x0``, ``width``; fractions of the photo's width) that a
    place ``x`` on the photo falls in; a place beyond the window's edge is its edge strip."""
    return int(np.clip(np.floor((x - x0) / width * N_BINS), 0, N_BINS - 1)) + 1


def in_view(views: list, photo_width: int) -> list[tuple]:
    """The views (``portrait_views`` / ``phone_views`` tuples, in their order) whose goal is in
    view, each as (view, bin, x in it, its left edge, its width), the last two fractions of the
    photo's width; the views are cut at offsets spread evenly from the photo's left to its right edge."""
    out = []
    for k, (view, x, lab, inside) in enumerate(views):
        cw = view.shape[1]   # the photo's columns it shows (a phone's view adds rows, not columns)
        if inside:
            out.append((view, lab, x, round(k / max(1, len(views) - 1) * (photo_width - cw)) / photo_width, cw / photo_width))
    return out


def _summary(name: str, view: str, pred: np.ndarray, lab: np.ndarray, deg: np.ndarray | None = None) -> str:
    err = np.abs(pred - lab)
    line = f"  {name:>10} {view:>9}: accuracy {np.mean(err == 0):.3f}, >= 2 strips off {np.mean(err >= 2):.3f}, bin MAE {err.mean():.3f}"
    if deg is not None and len(deg):
        line += f", degrees off mean {deg.mean():.2f} / median {np.median(deg):.2f} / p90 {np.percentile(deg, 90):.2f} (n {len(deg)})"
    return line


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
    geometry = read_bundle(a.bundles[0].partition("=")[2]).geometry   # the views are cut for the first bundle's camera
    train_fov, phone_fov = geometry.train_fov_deg, geometry.camera_fov_deg[1]
    photos = []   # (image, bin, far x)
    cuts = {"window": [], "phone": []}   # (view, bin, x in it, photo, left edge, width; fractions of the photo's width)
    for i, r in enumerate(rows):
        img = load_frame(ds.image_path(r), r.flags)
        photos.append((img, r.label, r.far_x))
        for kind, views in (("window", portrait_views(img, r.far_x, r.label, 3)),
                            ("phone", phone_views(img, r.far_x, r.label, 3, fov_deg=phone_fov, train_fov_deg=train_fov))):
            cuts[kind] += [(v, lab, x, i, x0, frac) for v, lab, x, x0, frac in in_view(views, img.shape[1])]
    print(f"{a.source or a.split}: {len(rows)} photos; goal in view: {len(cuts['window'])} 3:4 windows, "
          f"{len(cuts['phone'])} views of a phone held in portrait ({phone_fov:g} deg)")
    print(f"  {'truth':>10} {'landscape':>9}: strips {np.bincount([p[1] for p in photos], minlength=13)[1:].tolist()}")
    for kind, views in cuts.items():
        print(f"  {'truth':>10} {kind:>9}: strips {np.bincount([v[1] for v in views], minlength=13)[1:].tolist()}")
    for spec in a.bundles:
        name, _, path = spec.partition("=")
        eng = Engine(path, threads=1)
        # a view of a fraction of the photo's width sees that part of the training camera's FOV
        views = {"landscape": [(img, lab, x, train_fov) for img, lab, x in photos]}
        views.update({kind: [(v, lab, x, window_fov(frac, train_fov)) for v, lab, x, _, _, frac in vs]
                      for kind, vs in cuts.items()})
        probs = {}
        for view, frames in views.items():
            probs[view] = np.array([eng.predict(f, fov).probs for f, _, _, fov in frames])
            pred = probs[view].argmax(axis=1)
            lab = np.array([lab for _, lab, _, _ in frames])
            deg = np.array([abs(x_to_heading(bin_center_x(p), fov) - x_to_heading(x, fov))
                            for p, (_, _, x, fov) in zip(pred, frames) if x is not None and p != UNKNOWN])
            hist = np.bincount(pred, minlength=13)
            print(_summary(name, view, pred, lab, deg) + f", unknown {hist[0]}, strips chosen {hist[1:].tolist()}")
        for kind, vs in cuts.items():
            lab = np.array([v[1] for v in vs])
            for refine, how in ((False, "carried"), (True, "refined")):
                pred = np.array([carried_bin(placed_x(probs["landscape"][i], refine), x0, frac) for *_, i, x0, frac in vs])
                print(_summary(name, f"{kind} {how}", pred, lab) + f"  (the photo's placement carried into each {kind} view)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
