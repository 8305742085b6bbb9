"""Photos from a phone zoomed in (2x, 3x), as a PTL-layout folder with the EXIF a phone writes.

Each labelled photo of ``--split`` is cut to its middle ``1 / zoom`` of the width and height (what a
phone's 2x or 3x camera sees from the same spot) and saved as a JPEG carrying the lens's
35 mm-equivalent focal length (EXIF ``FocalLengthIn35mmFilm``: 26 mm x zoom, a phone main camera's
26 mm zoomed), with ``labels.csv`` in the PTL layout: the far point moves exactly,
``x' = (x - (1 - 1/zoom) / 2) * zoom``; photos whose far point leaves the view are left out.
Import it as a researcher would (``crossing-data import-ptl``: each photo gets its camera's FOV
from the EXIF) and play it through the runtime (``crossing-eval --bundle``); import it again with
``--no-exif-fov`` to hear what the default FOV (67 deg for a landscape photo) would make of it::

    .venv/bin/python scripts/zoom_photos.py --zoom 2 --out runs/zoom2
    .venv/bin/crossing-data import-ptl runs/zoom2 --out runs/data/zoom2 --images reference
    .venv/bin/crossing-data import-ptl runs/zoom2 --out runs/data/zoom2_default --images reference --no-exif-fov
    .venv/bin/crossing-eval --bundle crossing_assist/assets/default_bundle --data runs/data/zoom2 --split val --portrait 0

Each crop has 1/zoom of the photo's pixels across (PTL's copies are 299 x 224 read back at 4:3),
so it is softer than a real telephoto's photo.
Needs Pillow (to write the EXIF); reads the photos through ``--data`` (an imported PTL).
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from crossing_assist.actions import x_to_bin
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.errors import UserError, run_cli

#: A phone main camera's 35 mm-equivalent focal length, mm (67 deg across a 4:3 landscape photo).
MAIN_CAMERA_MM = 26


def zoom_photo(image: np.ndarray, far_x: float, zoom: float) -> tuple[np.ndarray, float | None]:
    """The middle ``1 / zoom`` of ``image`` (width and height) and the far point's x in it, None
    when it lies outside."""
    h, w = image.shape[:2]
    ch, cw = max(1, round(h / zoom)), max(1, round(w / zoom))
    top, left = (h - ch) // 2, (w - cw) // 2
    x = (far_x * w - left) / cw
    return np.ascontiguousarray(image[top:top + ch, left:left + cw]), (x if 0.0 <= x < 1.0 else None)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="runs/data/ptl", help="an imported PTL dataset (crossing-data import-ptl)")
    ap.add_argument("--split", default="val")
    ap.add_argument("--zoom", type=float, default=2.0, help="how far the camera zooms in (> 1; default 2)")
    ap.add_argument("--out", required=True, help="folder to write (labels.csv and images/)")
    a = ap.parse_args(argv)
    if not a.zoom > 1.0:
        raise UserError(f"Invalid --zoom {a.zoom}; valid: > 1")
    try:
        from PIL import Image  # noqa: PLC0415 - only this script writes EXIF
    except ImportError:
        raise UserError("writing EXIF needs Pillow (pip install pillow)") from None
    ds = read_manifest(a.data)
    rows = [r for r in ds.rows if r.split == a.split and r.far_x is not None]
    if not rows:
        raise UserError(f"{a.data}: no {a.split} photos with a far point")
    out = Path(a.out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    exif = Image.Exif()
    exif.get_ifd(0x8769)[0xA405] = round(MAIN_CAMERA_MM * a.zoom)
    lines, left_out = [], 0
    for r in rows:
        img, x = zoom_photo(load_frame(ds.image_path(r), r.flags), r.far_x, a.zoom)
        if x is None:
            left_out += 1
            continue
        name = f"images/{Path(r.image).stem}_zoom{a.zoom:g}.jpg"
        Image.fromarray(img).save(out / name, quality=95, exif=exif.tobytes())
        who = r.source.split(":", 1)[-1]
        lines.append([name, r.split, who, f"{x:.5f}", x_to_bin(x), "1" if "blocked" in r.flags else "0"])
    with open(out / "labels.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["image", "split", "photographer", "far_x", "bin12", "blocked"])
        w.writerows(lines)
    print(f"wrote {out / 'labels.csv'}: {len(lines)} photos zoomed {a.zoom:g}x "
          f"({round(MAIN_CAMERA_MM * a.zoom)} mm equivalent); {left_out} left out (far point out of view)")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
