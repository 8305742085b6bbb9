"""A narrow camera's frames evaluated at the bundle's default FOV and at their own (``fov=`` flags).

Cuts the centred 3:4 window of ``--photos`` PTL val photos (what a 40.8 deg camera sees of a
67 deg 4:3 photo, :func:`~crossing_assist.geometry.window_fov`) and writes two manifests over the
same images: ``OUT/plain`` (no flag: crossing-eval takes a 3:4 portrait frame for the bundle's
portrait phone, 53 deg) and ``OUT/flag`` (``fov=40.8``, as ``crossing-data frames --fov`` gives a
researcher's frames). Then compare::

    .venv/bin/python scripts/fov_flag_check.py [--photos 300] [--out runs/fovcheck]
    crossing-eval --bundle crossing_assist/assets/default_bundle --data runs/fovcheck/plain --split val --portrait 0
    crossing-eval --bundle crossing_assist/assets/default_bundle --data runs/fovcheck/flag --split val --portrait 0

A missing manifest is one line and exit 1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from prepared_data import draw, open_manifest  # noqa: E402  (a sibling script: the probes' photos)

from crossing_assist.data_tools.augment import crop_window
from crossing_assist.data_tools.images import load_frame, save_rgb
from crossing_assist.data_tools.manifest import Row, write_manifest
from crossing_assist.geometry import TRAIN_FOV_DEG, window_fov


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path("runs/data/ptl"))
    ap.add_argument("--photos", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("runs/fovcheck"))
    a = ap.parse_args(argv)
    ds = open_manifest(a.data)
    if ds is None:
        return 1
    rows = [r for r in ds.rows if r.split == "val" and r.far_x is not None]
    rows = draw(rows, a.photos, np.random.default_rng(a.seed))
    fov = window_fov(9 / 16, TRAIN_FOV_DEG)
    out: dict[str, list[Row]] = {"plain": [], "flag": []}
    for i, r in enumerate(rows):
        img = load_frame(ds.image_path(r), r.flags)
        if img.shape[1] > 1280:
            img = cv2.resize(img, (1280, round(img.shape[0] * 1280 / img.shape[1])), interpolation=cv2.INTER_AREA)
        win, fx, label = crop_window(img, r.far_x, r.label, 3 / 4, 0.5)
        save_rgb(a.out / "imgs" / f"w{i}.jpg", win)
        for k, rs in out.items():
            rs.append(Row(f"../imgs/w{i}.jpg", label, fx, r.source, "val", {}, (f"fov={fov:.1f}",) if k == "flag" else ()))
    for k, rs in out.items():
        write_manifest(a.out / k, rs)
    print(f"wrote {len(rows)} 3:4 windows ({fov:.1f} deg) to {a.out}/plain and {a.out}/flag (fov={fov:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
