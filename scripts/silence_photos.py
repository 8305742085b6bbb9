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

A photo whose EXIF gives its lens's 35 mm-equivalent focal length (phones write it) is played at
the FOV that gives, as taken and turned (:mod:`crossing_assist.data_tools.exif`); others at the
bundle's for their orientation. ``--fov 41`` plays them all as a narrow camera sees them (9:16
video: its portrait frames take the bundle's narrow camera threshold, the loosest). A missing
folder, one without an image or an unusable bundle is one line and exit 1 (a FOV outside 20..170
degrees: every play fails, silent); the figures are printed, nothing is written.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crossing_assist.actions import UNKNOWN
from crossing_assist.bundle import BundleError
from crossing_assist.data_tools.exif import read_camera
from crossing_assist.data_tools.images import ImageError, load_frame
from crossing_assist.geometry import orientation
from crossing_assist.runtime.demo import DEFAULT_BUNDLE
from crossing_assist.runtime.engine import Engine, Prediction
from crossing_assist.runtime.listen import Heard, Listener, summarise

SUFFIXES = (".png", ".jpg", ".jpeg")


def open_engine(bundle: Path, *, threads: int = 2, seed: int = 0) -> Engine:
    """The bundle's engine (onnxruntime ``threads``, MC-dropout ``seed``); a bundle that cannot be
    used raises SystemExit (one line)."""
    try:
        return Engine(bundle, threads=threads, seed=seed)
    except BundleError as exc:
        raise SystemExit(f"error: {exc}") from None


@dataclass(frozen=True)
class Play:
    """One frame with no crossing, played as a still clip: what the user heard at the end, the
    clip's last prediction and the gate threshold for its camera (orientation and FOV)."""

    heard: Heard
    last: Prediction
    threshold: float

    @property
    def margin(self) -> float:
        """The last frame's uncertainty minus the gate threshold when that frame names a strip
        (how near the gate came to speaking); NaN when it failed or says unknown."""
        return self.last.uncertainty - self.threshold if self.last.ok and self.last.action != UNKNOWN else float("nan")


def play(lis: Listener, frame: np.ndarray, fov_deg: float | None = None) -> Play:
    """Play ``frame`` (camera FOV ``fov_deg``, None = the bundle's for its orientation) through
    ``lis`` as a still clip (1 s at 10 fps by default: engine + filter + gate, ``runtime/listen.py``),
    labelled no crossing (the label feeds only ``summarise``, never the decisions); the clip stays
    in ``lis``."""
    lis.add(frame, UNKNOWN, fov_deg)
    i = len(lis.clips) - 1
    last = lis.clips[i][-1]
    threshold = lis.engine.decision_config(last.orientation or "landscape", last.fov_deg).threshold
    return Play(lis.heard(idx=[i])[0], last, threshold)


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
                    "9:16 video, whose portrait frames take a narrow camera's gate threshold); default: the FOV "
                    "its EXIF focal length gives, else the bundle's")
    a = ap.parse_args(argv)
    engine = open_engine(a.bundle)
    lis = Listener(engine)
    names, plays = [], []
    for path in photos(a.folders):
        try:
            frame = load_frame(path)
        except ImageError as exc:
            print(f"skipped: {exc}")
            continue
        camera = read_camera(path)   # a phone's photo says its lens: each view at its FOV
        for turn, view in (("as taken", frame), ("turned", np.ascontiguousarray(np.rot90(frame)))):
            plays.append(play(lis, view, a.fov or camera.fov(view.shape[1] / view.shape[0])))
            names.append(f"{path.name} ({turn}, {orientation(view.shape[1], view.shape[0])})")
    if not plays:
        raise SystemExit("error: no image could be read")
    print("| image | beacon | the model's last frame | uncertainty - gate threshold |\n|---|---|---|---:|")
    for name, p in zip(names, plays):
        h, last = p.heard, p.last
        if not last.ok:
            print(f"| {name} | {'ON' if h.on else 'off'} | failed: {last.error} | |")
            continue
        says = f"unknown (p {last.probs[UNKNOWN]:.2f})" if last.action == UNKNOWN else f"strip {last.action}"
        print(f"| {name} | {'ON, strip ' + str(h.strip) if h.on else 'off'} | {says}, {engine.measure} "
              f"{last.uncertainty:.3f} | {'' if np.isnan(p.margin) else format(p.margin, '+.3f')} |")
    heard = [p.heard for p in plays]
    s = summarise(heard)
    strips = [i for i, p in enumerate(plays) if not np.isnan(p.margin)]
    least = min(strips, key=lambda i: plays[i].margin) if strips else None
    print(f"\nsilent on {s['silence_no_crossing']:.1%} of {len(heard)} plays ({len(heard) // 2} images, each both ways); "
          f"beacon on for {sum(h.on for h in heard)}; the model names a strip on {len(strips)}"
          + (f", least margin {plays[least].margin:+.3f} ({names[least]})" if least is not None else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
