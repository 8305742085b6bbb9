"""What a user hears while panning the phone: photos turned into scans, played with and without a gyroscope.

A user looking for the crossing sweeps the phone left and right. crossing-eval plays still
clips, where the camera never turns; this probe plays each photo as a scan: 1 s still, then the
camera turned right to ``+A`` degrees, left to ``-A`` and back to straight ahead at ``R`` degrees
per second (``--amplitude``, ``--rate``), every frame re-rendered as that turned camera would see
it (:func:`~crossing_assist.data_tools.augment.yaw`, the unseen part black, the goal moved and
relabelled, ``unknown`` once it leaves the view), 10 fps, through the bundle's engine and the
runtime's decision logic (:class:`~crossing_assist.runtime.decide.Decider`), twice:

- ``gyro``: the decision logic told the turn (the app's opt-in gyroscope, the Python live loop's
  yaw input);
- ``no gyro``: told nothing (the app's default): the filter's and the hold's headings stay where
  they were while the view moves.

Each frame of the scan (after the still second) is judged against the goal's strip in *that*
frame: with the goal in view, beacon on and confidently wrong (on and >= 2 strips off), and how
many of the wrong frames the heading hold played; with the goal out of view, the beacon pointing
to the wrong side. The model's outputs are cached (``--cache``), so ``--replay`` decides again
(after a change to the decision logic) without running the model.

    .venv/bin/python scripts/pan_probe.py [--photos 100] [--amplitude 20] [--rate 30] \\
        [--cache runs/pan/preds.npz] [--replay] [--out runs/pan/pan.json]

A missing manifest, an empty split or an unusable bundle is one line and exit 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from crossing_assist.actions import UNKNOWN, heading_to_x, x_to_bin
from crossing_assist.bundle import BundleError
from crossing_assist.data_tools.augment import yaw
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.fileio import atomic_path, atomic_write_text
from crossing_assist.runtime.decide import Decider, Observation
from crossing_assist.runtime.demo import DEFAULT_BUNDLE
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.gate import GATE_HOLD
from crossing_assist.runtime.listen import WRONG_STRIPS

FPS = 10.0
STILL_S = 1.0
WIDTH = 640


def scan(amplitude: float, rate: float, fps: float = FPS) -> np.ndarray:
    """The camera's yaw (degrees, + = turned right) at each frame: ``STILL_S`` still, then
    0 -> +A -> -A -> 0 at ``rate`` degrees per second."""
    still = np.zeros(int(round(STILL_S * fps)))
    step = rate / fps
    legs = [np.arange(0, amplitude, step), np.arange(amplitude, -amplitude, -step), np.arange(-amplitude, 0, step)]
    return np.concatenate([still, *legs, [0.0]])


def play(engine: Engine, rows, images, psi: np.ndarray) -> dict[str, np.ndarray]:
    """Each photo scanned: the model's outputs per frame and the goal's label per frame."""
    n, f, a = len(rows), len(psi), engine.space.n
    out = {"probs": np.full((n, f, a), np.nan), "uncertainty": np.full((n, f), np.inf), "ok": np.zeros((n, f), bool),
           "labels": np.zeros((n, f), np.int64), "fov_deg": np.zeros(n), "psi": psi}
    for i, (r, img) in enumerate(zip(rows, images)):
        h, w = img.shape[:2]
        fov = engine.camera_fov(w, h)
        out["fov_deg"][i] = fov
        for j, p in enumerate(psi):
            view, _, label, _ = yaw(img, r.far_x, r.label, float(p), fov)
            pred = engine.predict(view)
            out["labels"][i, j] = label
            if pred.ok:
                out["probs"][i, j], out["uncertainty"][i, j], out["ok"][i, j] = pred.probs, pred.uncertainty, True
        print(f"\r{i + 1}/{n} photos scanned", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return out


def judge(engine: Engine, z: dict[str, np.ndarray], gyro: bool) -> dict:
    """Replay the decision logic over every scan; rates over the frames after the still second."""
    psi = z["psi"]
    rates = np.diff(psi, prepend=psi[0]) * FPS if gyro else np.zeros_like(psi)
    start = int(round(STILL_S * FPS))
    c = {"in_view": 0, "on": 0, "wrong": 0, "wrong_hold": 0, "out_of_view": 0, "out_on": 0, "out_wrong_side": 0}
    for i in range(len(z["labels"])):
        fov = float(z["fov_deg"][i])
        decider = Decider(engine.decision_config("landscape", fov))
        for j in range(len(psi)):
            obs = Observation(z["probs"][i, j], float(z["uncertainty"][i, j]), bool(z["ok"][i, j]))
            d = decider.step(j / FPS, obs, float(rates[j]))
            if j < start:
                continue
            label = int(z["labels"][i, j])
            strip = 0 if d.stop else x_to_bin(min(max(heading_to_x(d.heading_deg, fov), 0.0), 1.0 - 1e-9))
            if label != UNKNOWN:
                c["in_view"] += 1
                c["on"] += int(not d.stop)
                bad = not d.stop and abs(strip - label) >= WRONG_STRIPS
                c["wrong"] += int(bad)
                c["wrong_hold"] += int(bad and d.gate == GATE_HOLD)
            else:
                c["out_of_view"] += 1
                c["out_on"] += int(not d.stop)
                # the goal left on the side the camera turned away from: right turn -> goal to the left
                left = psi[j] > 0
                c["out_wrong_side"] += int(not d.stop and (d.heading_deg > 0) == left)
    r = lambda k, n: round(c[k] / c[n], 4) if c[n] else None  # noqa: E731
    return {**c, "beacon_on": r("on", "in_view"), "confidently_wrong": r("wrong", "in_view"),
            "wrong_by_hold": r("wrong_hold", "wrong"), "out_of_view_on": r("out_on", "out_of_view"),
            "out_of_view_wrong_side": r("out_wrong_side", "out_of_view")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE, help="bundle folder (default: the embedded one)")
    ap.add_argument("--data", type=Path, default=Path("runs/data/ptl"), help="crossing-data manifest folder")
    ap.add_argument("--split", default="val")
    ap.add_argument("--photos", type=int, default=100, help="photos drawn from the split (default 100)")
    ap.add_argument("--amplitude", type=float, default=20.0, help="degrees either side of straight ahead (default 20)")
    ap.add_argument("--rate", type=float, default=30.0, help="turn rate, degrees per second (default 30)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, help="the model's outputs: written after playing, read with --replay")
    ap.add_argument("--replay", action="store_true", help="decide again from --cache without running the model")
    ap.add_argument("--out", type=Path, help="write the figures as JSON here")
    a = ap.parse_args(argv)
    try:
        engine = Engine(a.bundle, threads=1)
    except BundleError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if a.replay:
        if a.cache is None or not a.cache.is_file():
            print(f"error: --replay needs the --cache file a play wrote ({a.cache} not found)", file=sys.stderr)
            return 1
        with np.load(a.cache) as f:
            z = {k: f[k] for k in f.files}
    else:
        if not (a.data / "manifest.csv").is_file():
            print(f"error: no manifest at {a.data / 'manifest.csv'} (scripts/prepare_default_data.sh writes runs/data/ptl)",
                  file=sys.stderr)
            return 1
        ds = read_manifest(a.data)
        rows = [r for r in ds.rows if r.split == a.split and r.far_x is not None]
        if not rows:
            print(f"error: no photo with a crossing in split {a.split!r} of {a.data}", file=sys.stderr)
            return 1
        rng = np.random.default_rng(a.seed)
        rows = [rows[i] for i in sorted(rng.choice(len(rows), min(a.photos, len(rows)), replace=False))]
        images = []
        for r in rows:
            img = load_frame(ds.image_path(r), r.flags)
            h, w = img.shape[:2]
            images.append(cv2.resize(img, (WIDTH, round(h * WIDTH / w)), interpolation=cv2.INTER_AREA) if w > WIDTH else img)
        z = play(engine, rows, images, scan(a.amplitude, a.rate))
        if a.cache:
            a.cache.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(a.cache) as tmp:
                np.savez_compressed(tmp, **z)
    res = {"bundle": str(a.bundle), "photos": int(len(z["labels"])), "frames_per_scan": int(len(z["psi"])),
           "amplitude_deg": float(np.abs(z["psi"]).max()), "rate_dps": float(np.abs(np.diff(z["psi"])).max() * FPS),
           "gyro": judge(engine, z, True), "no_gyro": judge(engine, z, False)}
    print("| scan | goal-in-view frames | beacon on | confidently wrong | of them by the hold | "
          "goal out of view: on | wrong side |\n|---|---|---|---|---|---|---|")
    for name in ("gyro", "no_gyro"):
        g = res[name]
        pct = lambda v: "–" if v is None else f"{100 * v:.1f} %"  # noqa: E731
        print(f"| {name.replace('_', ' ')} | {g['in_view']} | {pct(g['beacon_on'])} | {pct(g['confidently_wrong'])} | "
              f"{pct(g['wrong_by_hold'])} | {pct(g['out_of_view_on'])} | {pct(g['out_of_view_wrong_side'])} |")
    if a.out:
        atomic_write_text(a.out, json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
