"""How well the turn read from the frames (``runtime.visual_yaw``) reads turns, and what it reads where there is none.

Four checks, no model involved:

- **known turns**: photos drawn from one split of a crossing-data manifest (default PTL val in
  ``runs/data/ptl``), scaled to 320 px wide, each re-rendered as the camera turned by a known angle
  (``data_tools.augment.yaw``, the perspective warp; sensor noise of +-3 added) and read as a
  pair of frames at the default landscape FOV: the error in degrees, and how many pairs it refused
  (no turn);
- **a rolled camera**: the same known turns seen by a camera rolled 10, 20 and 30 deg (the scene
  beyond the photo reflected in), read from its picture as it is and levelled, as the pipeline and
  the app read it when told the roll;
- **a bus passing a still camera**: each photo held still while a block of another photo (a bus:
  a share of the frame's width and height, from the bottom) crosses it at 30 px a frame, 10 fps:
  the turn it read over the pass (there was none), with the tile veto and without it (the same
  estimator with ``TILE_VETO`` 1e12: what it read before the veto);
- **the synthetic sample clip**: the estimate against the clip's true camera yaw, per phase of
  the clip (turning to the crossing, aligning, walking), per frame and summed.

    .venv/bin/python scripts/visual_yaw_check.py [--photos 60] [--data runs/data/ptl] [--out runs/visual_yaw.json]

A missing manifest or an empty split is one line and exit 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from prepared_data import draw, open_manifest  # noqa: E402  (a sibling script: the probes' photos)

from crossing_assist.data_tools.augment import roll
from crossing_assist.data_tools.augment import yaw as turned
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.synth import clip_pose, clip_scene
from crossing_assist.fileio import atomic_write_text
from crossing_assist.geometry import level
from crossing_assist.runtime import visual_yaw as vy
from crossing_assist.runtime.demo import DEFAULT_CLIP

FOV = 67.0                      # the default landscape camera's horizontal FOV
TURNS = (0.5, 1.0, 3.0, 6.0, -4.0)
ROLLS = (10.0, 20.0, 30.0)      # a phone held rolled (degrees)
BUSES = ((0.3, 0.5), (0.5, 0.6), (0.8, 0.7), (1.2, 0.8))   # (share of width, share of height)
BUS_PX, FPS, WIDTH = 30, 10.0, 320


def _known_turns(images: list[np.ndarray], rng: np.random.Generator, seen=lambda frame: frame) -> dict:
    """Each photo and its turned views read as pairs; ``seen``: what the estimator gets of a frame
    (the camera's picture as it is, by default)."""
    errors, refused = [], 0
    for img in images:
        for psi in TURNS:
            view = turned(img, None, 12, psi, FOV)[0].astype(np.int16) + rng.integers(-3, 4, img.shape)
            shift = vy.shift_between(vy.thumbnail(seen(img)), vy.thumbnail(seen(np.clip(view, 0, 255).astype(np.uint8))))
            if shift is None:
                refused += 1
            else:
                errors.append(vy.shift_to_deg(shift, vy.THUMB_WIDTH, FOV) - psi)
    err = np.abs(errors) if errors else np.zeros(1)
    return {"pairs": len(images) * len(TURNS), "refused": refused, "mae_deg": float(err.mean()),
            "p90_deg": float(np.percentile(err, 90)), "max_deg": float(err.max())}


def _rolled(images: list[np.ndarray], rng: np.random.Generator) -> dict:
    """The known turns of a camera rolled by each of :data:`ROLLS` (the scene beyond the photo
    reflected in), read from its picture as it is and levelled (``geometry.level``, as the
    pipeline and the app read it when told the roll)."""
    out = {}
    for deg in ROLLS:
        rolled = lambda f, d=deg: roll(f, None, 0.5, 0, d, fill="reflect")[0]  # noqa: E731
        out[f"{deg:g}"] = {"as_is": _known_turns(images, rng, rolled),
                           "levelled": _known_turns(images, rng, lambda f, r=rolled, d=deg: level(r(f), d))}
    return out


def _bus_pass(view: np.ndarray, bus: np.ndarray, cover: tuple[float, float]) -> float:
    """Degrees read over one pass of the bus across the still ``view``."""
    h, w = view.shape[:2]
    bw, bh = int(cover[0] * w), int(cover[1] * h)
    yaw, total, k = vy.VisualYaw(), 0.0, 0
    while -bw + BUS_PX * k < w + BUS_PX:
        frame, x = view.copy(), -bw + BUS_PX * k
        x0, x1 = max(0, x), min(w, x + bw)
        if x1 > x0:
            frame[h - bh:, x0:x1] = bus[:bh, x0 - x:x1 - x]
        total += yaw.update(frame, k / FPS, FOV) / FPS
        k += 1
    return total


def _buses(images: list[np.ndarray]) -> dict:
    out = {}
    for cover in BUSES:
        row = {}
        for name, veto in (("veto", vy.TILE_VETO), ("no_veto", 1e12)):     # 1e12: no tile ever vetoes
            saved, vy.TILE_VETO = vy.TILE_VETO, veto
            try:
                reads = [_bus_pass(img, cv2.resize(images[(i + 1) % len(images)], (2 * WIDTH, img.shape[0])), cover)
                         for i, img in enumerate(images)]
            finally:
                vy.TILE_VETO = saved
            row[name] = {"mean_abs_deg": float(np.mean(np.abs(reads))), "max_abs_deg": float(np.max(np.abs(reads)))}
        out[f"{cover[0]:g}x{cover[1]:g}"] = row
    return out


def _sample_clip() -> dict:
    meta = json.loads(DEFAULT_CLIP.with_suffix(".json").read_text())
    scene, seconds, fov = clip_scene(int(meta["seed"])), meta["n_frames"] / meta["fps"], float(meta["fov_deg"])
    cap = cv2.VideoCapture(str(DEFAULT_CLIP))
    yaw, prev, per = vy.VisualYaw(), None, {}
    for t in meta["t"]:
        ok, bgr = cap.read()
        if not ok:
            break
        cam, phase = clip_pose(scene, t, seconds, fov)
        rate = yaw.update(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), t, fov)
        if prev is not None:
            per.setdefault(phase, []).append((cam.yaw - prev[0], rate * (t - prev[1])))
        prev = (cam.yaw, t)
    cap.release()
    out = {}
    for phase, pairs in per.items():
        true, read = np.array(pairs).T
        out[phase] = {"frames": len(pairs), "mae_deg": float(np.abs(read - true).mean()),
                      "true_sum_deg": float(true.sum()), "read_sum_deg": float(read.sum()),
                      "no_turn_read": int((read == 0).sum())}
    return out


def markdown(res: dict) -> str:
    k = res["known_turns"]
    lines = [f"known turns ({', '.join(f'{t:g}' for t in TURNS)} deg at {FOV:g} deg FOV, {k['pairs']} pairs): "
             f"error mean {k['mae_deg']:.3f} deg, p90 {k['p90_deg']:.3f}, max {k['max_deg']:.3f}; "
             f"refused {k['refused']} ({100 * k['refused'] / k['pairs']:.1f} %)", "",
             "| camera rolled | read as it is: error mean / p90, refused | levelled |", "|---|---:|---:|"]
    for deg, row in res["rolled"].items():
        lines.append(f"| {deg} deg | " + " | ".join(f"{row[k]['mae_deg']:.2f} / {row[k]['p90_deg']:.2f} deg, "
                                                   f"{row[k]['refused']}" for k in ("as_is", "levelled")) + " |")
    lines += ["", "| bus (width x height) | read over a pass, tile veto: mean / max | without the veto |",
              "|---|---:|---:|"]
    for cover, row in res["buses"].items():
        lines.append(f"| {cover} | {row['veto']['mean_abs_deg']:.1f} / {row['veto']['max_abs_deg']:.1f} deg | "
                     f"{row['no_veto']['mean_abs_deg']:.1f} / {row['no_veto']['max_abs_deg']:.1f} deg |")
    lines += ["", "| sample clip phase | frames | error a frame (mean) | true turn | read | frames read as no turn |",
              "|---|---:|---:|---:|---:|---:|"]
    for phase, r in res["sample_clip"].items():
        lines.append(f"| {phase} | {r['frames']} | {r['mae_deg']:.3f} deg | {r['true_sum_deg']:.1f} deg | "
                     f"{r['read_sum_deg']:.1f} deg | {r['no_turn_read']} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path("runs/data/ptl"), help="crossing-data manifest folder")
    ap.add_argument("--split", default="val")
    ap.add_argument("--photos", type=int, default=60, help="photos drawn from the split (default 60)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, help="write the figures as JSON here")
    a = ap.parse_args(argv)
    ds = open_manifest(a.data)
    if ds is None:
        return 1
    rows = [r for r in ds.rows if r.split == a.split]
    if not rows:
        print(f"error: no photo in split {a.split!r} of {a.data}", file=sys.stderr)
        return 1
    rng = np.random.default_rng(a.seed)
    rows = draw(rows, a.photos, rng)
    images = []
    for r in rows:
        img = load_frame(ds.image_path(r), r.flags)
        images.append(cv2.resize(img, (WIDTH, round(WIDTH * img.shape[0] / img.shape[1])), interpolation=cv2.INTER_AREA))
    res = {"data": str(a.data), "split": a.split, "photos": len(rows), "seed": a.seed, "fov_deg": FOV,
           "known_turns": _known_turns(images, rng), "rolled": _rolled(images, rng), "buses": _buses(images),
           "sample_clip": _sample_clip()}
    print(markdown(res))
    if a.out:
        atomic_write_text(a.out, json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
