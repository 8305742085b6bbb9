"""Test clips for the phone app's fake camera (numpy only).

Chromium's ``--use-file-for-fake-video-capture=clip.y4m`` plays a raw YUV4MPEG2 4:2:0 file in a
loop as if it were the camera. :func:`write_y4m` writes RGB frames in that format with BT.601
*limited-range* coefficients (what Chromium assumes when it turns the frames back into RGB),
so a frame's pixels survive the round trip to within a few levels (exactly for greys, where
chroma is 128).

:func:`bar_clip` makes the clip the end-to-end test uses: a mid-grey frame with a bright,
coloured vertical bar (the "goal" of the test bundle's brightness detector) that sits left,
sweeps right, sits right, disappears (plain grey: the model cannot tell), and finally sits
right in exactly repeated frames (a frozen camera). With ``flip_s`` > 0 the bar first hops
between strips 7 and 8 every second for ``flip_s`` seconds (the heading crosses the 7.5 degree
"straight ahead" boundary: the spoken advice must not chatter). Every other frame carries a little
sensor noise, as a live camera's does, so that only the frozen segment repeats itself.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def rgb_to_i420(frame: np.ndarray) -> bytes:
    """H x W x 3 uint8 RGB (H, W even) -> I420 planes (Y, then U, V at half resolution), limited range."""
    if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3 or frame.shape[0] % 2 or frame.shape[1] % 2:
        raise ValueError(f"Invalid frame: shape {frame.shape} dtype {frame.dtype}; expected H x W x 3 uint8 with even H, W")
    rgb = frame.astype(np.float64) / 255.0
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    y = 16 + 219 * (0.299 * r + 0.587 * g + 0.114 * b)
    u = 128 + 224 * (-0.168736 * r - 0.331264 * g + 0.5 * b)
    v = 128 + 224 * (0.5 * r - 0.418688 * g - 0.081312 * b)

    def half(p: np.ndarray) -> np.ndarray:
        return 0.25 * (p[0::2, 0::2] + p[1::2, 0::2] + p[0::2, 1::2] + p[1::2, 1::2])

    planes = [y, half(u), half(v)]
    return b"".join(np.clip(np.rint(p), 0, 255).astype(np.uint8).tobytes() for p in planes)


def write_y4m(path: str | Path, frames: list[np.ndarray] | np.ndarray, fps: int) -> Path:
    """Write RGB frames (each H x W x 3 uint8, all the same size) as a 4:2:0 Y4M file at ``fps``."""
    if len(frames) == 0:
        raise ValueError("Invalid clip: no frames")
    h, w = frames[0].shape[:2]
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(f"YUV4MPEG2 W{w} H{h} F{int(fps)}:1 Ip A1:1 C420jpeg\n".encode())
        for frame in frames:
            if frame.shape[:2] != (h, w):
                raise ValueError(f"Invalid clip: frame of shape {frame.shape} in a {h}x{w} clip")
            f.write(b"FRAME\n")
            f.write(rgb_to_i420(frame))
    tmp.replace(path)
    return path


BAR_RGB = (250, 215, 120)  # distinct channels: a swapped channel order would show


def bar_frame(width: int, height: int, strip: float | None, grey: int = 110,
              bar: tuple[int, int, int] = BAR_RGB) -> np.ndarray:
    """A grey frame with a bright vertical bar one strip wide starting at strip ``strip`` (1..12,
    may be fractional); ``strip=None`` gives a plain grey frame. H x W x 3 uint8 RGB."""
    frame = np.full((height, width, 3), grey, np.uint8)
    if strip is not None:
        w = width / 12
        x0 = int(round((strip - 1) * w))
        frame[:, max(0, x0):min(width, int(round(x0 + w)))] = bar
    return frame


def bar_clip(width: int = 160, height: int = 120, fps: int = 10, *, noise: int = 3, seed: int = 0,
             flip_s: int = 0) -> tuple[list[np.ndarray], list[float | None], list[bool]]:
    """The test clip: frames, the bar's strip in each (None = no bar) and whether the frame is
    part of the frozen segment. 3 s at strip 3, 2 s sweeping to strip 10, 2.5 s at strip 10,
    ``flip_s`` s hopping between strips 7 and 8 each second, 1.5 s of plain grey, then 2 s of one
    frame (bar at strip 10) repeated exactly: 11 s + ``flip_s``.
    Live frames get uniform integer noise in [-noise, noise] (``seed`` fixes it)."""
    rng = np.random.default_rng(seed)
    strips: list[float | None] = [3.0] * (3 * fps)
    strips += [3.0 + 7.0 * (i + 1) / (2 * fps) for i in range(2 * fps)]
    strips += [10.0] * int(2.5 * fps)
    last_at_10 = len(strips) - 1
    strips += [7.0 if (i // fps) % 2 == 0 else 8.0 for i in range(flip_s * fps)]
    strips += [None] * int(1.5 * fps)
    frames = []
    for s in strips:
        f = bar_frame(width, height, s).astype(np.int16)
        f += rng.integers(-noise, noise + 1, size=f.shape, dtype=np.int16)
        frames.append(np.clip(f, 0, 255).astype(np.uint8))
    frozen = frames[last_at_10]  # the last frame with the bar at strip 10
    n_frozen = 2 * fps
    return (frames + [frozen] * n_frozen, strips + [10.0] * n_frozen,
            [False] * len(frames) + [True] * n_frozen)


def view_crop_clip(width: int, height: int, keep: tuple[int, int], fps: int = 10, seconds: int = 8, *,
                   noise: int = 3, seed: int = 0) -> tuple[list[np.ndarray], list[tuple[int, int]]]:
    """A clip for the view crop (bundle schema 3): in the rows ``keep`` = (top, rows) the graph
    should see, a grey bar (200) at one strip; in the rows above and below them, a brighter bar
    (255) at another strip. A model that sees only the kept rows finds the first strip; one that
    sees the whole frame the second (it covers as many rows and is brighter). The two strips
    swap every 3 s. Returns the frames and each frame's (kept strip, outer strip), 1..12."""
    rng = np.random.default_rng(seed)
    top, rows = keep
    if not 0 < rows < height:
        raise ValueError(f"Invalid keep {keep}: the rows kept must leave some of the {height} rows out")
    frames, strips = [], []
    for i in range(seconds * fps):
        inner, outer = (4, 9) if (i // (3 * fps)) % 2 == 0 else (9, 4)
        f = bar_frame(width, height, outer, grey=110, bar=(255, 255, 255))
        f[top:top + rows] = bar_frame(width, rows, inner, grey=110, bar=(200, 200, 200))
        f = f.astype(np.int16) + rng.integers(-noise, noise + 1, size=f.shape, dtype=np.int16)
        frames.append(np.clip(f, 0, 255).astype(np.uint8))
        strips.append((inner, outer))
    return frames, strips
