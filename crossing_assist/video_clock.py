"""When each frame of a video file was shown: the container's presentation times.

Phones record variable frame rate (fewer frames in low light), so ``index / fps`` drifts from the
picture: a clip of 30 frames at 30 fps then 10 at 5 fps reports 13.3 fps on average, and its
frame 30 is at 1.33 s, not 2.25 s. OpenCV gives each frame's own time after ``read()``
(``CAP_PROP_POS_MSEC``); a raw elementary stream carries none (always 0), and then the times
step by the frame rate.
"""

from __future__ import annotations

import math


class FrameClock:
    """Frame times of one video, read in order: :meth:`time` after each ``read()``."""

    def __init__(self, fps: float) -> None:
        self.fps = float(fps)
        self.last: float | None = None

    def time(self, pos_msec: float) -> float:
        """The time (s) of the frame just read, given ``CAP_PROP_POS_MSEC``: the container's own
        where it moves forward, else one frame period after the last frame (so times only rise)."""
        t = pos_msec / 1000.0 if math.isfinite(pos_msec) else -1.0
        if self.last is None:
            t = max(t, 0.0)
        elif not t > self.last:
            t = self.last + 1.0 / self.fps
        self.last = t
        return t
