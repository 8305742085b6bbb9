"""A user panning the phone: photos turned into scans, the turn from a gyroscope, from the frames, or none.

A user looking for the crossing sweeps the phone left and right. This probe plays each photo as a
scan, as ``crossing-eval --scan R`` does: 1 s still, then the camera turned right to ``+A``
degrees, left to ``-A`` and back to straight ahead at ``R`` degrees per second (``--amplitude``,
``--rate``), every frame re-rendered as that turned camera would see it
(``crossing_assist.models.evaluate.scan_clips``: the unseen part black, the goal moved and
relabelled, ``unknown`` once it leaves the view), 10 fps, through the bundle's engine and the
runtime's decision logic (``runtime.listen.judge_scans``), three times:

- ``gyro``: the decision logic told the turn (the app's opt-in gyroscope);
- ``camera``: told the turn read from the frames (``runtime.visual_yaw``: the app's and the
  Python pipeline's default without a gyroscope);
- ``no yaw``: told nothing (``crossing-demo --no-visual-yaw``, the app with both off): the
  filter's and the hold's headings stay where they were while the view moves.

Each frame of the scan (after the still second) is judged against the goal's strip in *that*
frame: with the goal in view, beacon on and confidently wrong (on and >= 2 strips off), and how
many of the wrong frames the heading hold played; with the goal out of view, the beacon pointing
to the wrong side. The model's outputs are cached (``--cache``), so ``--replay`` decides again
(after a change to the decision logic) without running the model.

    .venv/bin/python scripts/pan_probe.py [--photos 100] [--amplitude 20] [--rate 30] [--window] \\
        [--heard-after 0.2] [--cache runs/pan/preds.npz] [--replay] [--out runs/pan/pan.json]

``--heard-after S``: judge each decision when the user hears it, S seconds after its frame's
capture (whole frames), not at the capture: a phone answers after the model's run and plays the
answer until the next one, so while the user turns it lags their facing. Two more readings,
``gyro turned`` and ``camera turned``, are those decisions with the beacon turned by the
gyroscope's turn since the capture, as the app plays them (``runtime.decide.turned``: the
gyroscope followed, or the picture followed and the gyroscope confirmed by it).

``--window``: a narrow camera scans instead, seeing the middle 3:4 window of each turned view at
the window's own FOV (40.8 deg from PTL's 67), as ``crossing-eval --scan --portrait`` plays it;
a goal beside the window but still in the photo is its edge strip. ``--phone``: a phone held in
portrait scans instead (3:4 at the bundle's portrait FOV, 53 deg), seeing the middle of each
turned view as choose_gate's ``portrait`` view cuts it.

A missing manifest, an empty split or an unusable bundle is one line and exit 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from prepared_data import draw, open_manifest  # noqa: E402  (a sibling script: the probes' photos)

from crossing_assist.bundle import BundleError
from crossing_assist.data_tools.images import load_frame
from crossing_assist.fileio import atomic_write_text
from crossing_assist.models.evaluate import SCAN_WINDOW_ASPECT, scan_clips
from crossing_assist.runtime.demo import DEFAULT_BUNDLE
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.listen import SCAN_FPS, Listener, judge_scans, scan_yaw


def camera(a) -> str:
    """Which camera scans (``--window``, ``--phone`` or neither): ``window``, ``phone`` or ``landscape``."""
    return "window" if a.window else "phone" if a.phone else "landscape"


def camera_suffix(cam: str) -> str:
    """The file-name suffix of a camera's scans: none for landscape, else ``_window`` / ``_phone``."""
    return "" if cam == "landscape" else f"_{cam}"


def play(engine: Engine, images, rows, psi: np.ndarray, cam: str = "landscape") -> tuple[Listener, np.ndarray, np.ndarray]:
    """Each photo scanned by ``cam`` (:func:`camera`: the photo's own camera, the narrow camera's
    middle 3:4 window, or a phone held in portrait at the bundle's portrait FOV): its predictions
    (a :class:`Listener`'s clips, which it saves and loads), the goal's strip and the yaw rate read
    from the frames, per frame [photo, frame]."""
    window = SCAN_WINDOW_ASPECT if cam == "window" else None
    phone_fov = engine.bundle.geometry.camera_fov_deg[1] if cam == "phone" else None
    lis, labels, rates = Listener(engine, len(psi) / SCAN_FPS, SCAN_FPS), [], []
    for i, (r, img) in enumerate(zip(rows, images)):
        preds, labs, seen = scan_clips(engine, img, r.far_x, r.label, psi, window=window, phone_fov_deg=phone_fov)
        lis.clips.append(preds)
        lis.labels.append(r.label)
        labels.append(labs)
        rates.append(seen)
        print(f"\r{i + 1}/{len(rows)} photos scanned", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return lis, np.asarray(labels, np.int64), np.asarray(rates, float)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE, help="bundle folder (default: the embedded one)")
    ap.add_argument("--data", type=Path, default=Path("runs/data/ptl"), help="crossing-data manifest folder")
    ap.add_argument("--split", default="val")
    ap.add_argument("--photos", type=int, default=100, help="photos drawn from the split (default 100)")
    ap.add_argument("--amplitude", type=float, default=20.0, help="degrees either side of straight ahead (default 20)")
    ap.add_argument("--rate", type=float, default=30.0, help="turn rate, degrees per second (default 30)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--window", action="store_true",
                    help="a narrow camera: the middle 3:4 window of each turned view (crossing-eval --scan --portrait)")
    ap.add_argument("--phone", action="store_true",
                    help="a phone held in portrait (3:4 at the bundle's portrait FOV) sees the middle of each turned view")
    ap.add_argument("--heard-after", type=float, default=0.0, metavar="S",
                    help="judge each decision S seconds after its frame's capture, when it is heard (default 0)")
    ap.add_argument("--cache", type=Path, help="the model's outputs: written after playing, read with --replay")
    ap.add_argument("--replay", action="store_true", help="decide again from --cache without running the model")
    ap.add_argument("--out", type=Path, help="write the figures as JSON here")
    a = ap.parse_args(argv)
    if a.window and a.phone:
        ap.error("--window and --phone: one camera scans")
    if not 0 <= a.heard_after <= 1:   # before a play that takes minutes (crossing-eval's range)
        print(f"error: --heard-after {a.heard_after:g} s invalid; valid: 0..1 s after the frame's capture", file=sys.stderr)
        return 1
    try:
        engine = Engine(a.bundle, threads=1)
    except BundleError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if a.replay:
        if a.cache is None or not a.cache.is_file():
            print(f"error: --replay needs the --cache file a play wrote ({a.cache} not found)", file=sys.stderr)
            return 1
        lis, extra = Listener.load(engine, a.cache)
        if "camera_rates" not in extra:
            print(f"error: {a.cache} was written before scans kept the turn read from the frames; play again",
                  file=sys.stderr)
            return 1
        labels, psi, rates = extra["scan_labels"], extra["psi"], extra["camera_rates"]
    else:
        ds = open_manifest(a.data)
        if ds is None:
            return 1
        rows = [r for r in ds.rows if r.split == a.split and r.far_x is not None]
        if not rows:
            print(f"error: no photo with a crossing in split {a.split!r} of {a.data}", file=sys.stderr)
            return 1
        rng = np.random.default_rng(a.seed)
        rows = draw(rows, a.photos, rng)
        psi = scan_yaw(a.amplitude, a.rate)
        lis, labels, rates = play(engine, [load_frame(ds.image_path(r), r.flags) for r in rows], rows, psi, camera(a))
        if a.cache:
            a.cache.parent.mkdir(parents=True, exist_ok=True)
            lis.save(a.cache, scan_labels=labels, psi=psi, camera_rates=rates)
    try:
        judged = judge_scans(engine, lis.clips, labels, psi, rates, heard_after_s=a.heard_after)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    res = {"bundle": str(a.bundle), "photos": len(lis.clips), "frames_per_scan": int(len(psi)),
           "amplitude_deg": float(np.abs(psi).max()), "rate_dps": float(np.abs(np.diff(psi)).max() * SCAN_FPS),
           "heard_after_s": round(a.heard_after * SCAN_FPS) / SCAN_FPS, **judged}
    print("| scan | goal-in-view frames | beacon on | confidently wrong | of them by the hold | "
          "goal out of view: on | wrong side |\n|---|---|---|---|---|---|---|")
    pct = lambda v: "–" if v is None else f"{100 * v:.2f} %"  # noqa: E731
    for name in judged:
        g = res[name]
        print(f"| {name.replace('_', ' ')} | {g['in_view']} | {pct(g['beacon_on'])} | {pct(g['confidently_wrong'])} | "
              f"{pct(g['wrong_by_hold'])} | {pct(g['out_of_view_on'])} | {pct(g['out_of_view_wrong_side'])} |")
    if a.out:
        atomic_write_text(a.out, json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
