"""Clips made from labelled photos: a phone panning across real crossings, with ground truth.

Each of ``count`` photos (those with a known goal, spread over the split) is shown for
``seconds_each``: a window of the phone's ``aspect`` (3:4 portrait by default; 4:3 keeps the
whole landscape photo) slides from the photo's left edge to its right, so the goal sweeps across
the frame and out of view. The sidecar ``<clip>.json`` (the same fields as ``synth --video``,
read by :mod:`crossing_assist.runtime.truth`) holds per frame the label (bin of the window, the
edge strip when the goal is out of view but inferable) and the goal's bearing. The window's
horizontal field of view follows from the photo's (``fov_deg``, the camera that took it; by
default the row's own ``fov=DEG`` flag, e.g. from its EXIF at import, else a phone's for the
photo's orientation and aspect, 67 deg for a 4:3 landscape photo and 53 deg for a 3:4 portrait
one, :func:`~crossing_assist.geometry.letterbox_geometry`):
``2 atan(w'/W tan(fov/2))``; ``crossing-demo --fov`` should be given that value (printed, and in
the sidecar's ``fov_deg``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from crossing_assist.actions import UNKNOWN, format_label, x_to_bin
from crossing_assist.data_tools.images import ImageError, frame_fov, load_frame
from crossing_assist.data_tools.manifest import ManifestError, atomic_write_text, read_manifest
from crossing_assist.geometry import GeometryError, check_fov, letterbox_geometry, window_fov


@dataclass(frozen=True)
class PhotoClipConfig:
    dataset: Path
    out: Path
    split: str = "val"
    count: int = 6
    seconds_each: float = 3.0
    fps: float = 10.0
    aspect: float = 3 / 4          # width / height of the phone's frame
    height: int = 320              # output frame height (px)
    fov_deg: float | None = None   # horizontal FOV of the photos' camera (None: each row's fov flag, else a phone's for its shape)


def make_photo_clip(cfg: PhotoClipConfig) -> tuple[Path, Path, float]:
    """Write the clip (mp4v, atomic) and its sidecar; returns (clip, sidecar, window FOV)."""
    out = Path(cfg.out)
    if out.suffix.lower() != ".mp4":
        raise ManifestError(f"--out {out} invalid; expected a file name ending in .mp4")
    if not (1 <= cfg.count <= 200 and 0.5 <= cfg.seconds_each <= 30 and 1 <= cfg.fps <= 60):
        raise ManifestError(f"count={cfg.count} seconds_each={cfg.seconds_each} fps={cfg.fps} invalid; "
                            "valid: 1..200 photos, 0.5..30 s each, 1..60 fps")
    if not 0.2 <= cfg.aspect <= 5:
        raise ManifestError(f"aspect={cfg.aspect:.3f} invalid; valid: 0.2..5 (width / height)")
    if cfg.fov_deg is not None:
        try:
            check_fov(cfg.fov_deg)
        except GeometryError as exc:
            raise ManifestError(f"photo FOV: {exc}") from None
    ds = read_manifest(cfg.dataset).split(cfg.split)
    rows = [r for r in ds.rows if r.label != UNKNOWN and r.far_x is not None]
    if not rows:
        raise ManifestError(f"{cfg.dataset}: split {cfg.split!r} has no photo with a known goal (far_x)")
    rows = [rows[i] for i in np.linspace(0, len(rows) - 1, min(cfg.count, len(rows))).astype(int)]
    h = int(cfg.height)
    w = max(8, int(round(cfg.aspect * h)))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.tmp.mp4")
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), cfg.fps, (w, h))
    if not writer.isOpened():
        raise ManifestError(f"OpenCV cannot write mp4v video to {tmp}")
    truth: dict[str, list] = {"t": [], "far_x": [], "label": [], "photo": [], "goal_azimuth_deg": []}
    per = max(2, int(round(cfg.seconds_each * cfg.fps)))
    fovs, photo_fovs = [], []
    try:
        for r in rows:
            photo = load_frame(ds.image_path(r), r.flags)
            ph, pw = photo.shape[:2]
            try:
                photo_fov = cfg.fov_deg or frame_fov(r.flags) or letterbox_geometry().camera_fov(pw, ph)
            except (GeometryError, ImageError) as exc:
                raise ManifestError(f"{r.image}: {exc}; give the camera's with --photo-fov") from None
            photo_fovs.append(photo_fov)
            if w > int(round(pw * h / ph)) + 1:
                raise ManifestError(f"--aspect {cfg.aspect:.3f} is wider than the photo {r.image} ({pw}x{ph}); "
                                    "a window cannot be wider than what the camera saw")
            photo = cv2.resize(photo, (max(w, int(round(pw * h / ph))), h), interpolation=cv2.INTER_AREA)
            pw = photo.shape[1]
            fov = window_fov(min(1.0, w / pw), photo_fov)   # a full-height window of the photo
            fovs.append(fov)
            f_px = (pw / 2) / math.tan(math.radians(photo_fov) / 2)   # the photo camera's focal length
            goal_px = r.far_x * pw
            for k in range(per):
                x0 = int(round((pw - w) * k / (per - 1)))
                frame = photo[:, x0:x0 + w]
                writer.write(cv2.cvtColor(np.ascontiguousarray(frame), cv2.COLOR_RGB2BGR))
                x = (goal_px - x0) / w
                # bearing from the window's optical axis (its centre column), + right
                az = math.degrees(math.atan2(goal_px - (x0 + w / 2), f_px))
                inside = 0.0 <= x < 1.0
                truth["t"].append(round(len(truth["t"]) / cfg.fps, 4))
                truth["far_x"].append(round(x, 5) if inside else None)
                truth["label"].append(format_label(x_to_bin(min(max(x, 1e-6), 1 - 1e-6))))
                truth["photo"].append(r.image)
                truth["goal_azimuth_deg"].append(round(az, 3))
    finally:
        writer.release()
    tmp.replace(out)
    fov = float(np.mean(fovs))
    meta = {"synthetic": False, "description": f"{len(rows)} labelled photos from {cfg.dataset} ({cfg.split}), "
            f"a {w}x{h} window panning across each", "fps": cfg.fps, "size": [w, h], "fov_deg": round(fov, 3),
            "photo_fov_deg": [round(f, 3) for f in photo_fovs], "n_frames": len(truth["t"]), "codec": "mp4v", **truth}
    side = out.with_suffix(".json")
    atomic_write_text(side, json.dumps(meta, indent=1) + "\n")
    return out, side, fov
