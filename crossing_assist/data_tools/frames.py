"""``crossing-data frames``: frames from videos at a fixed rate, ready for labelling.

For each video, frame ``k`` is the first decoded frame at or after ``k / fps`` seconds
(timestamps from the frame index and the video's own frame rate). Frames are written as
``OUT/<video>/<video>_t<seconds>.jpg`` (``corner03_t0012.500.jpg``: sorts by time) and listed
in ``OUT/frames.csv`` (``image,source,video,t_s``, and ``fov_deg`` when the camera's FOV is
given) with source ``vid:<video>``, the leakage unit for splits; ``crossing-data votes`` carries
the FOV into the manifest as an ``fov=DEG`` flag, which ``crossing-eval`` plays the frames at. A
video that cannot be opened or yields no frame is reported and skipped; the others are still
processed; a photo given as a video is refused. ``OUT/label_studio_tasks.json`` lists the same frames as
Label Studio tasks served from local files (``/data/local-files/?d=<OUT name>/<image>``: set
``LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT`` to OUT's parent folder). A video that ends before its header's frame count
(truncated) keeps the frames decoded so far and gets a warning.
"""

from __future__ import annotations

import csv
import io
import json
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
from tqdm import tqdm

from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import atomic_write_text
from crossing_assist.errors import UserError
from crossing_assist.video_clock import FrameClock

FRAMES_CSV = "frames.csv"
LABEL_STUDIO_TASKS = "label_studio_tasks.json"
#: Photos, not videos: OpenCV would open one as a one-frame video, ignoring its EXIF orientation.
PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".heic", ".heif", ".webp", ".bmp", ".tif", ".tiff")


class VideoError(UserError):
    """A video that cannot be read; names the file."""


@dataclass(frozen=True)
class FramesConfig:
    videos: tuple[Path, ...]
    out_dir: Path
    fps: float = 2.0
    quality: int = 92
    progress: bool = True
    fov_deg: float | None = None    # the videos' camera: horizontal field of view, degrees (None: unknown)


@dataclass(frozen=True)
class VideoResult:
    """What happened to one video: frames written, and an error or a warning (or neither)."""

    video: Path
    name: str
    frames: tuple[tuple[str, float], ...]     # (image path relative to out_dir, t in s)
    error: str | None = None
    warning: str | None = None


def video_name(path: Path, taken: set[str]) -> str:
    """A file-system-safe, unique name for a video (its stem; ``_2``, ``_3``… on clashes)."""
    base = re.sub(r"[^A-Za-z0-9_-]+", "_", Path(path).stem).strip("_") or "video"
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    taken.add(name)
    return name


def extract_video(path: Path, name: str, cfg: FramesConfig) -> VideoResult:
    """Write the frames of one video; errors are returned in the result, not raised."""
    if not Path(path).is_file():
        return VideoResult(path, name, (), error=f"{path}: no such file")
    if Path(path).suffix.lower() in PHOTO_SUFFIXES:
        return VideoResult(path, name, (), error=f"{path}: a photo, not a video; crossing-data frames reads videos "
                                                 "(photos: crossing-data import-ptl, which turns them upright by EXIF)")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        return VideoResult(path, name, (), error=f"{path}: cannot open as a video (empty, corrupt or unknown format)")
    try:
        native = cap.get(cv2.CAP_PROP_FPS)
        native = native if 0 < native < 1000 else None
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        expect = int(count / native * cfg.fps) + 1 if native and count > 0 else None
        written: list[tuple[str, float]] = []
        next_t, index = 0.0, 0
        clock = FrameClock(native or 30.0)
        bar = tqdm(total=expect, desc=name[:24], unit="frame", disable=not cfg.progress, leave=False)
        while True:
            ok, frame = cap.read()
            if not ok or frame is None:
                break
            t = clock.time(cap.get(cv2.CAP_PROP_POS_MSEC))   # the frame's own time: phones record variable frame rate
            index += 1
            if t + 1e-6 < next_t:
                continue
            rel = f"{name}/{name}_t{t:09.3f}.jpg"
            save_rgb(cfg.out_dir / rel, cv2.cvtColor(frame, cv2.COLOR_BGR2RGB), quality=cfg.quality)
            written.append((rel, round(t, 3)))
            bar.update(1)
            while next_t <= t + 1e-6:
                next_t += 1.0 / cfg.fps
        bar.close()
    finally:
        cap.release()
    if not written:
        return VideoResult(path, name, (), error=f"{path}: no frame could be decoded (empty or truncated video)")
    warning = None
    if count > 0 and index < count * 0.98 - 1:
        warning = (f"{path}: decoding stopped at frame {index} of {count} (t={clock.last or 0.0:.2f} s); "
                   "the file looks truncated; kept the frames before that point")
    return VideoResult(path, name, tuple(written), warning=warning)


def extract_frames(cfg: FramesConfig) -> tuple[list[VideoResult], Path | None]:
    """Extract every video; write ``frames.csv`` listing all frames written (None if none)."""
    if not 0 < cfg.fps <= 120:
        raise VideoError(f"fps={cfg.fps} invalid; valid: 0 < fps <= 120")
    if not cfg.videos:
        raise VideoError("no videos given")
    if cfg.fov_deg is not None:
        from crossing_assist.geometry import GeometryError, check_fov
        try:
            check_fov(cfg.fov_deg)
        except GeometryError as exc:
            raise VideoError(f"--fov: {exc}") from None
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    taken: set[str] = set()
    results = [extract_video(Path(v), video_name(Path(v), taken), cfg) for v in cfg.videos]
    if not any(r.frames for r in results):
        return results, None
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    fov = [] if cfg.fov_deg is None else [f"{float(cfg.fov_deg):g}"]
    writer.writerow(["image", "source", "video", "t_s"] + (["fov_deg"] if fov else []))
    for r in results:
        for rel, t in r.frames:
            writer.writerow([rel, f"vid:{r.name}", str(r.video), f"{t:.3f}", *fov])
    path = out / FRAMES_CSV
    atomic_write_text(path, buf.getvalue())
    tasks = [{"data": {"image": f"/data/local-files/?d={out.name}/{rel}", "source": f"vid:{r.name}", "t_s": t}}
             for r in results for rel, t in r.frames]
    atomic_write_text(out / LABEL_STUDIO_TASKS, json.dumps(tasks, indent=1) + "\n")
    return results, path
