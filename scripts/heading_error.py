"""Heading error in degrees on held-out photographers, per view: is a portrait phone placed worse,
or are its strips only narrower?

Strip accuracy does not compare cameras: a strip of the 67 deg training camera is 5.6 deg wide, of a
53 deg portrait phone 4.4 deg, of a 3:4 window of a photo (41 deg) 3.4 deg, so the same angular
error is more strips off on a narrower camera. This script reads the predictions
``scripts/choose_gate.py`` saved in each fold (``listened…npz``; no model runs) and, over the
clips whose goal is in view, measures the heading of the model's argmax strip (first frame) and
of the beacon heard at the gate scales (the decision logic replayed, the fold's fitted threshold
times ``--scale`` / ``--portrait-scale``; ``--window-scale`` for the 3:4 windows, as a bundle with
a narrow camera's threshold gates them) against the labelled strip's, both at the clip's camera FOV.
``--by-strip`` adds, per view and labelled strip, how often the beacon is on and confidently wrong.
``--measure far_mass`` replays the far-mass gate instead (thresholds ``0.01 x --scale``, as
``choose_gate.py --measure far_mass`` chose them).

    .venv/bin/python scripts/heading_error.py runs/res256 --also runs/res256_s1 --also runs/res256_s2 \
        --mirror --frames 100000 --portrait-frames 200 --portrait 3 --scale 0.8409 --portrait-scale 0.9576
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from choose_gate import (FAR_MASS_REFERENCE, add_also, finished_folds, fold_bundle, held_out_parser,  # noqa: E402
                         reference_threshold, view_tag)

from crossing_assist.actions import N_BINS, bin_center_x, x_to_heading  # noqa: E402
from crossing_assist.data_tools.augment import PORTRAIT_SETS  # noqa: E402
from crossing_assist.data_tools.manifest import read_manifest  # noqa: E402
from crossing_assist.runtime.listen import WRONG_STRIPS, Listener  # noqa: E402

FAR_DEG = 10.0   # a heading this far off is reported apart


def strip_heading(strip: np.ndarray, fov_deg: np.ndarray) -> np.ndarray:
    """Heading (degrees) of the centre of each strip 1..12 under a pinhole camera of ``fov_deg``."""
    return np.asarray([x_to_heading(bin_center_x(int(b)), float(f)) for b, f in zip(strip, fov_deg)], float)


def view_errors(lis: Listener, in_view: list[int], threshold: float) -> dict[str, np.ndarray]:
    """Per clip with a crossing and its goal in view: ``fov`` (deg), ``label`` (its strip),
    ``right`` (argmax = label), ``model`` (deg, argmax against label; NaN for an unknown or failed
    argmax), ``heard`` (deg, the beacon at ``threshold`` against the label; NaN when off) and
    ``wrong`` (the beacon on and >= 2 strips off: confidently wrong)."""
    idx = [i for i in in_view if lis.labels[i] != 0]
    labels = np.asarray([lis.labels[i] for i in idx])
    heard = lis.heard(threshold, idx)
    fov = np.asarray([h.fov_deg for h in heard], float)   # the FOV the decision logic read the clip with
    first = np.asarray([lis.clips[i][0].action if lis.clips[i][0].ok else 0 for i in idx])
    goal = strip_heading(labels, fov)
    model = np.where(first > 0, np.abs(strip_heading(np.maximum(first, 1), fov) - goal), np.nan)
    played = np.asarray([np.nan if not h.on or h.heading_deg is None else h.heading_deg for h in heard], float)
    wrong = np.asarray([h.on and abs(h.strip - h.label) >= WRONG_STRIPS for h in heard], bool)
    return {"fov": fov, "label": labels, "right": first == labels, "model": model, "heard": np.abs(played - goal),
            "wrong": wrong}


def row(name: str, e: dict[str, np.ndarray]) -> str:
    """One markdown row of a view's pooled errors."""
    model, heard = e["model"][~np.isnan(e["model"])], e["heard"][~np.isnan(e["heard"])]
    fov = float(np.nanmedian(e["fov"]))
    stat = lambda v: f"{v.mean():.2f} / {np.percentile(v, 90):.1f} / {100 * (v >= FAR_DEG).mean():.1f} %" if len(v) else "n/a"  # noqa: E731
    return (f"| {name} | {len(e['right'])} | {fov:.1f} deg ({fov / N_BINS:.2f}) | {e['right'].mean():.3f} | {stat(model)} | "
            f"{100 * len(heard) / len(e['right']):.1f} % | {stat(heard)} |")


def by_strip(name: str, e: dict[str, np.ndarray]) -> list[str]:
    """Markdown rows of a view's beacon per labelled strip: clips, beacon on, confidently wrong
    (shares of that strip's clips)."""
    out = []
    for b in range(1, N_BINS + 1):
        sel = e["label"] == b
        if sel.any():
            out.append(f"| {name} | {b} | {int(sel.sum())} | {100 * (~np.isnan(e['heard'][sel])).mean():.1f} % | "
                       f"{100 * e['wrong'][sel].mean():.2f} % |")
    return out


def main(argv=None) -> int:
    ap = held_out_parser(__doc__.split("\n\n")[0], frames=200)
    add_also(ap)
    ap.add_argument("--portrait", type=int, default=3, help="portrait views a photo, of each kind, as listened to")
    ap.add_argument("--portrait-frames", type=int, metavar="N", help="the portrait draw's photos a fold (default: --frames)")
    ap.add_argument("--scale", type=float, default=1.0, help="landscape gate threshold = the fold's fitted one x this")
    ap.add_argument("--portrait-scale", type=float, default=1.0, help="the same for portrait views")
    ap.add_argument("--window-scale", type=float, metavar="S", help="the same for the 3:4 windows, as a bundle with a "
                    "narrow camera's threshold gates them (default: --portrait-scale)")
    ap.add_argument("--by-strip", action="store_true", help="also the beacon per labelled strip, each view")
    ap.add_argument("--measure", choices=("far_mass",), help="the gate replayed with this measure, as choose_gate.py "
                    "--measure: thresholds are the scales x its reference, not x the fold's fitted one")
    a = ap.parse_args(argv)
    from crossing_assist.runtime.engine import Engine

    window = a.portrait_scale if a.window_scale is None else a.window_scale
    scales = {"landscape": a.scale, "portrait": a.portrait_scale, "portrait_window": window}

    ptl = read_manifest(a.ptl)
    views = ("landscape", *(PORTRAIT_SETS if a.portrait else ()))
    pooled: dict[str, list[dict]] = {v: [] for v in views}
    for cv in (a.cv, *a.also):
        for fold, source in finished_folds(cv):
            engine = Engine(fold_bundle(fold, source, ptl, a.mirror), threads=1)
            t0 = reference_threshold(engine, a.measure)
            for view in views:
                n = a.frames if view == "landscape" or a.portrait_frames is None else a.portrait_frames
                path = fold / f"listened{view_tag(a.mirror, n, a.seed, view, a.portrait)}.npz"
                if not path.is_file():
                    print(f"error: {path} missing: run scripts/choose_gate.py {cv} with the same draw first", file=sys.stderr)
                    return 2
                lis, extra = Listener.load(engine, path, a.measure)
                scale = scales[view]
                pooled[view].append(view_errors(lis, extra["in_view"].tolist(), scale * t0))
                print(f"{cv} {source} {view}: {len(pooled[view][-1]['right'])} clips, goal in view", file=sys.stderr, flush=True)
    if not any(pooled.values()):
        print(f"error: no finished fold in {a.cv}", file=sys.stderr)
        return 2
    print(f"goal in view; heading errors in degrees against the labelled strip's centre, mean / p90 / share >= {FAR_DEG:g} deg; "
          + (f"heard with far mass <= {a.scale * FAR_MASS_REFERENCE:.4g} (landscape), {a.portrait_scale * FAR_MASS_REFERENCE:.4g} "
             f"(portrait), {window * FAR_MASS_REFERENCE:.4g} (3:4 window)\n"
             if a.measure else f"heard at the fitted threshold x {a.scale:g} (landscape), x {a.portrait_scale:g} (portrait), "
             f"x {window:g} (3:4 window)\n"))
    print("| view | clips | camera FOV (a strip) | accuracy | model: error | beacon on | heard: error |")
    print("|---|---:|---|---:|---|---:|---|")
    merged = {v: {k: np.concatenate([f[k] for f in pooled[v]]) for k in pooled[v][0]} for v in views if pooled[v]}
    for view, e in merged.items():
        print(row(view, e))
    if a.by_strip:
        print("\n| view | labelled strip | clips | beacon on | confidently wrong |\n|---|---:|---:|---:|---:|")
        for view, e in merged.items():
            print("\n".join(by_strip(view, e)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
