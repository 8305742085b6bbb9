"""How far a phone may pitch before the far kerb leaves the rows a bundle shows the model.

A bundle's view crop (``geometry.view_crop``, :func:`crossing_assist.geometry.view_rows`) keeps a
centred band of a portrait frame's rows; with ``geometry.view_zoom`` > 1 the band is narrower,
since the frame is shown magnified. Photos taken in landscape cannot show what a portrait phone
pitched up or down sees beyond them, but where their far points lie can: each PTL photo's far
kerb (``far_y``, taken at the training camera, ``train_fov_deg`` across a 4:3 photo) is placed at
its angle above or below the optical axis, the phone pitched by each angle (positive: pointed
further down, so the far kerb rises in the frame), and counted as seen when it stays inside the
band, on the vertical through the frame's centre. No model is involved: this is the geometry's
share of far kerbs in view, an upper bound on what the model can place.

    .venv/bin/python scripts/pitch_tolerance.py crossing_assist/assets/default_bundle --view-zoom 1 1.3
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from crossing_assist.bundle import read_bundle
from crossing_assist.geometry import GeometryError, check_fov, parse_size


def far_angles(far_y: np.ndarray, train_fov_deg: float, aspect: float = 4 / 3) -> np.ndarray:
    """Degrees above the optical axis of far points at row fraction ``far_y`` of a ``aspect``
    (width / height) photo whose horizontal FOV is ``train_fov_deg``."""
    half_tan = math.tan(math.radians(train_fov_deg) / 2) / aspect
    return np.degrees(np.arctan((0.5 - np.asarray(far_y, float)) * 2 * half_tan))


def band_half_angle(geometry, canvas: tuple[int, int], frame: tuple[int, int], fov_deg: float) -> float:
    """Half the vertical angle (degrees) of the centred rows the view crop keeps of a ``frame``
    (width, height) at horizontal FOV ``fov_deg``; the whole frame without the view crop."""
    w, h = frame
    _, rows = geometry.rows_seen(h, w, fov_deg, canvas)
    focal = (w / 2) / math.tan(math.radians(fov_deg) / 2)
    return math.degrees(math.atan(rows / 2 / focal))


def in_view(angles: np.ndarray, half: float, pitches) -> list[float]:
    """Per pitch (degrees, positive: pointed further down), the share of far points inside ±half."""
    return [float(np.mean(np.abs(angles + p) <= half)) for p in pitches]


def read_far_y(labels: Path) -> np.ndarray:
    with open(labels, newline="") as f:
        return np.asarray([float(r["far_y"]) for r in csv.DictReader(f) if r.get("far_y") not in (None, "")], float)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bundle", type=Path)
    ap.add_argument("--labels", type=Path, default=Path("../shared/data/ptl/labels.csv"),
                    help="a CSV with a far_y column (row fraction of the far kerb), e.g. PTL's labels.csv")
    ap.add_argument("--view-zoom", type=float, nargs="+", metavar="Z",
                    help="compare the bundle's geometry with these view zooms (default: the bundle's own)")
    ap.add_argument("--frame", type=lambda t: parse_size(t, "WxH"), default=(640, 480), metavar="WxH",
                    help="the portrait frame (default 480x640)")
    ap.add_argument("--fov", type=float, help="its horizontal FOV in degrees (default: the bundle's portrait FOV)")
    ap.add_argument("--pitch", default="-20,-15,-10,-5,0,5,10,15,20", help="pitches in degrees, comma-separated")
    a = ap.parse_args(argv)
    h, w = a.frame
    try:
        pitches = [float(p) for p in a.pitch.split(",")]
    except ValueError:
        ap.error(f"--pitch {a.pitch!r}: comma-separated degrees, e.g. -10,0,10")
    if not a.labels.is_file():
        print(f"error: {a.labels} not found (a CSV with a far_y column)", file=sys.stderr)
        return 2
    try:
        b = read_bundle(a.bundle)
        fov = check_fov(a.fov if a.fov is not None else b.geometry.camera_fov_deg[1])
        geometries = [replace(b.geometry, view_zoom=z) for z in a.view_zoom] if a.view_zoom else [b.geometry]
        halves = [band_half_angle(g, b.input.size, (w, h), fov) for g in geometries]
        far_y = read_far_y(a.labels)
        if not len(far_y):
            raise ValueError(f"{a.labels} has no far_y values")
    except (OSError, ValueError, KeyError, GeometryError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    angles = far_angles(far_y, b.geometry.train_fov_deg)
    print(f"{len(angles)} far kerbs; a {w}x{h} frame at {fov:g} deg; positive pitch: pointed further down")
    print(f"{'view':<22}{'band':>9}  " + "".join(f"{p:>+7g}" for p in pitches))
    for g, half in zip(geometries, halves):
        name = f"view_zoom {g.view_zoom:g}" if g.view_crop else "no view crop"
        print(f"{name:<22}{f'±{half:.1f}°':>9}  " + "".join(f"{100 * s:>6.1f}%" for s in in_view(angles, half, pitches)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
