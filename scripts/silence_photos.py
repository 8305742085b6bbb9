"""Is the beacon silent on real photos with no crossing in them, from anywhere?

Plays every image under the given folders (``.png``, ``.jpg``, ``.jpeg``, EXIF orientation applied)
as a 1 s still clip at 10 fps through the runtime (engine + filter + gate, ``runtime/listen.py``),
as it is and turned 90 degrees (a phone held the other way), and reports which plays turn the
beacon on and, for plays whose last frame names a strip, how far its uncertainty stays above its
orientation's gate threshold (the least margin says how near the gate came to speaking). Use it
on your own walks with no crossing in view, or on the sample photos scikit-image ships in its
wheel (read where pip installed them, never copied here; none shows a street crossing)::

    .venv/bin/pip install scikit-image
    .venv/bin/python scripts/silence_photos.py \
        "$(.venv/bin/python -c 'import os, skimage; print(os.path.dirname(skimage.__file__))')/data"

``--fov 41`` plays them as a narrow camera sees them (9:16 video: its portrait frames take the
bundle's narrow camera threshold, the loosest). A missing folder, one without an image or an
unusable bundle is one line and exit 1 (a FOV outside 20..170 degrees: every play fails, silent);
the figures are printed, nothing is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from crossing_assist.actions import UNKNOWN
from crossing_assist.bundle import BundleError
from crossing_assist.data_tools.images import ImageError, load_frame
from crossing_assist.geometry import orientation
from crossing_assist.runtime.demo import DEFAULT_BUNDLE
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.listen import Listener, summarise

SUFFIXES = (".png", ".jpg", ".jpeg")


def photos(folders: list[Path]) -> list[Path]:
    """The images under ``folders``, sorted; a missing folder or one without an image raises
    SystemExit (one line)."""
    out = []
    for folder in folders:
        if not folder.is_dir():
            raise SystemExit(f"error: {folder} is not a folder")
        found = sorted(p for p in folder.rglob("*") if p.suffix.lower() in SUFFIXES)
        if not found:
            raise SystemExit(f"error: no .png/.jpg image under {folder}")
        out += found
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", type=Path, help="folders of photos with no crossing in view")
    ap.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE, help="bundle folder (default: the embedded one)")
    ap.add_argument("--fov", type=float, metavar="DEG", help="play every image as seen by a camera DEG across (e.g. 41: "
                    "9:16 video, whose portrait frames take a narrow camera's gate threshold); default: the bundle's")
    a = ap.parse_args(argv)
    try:
        engine = Engine(a.bundle, threads=2)
    except BundleError as exc:
        raise SystemExit(f"error: {exc}") from None
    lis = Listener(engine)
    names = []
    for path in photos(a.folders):
        try:
            frame = load_frame(path)
        except ImageError as exc:
            print(f"skipped: {exc}")
            continue
        for turn, view in (("as taken", frame), ("turned", np.ascontiguousarray(np.rot90(frame)))):
            lis.add(view, UNKNOWN, a.fov)
            names.append(f"{path.name} ({turn}, {orientation(view.shape[1], view.shape[0])})")
    if not lis.clips:
        raise SystemExit("error: no image could be read")
    heard = lis.heard()
    margins = []   # a strip's play: the last frame's uncertainty minus the gate threshold; else NaN
    print("| image | beacon | the model's last frame | uncertainty - gate threshold |\n|---|---|---|---:|")
    for name, clip, h in zip(names, lis.clips, heard):
        last = clip[-1]
        if not last.ok:
            margins.append(float("nan"))
            print(f"| {name} | {'ON' if h.on else 'off'} | failed: {last.error} | |")
            continue
        says = f"unknown (p {last.probs[UNKNOWN]:.2f})" if last.action == UNKNOWN else f"strip {last.action}"
        thr = engine.decision_config(last.orientation or "landscape", last.fov_deg).threshold
        margins.append(float("nan") if last.action == UNKNOWN else last.uncertainty - thr)
        print(f"| {name} | {'ON, strip ' + str(h.strip) if h.on else 'off'} | {says}, {engine.measure} "
              f"{last.uncertainty:.3f} | {'' if np.isnan(margins[-1]) else format(margins[-1], '+.3f')} |")
    s = summarise(heard)
    strips = [i for i, m in enumerate(margins) if not np.isnan(m)]
    least = min(strips, key=margins.__getitem__) if strips else None
    print(f"\nsilent on {s['silence_no_crossing']:.1%} of {len(heard)} plays ({len(heard) // 2} images, each both ways); "
          f"beacon on for {sum(h.on for h in heard)}; the model names a strip on {len(strips)}"
          + (f", least margin {margins[least]:+.3f} ({names[least]})" if least is not None else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
