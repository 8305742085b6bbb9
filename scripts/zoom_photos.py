"""Photos from a phone zoomed in (2x, 3x), or cropped afterwards, as a PTL-layout folder with the
EXIF a phone writes.

Each labelled photo of ``--split`` is cut to its middle ``1 / zoom`` of the width and height (what a
phone's 2x or 3x camera sees from the same spot) and saved as a JPEG carrying the lens's
35 mm-equivalent focal length (EXIF ``FocalLengthIn35mmFilm``: 26 mm x zoom, a phone main camera's
26 mm zoomed) and the size of the image it recorded (``PixelXDimension`` / ``PixelYDimension``),
with ``labels.csv`` in the PTL layout: the far point moves exactly,
``x' = (x - (1 - 1/zoom) / 2) * zoom``; photos whose far point leaves the view are left out.
Import it as a researcher would (``crossing-data import-ptl``: each photo gets its camera's FOV
from the EXIF) and play it through the runtime (``crossing-eval --bundle``); import it again with
``--no-exif-fov`` to hear what the default FOV (67 deg for a landscape photo) would make of it::

    .venv/bin/python scripts/zoom_photos.py --zoom 2 --out runs/zoom2
    .venv/bin/crossing-data import-ptl runs/zoom2 --out runs/data/zoom2 --images reference
    .venv/bin/crossing-data import-ptl runs/zoom2 --out runs/data/zoom2_default --images reference --no-exif-fov
    .venv/bin/crossing-eval --bundle crossing_assist/assets/default_bundle --data runs/data/zoom2 --split val --portrait 0

``--cut W:H`` instead crops each photo afterwards, as an editor does, to the largest centred cut of
that aspect (full height or full width), keeping the 26 mm camera's EXIF and the recorded size of
the whole photo; ``--no-recorded-size`` leaves the size out, so the FOV is read from the cut's own
diagonal. A square cut (import it with ``--square square``) sees 53.1 deg, the 4:3 photo's height.

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
from crossing_assist.geometry import parse_ratio

#: A phone main camera's 35 mm-equivalent focal length, mm (67 deg across a 4:3 landscape photo).
MAIN_CAMERA_MM = 26


def centre_crop(image: np.ndarray, far_x: float, height: int, width: int) -> tuple[np.ndarray, float | None]:
    """The centred ``height x width`` part of ``image`` and the far point's x in it, None when it
    lies outside."""
    h, w = image.shape[:2]
    top, left = (h - height) // 2, (w - width) // 2
    x = (far_x * w - left) / width
    return np.ascontiguousarray(image[top:top + height, left:left + width]), (x if 0.0 <= x < 1.0 else None)


def zoom_photo(image: np.ndarray, far_x: float, zoom: float) -> tuple[np.ndarray, float | None]:
    """The middle ``1 / zoom`` of ``image`` (width and height) and the far point's x in it, None
    when it lies outside."""
    h, w = image.shape[:2]
    return centre_crop(image, far_x, max(1, round(h / zoom)), max(1, round(w / zoom)))


def cut_photo(image: np.ndarray, far_x: float, aspect: float) -> tuple[np.ndarray, float | None]:
    """The largest centred cut of ``image`` of ``aspect`` (width / height: full height when it is
    narrower than the photo, else full width) and the far point's x in it, None when outside."""
    h, w = image.shape[:2]
    if aspect < w / h:
        return centre_crop(image, far_x, h, max(1, round(h * aspect)))
    return centre_crop(image, far_x, max(1, round(w / aspect)), w)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="runs/data/ptl", help="an imported PTL dataset (crossing-data import-ptl)")
    ap.add_argument("--split", default="val")
    ap.add_argument("--zoom", type=float, default=2.0, help="how far the camera zooms in (> 1; default 2)")
    ap.add_argument("--cut", metavar="W:H", help="instead of zooming, crop each photo afterwards to the largest "
                                                 "centred cut of this aspect (e.g. 1:1, 16:9), its EXIF kept")
    ap.add_argument("--no-recorded-size", action="store_true", help="leave the recorded image size out of the EXIF")
    ap.add_argument("--out", required=True, help="folder to write (labels.csv and images/)")
    a = ap.parse_args(argv)
    if not a.zoom > 1.0:
        raise UserError(f"Invalid --zoom {a.zoom}; valid: > 1")
    try:
        cut = None if a.cut is None else parse_ratio(a.cut)
    except ValueError:
        raise UserError(f"Invalid --cut {a.cut!r}; expected W:H, e.g. 1:1") from None
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
    focal = MAIN_CAMERA_MM if cut else round(MAIN_CAMERA_MM * a.zoom)
    tag = f"cut{a.cut.replace(':', 'x')}" if cut else f"zoom{a.zoom:g}"
    lines, left_out = [], 0
    for r in rows:
        photo = load_frame(ds.image_path(r), r.flags)
        img, x = cut_photo(photo, r.far_x, cut) if cut else zoom_photo(photo, r.far_x, a.zoom)
        if x is None:
            left_out += 1
            continue
        exif = Image.Exif()
        exif.get_ifd(0x8769)[0xA405] = focal
        if not a.no_recorded_size:   # the camera's image: the whole photo a cut was taken from, else the zoomed one
            recorded = photo if cut else img
            exif.get_ifd(0x8769).update({0xA002: recorded.shape[1], 0xA003: recorded.shape[0]})
        name = f"images/{Path(r.image).stem}_{tag}.jpg"
        Image.fromarray(img).save(out / name, quality=95, exif=exif.tobytes())
        who = r.source.split(":", 1)[-1]
        lines.append([name, r.split, who, f"{x:.5f}", x_to_bin(x), "1" if "blocked" in r.flags else "0"])
    with open(out / "labels.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["image", "split", "photographer", "far_x", "bin12", "blocked"])
        w.writerows(lines)
    what = f"cut to {a.cut}" if cut else f"zoomed {a.zoom:g}x"
    print(f"wrote {out / 'labels.csv'}: {len(lines)} photos {what} ({focal} mm equivalent); "
          f"{left_out} left out (far point out of view)")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
