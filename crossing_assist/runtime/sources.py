"""Frame sources: a video file (its frames' own presentation times) or a camera (monotonic clock).

A source yields ``(t_seconds, frame_rgb)`` with ``frame_rgb`` H x W x 3 uint8 RGB; it ends when
the video ends or the camera stops delivering. Tests substitute any iterable of such pairs.
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from crossing_assist.errors import UserError
from crossing_assist.video_clock import FrameClock

#: Widest frame a live camera's stream is scaled to (the app's grab does the same).
CAMERA_WIDTH = 640


class SourceError(UserError, RuntimeError):
    """A video or camera that cannot be opened; one line naming it."""


class VideoSource:
    """Frames of a video file in order; ``t`` is each frame's presentation time in the file
    (:class:`~crossing_assist.video_clock.FrameClock`: right for variable frame rate; ``index /
    fps`` where the file carries no times)."""

    def __init__(self, path: str | Path, *, max_width: int | None = None) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise SourceError(f"video {self.path} does not exist")
        self._cap = cv2.VideoCapture(str(self.path))
        if not self._cap.isOpened():
            raise SourceError(f"video {self.path} cannot be opened by OpenCV (unsupported or corrupt file)")
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = fps if 1.0 <= fps <= 1000.0 else 30.0
        self.frame_count = max(0, int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0))   # raw streams: garbage
        self.max_width = max_width

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        clock = FrameClock(self.fps)
        try:
            while True:
                ok, bgr = self._cap.read()
                if not ok or bgr is None:
                    return
                yield clock.time(self._cap.get(cv2.CAP_PROP_POS_MSEC)), _to_rgb(bgr, self.max_width)
        finally:
            self._cap.release()


class CameraSource:
    """The newest frame of camera ``index`` each time the loop asks; ``t`` is ``time.monotonic()``
    when the driver handed it over.

    A reader thread takes every frame as it arrives and keeps only the newest: reading in the
    loop itself returns the oldest of the driver's queued frames (V4L2 keeps about four), so
    behind a slow model a frame 4 camera periods old (0.8 s at 5 fps in low light) was stamped
    now and counted fresh. Frames the loop had no time for are dropped, never queued."""

    def __init__(self, index: int, *, max_width: int | None = CAMERA_WIDTH) -> None:
        self._cap = cv2.VideoCapture(int(index))
        if not self._cap.isOpened():
            raise SourceError(f"camera {index} cannot be opened; check the index (0 is usually the first camera)")
        self.max_width = max_width
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = fps if 1.0 <= fps <= 240.0 else 30.0
        self.frame_count = 0
        self.dropped = 0   # frames the loop never took (a newer one had arrived)

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        newest: list = [None, 0.0, 0]   # frame (BGR) or None, its time, how many have arrived
        ended = threading.Event()
        arrived = threading.Condition()

        def read() -> None:
            try:
                while not ended.is_set():
                    ok, bgr = self._cap.read()
                    t = time.monotonic()
                    if not ok or bgr is None:
                        return
                    with arrived:
                        newest[:] = [bgr, t, newest[2] + 1]
                        arrived.notify()
            finally:
                self._cap.release()   # here, never while a read may still be running
                with arrived:
                    ended.set()
                    arrived.notify()

        reader = threading.Thread(target=read, name="camera-reader", daemon=True)
        reader.start()
        taken = 0
        try:
            while True:
                with arrived:
                    arrived.wait_for(lambda: newest[2] > taken or ended.is_set())
                    if newest[2] == taken:   # the camera ended with no frame left
                        return
                    bgr, t, count = newest
                self.dropped += count - taken - 1
                taken = count
                yield t, _to_rgb(bgr, self.max_width)
        finally:
            ended.set()   # the reader stops after its current read (a hung camera: when it returns)
            reader.join(timeout=2.0)


def scale_to_width(image: np.ndarray, max_width: int | None) -> np.ndarray:
    """``image`` scaled down to ``max_width`` columns when wider (None: as it is), as a camera's
    stream gives it: the app's arithmetic (camera.js grab), halves rounding up as Math.round does
    (Python's round() gave 1280 x 721 360 rows where the app gives 361)."""
    if max_width and image.shape[1] > max_width:
        h = max(1, math.floor(image.shape[0] * (max_width / image.shape[1]) + 0.5))
        image = cv2.resize(image, (max_width, h), interpolation=cv2.INTER_AREA)
    return image


def _to_rgb(bgr: np.ndarray, max_width: int | None) -> np.ndarray:
    return cv2.cvtColor(scale_to_width(bgr, max_width), cv2.COLOR_BGR2RGB)
