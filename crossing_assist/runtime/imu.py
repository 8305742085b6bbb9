"""A motion-sensor log recorded with a video, replayed with it: ``crossing-demo VIDEO --imu LOG.csv``.

A phone that films a walk can log its gyroscope and tilt at the same time. Given that log, the
demo hears the video as the phone app would have played it: the decision logic is told the
gyroscope's turn between frames once the picture's turn has confirmed its sign (or from the start
with ``--follow-gyro``), live the beacon is turned with the user between decisions (decision step
10), and each frame is levelled by the camera's roll. Without one, the turn is read from the frames
and a rolled video is used as it is.

The log is a CSV file with a header naming its columns, in any order; others are ignored:

- ``t``: seconds, increasing; the video's first frame is at ``t = offset`` (``--imu-offset``, 0 by
  default; ``--imu-offset auto`` finds it: :func:`align`);
- ``yaw_dps``: the turn rate about the world's vertical, degrees per second, + = turning right
  (the camera's view pans right). From a phone's raw gyroscope held upright in portrait, this is
  minus the rate about the device's y axis (up the screen), in degrees;
- ``roll_deg`` (optional): the camera's roll, degrees, + = the phone turned clockwise as its user
  sees it (the scene then leans counter-clockwise in the frame), as the app reads it from the tilt
  sensor; an empty cell where no roll was known (the phone pointed down, no tilt sensor).

``crossing-data synth --video`` writes one beside each clip (``<clip>.imu.csv``, the camera's own
motion at 100 Hz); the embedded sample clip has one. The phone app records one with its video
(``?record=1``, android_demo/www/js/record.js).
"""

from __future__ import annotations

import bisect
import csv
import math
import threading
import time
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from crossing_assist.errors import UserError
from crossing_assist.runtime.gyro import MAX_SAMPLE_GAP_S, YawIntegrator
from crossing_assist.runtime.visual_yaw import VisualYaw

MAX_RATE_DPS = 2000.0   # a phone gyroscope's full scale: a larger rate is in another unit (rad/s given as deg/s
                        # is smaller and passes; the picture's check then never confirms it, and the summary says so)
MAX_ROLL_DEG = 180.0
MAX_ROWS = 10_000_000
ALIGN_SEARCH_S = 5.0    # offsets tried either way by --imu-offset auto
ALIGN_STEP_S = 0.01
ALIGN_MIN_TURNS = 10    # frames the picture must read a turn on
ALIGN_MIN_SD_DPS = 3.0  # ... varying this much: a steady view tells no offset
ALIGN_MIN_CORR = 0.6    # the best offset's correlation with the picture's turn, at least


class ImuError(UserError):
    """An unreadable or implausible IMU log: one line naming the problem and the fix."""


@dataclass(frozen=True)
class ImuLog:
    """A recorded log on the video's timeline (``t`` already shifted by the offset)."""

    path: Path
    t: tuple[float, ...]
    yaw_dps: tuple[float, ...]
    roll_deg: tuple[float, ...] | None = None

    @classmethod
    def load(cls, path: str | Path, offset: float = 0.0) -> "ImuLog":
        """Read ``path`` (the module's format); ``offset``: the log's time at the video's first
        frame. Raises :class:`ImuError` with the first problem found."""
        path = Path(path)
        if not math.isfinite(offset):
            raise ImuError(f"--imu-offset {offset} invalid; valid: seconds, the log's time at the video's first frame")
        try:
            with open(path, newline="", encoding="utf-8") as f:
                reader = csv.DictReader(f)
                names = [n.strip() for n in (reader.fieldnames or [])]
                missing = [c for c in ("t", "yaw_dps") if c not in names]
                if missing:
                    raise ImuError(f"IMU log {path}: no column {' or '.join(missing)} in its header "
                                   f"(found: {', '.join(names) or 'none'}); needs t, yaw_dps and optionally roll_deg")
                reader.fieldnames = names
                has_roll = "roll_deg" in names
                t: list[float] = []
                yaw: list[float] = []
                roll: list[float] = []
                for row in reader:
                    line = reader.line_num
                    if len(t) >= MAX_ROWS:
                        raise ImuError(f"IMU log {path}: more than {MAX_ROWS} rows")
                    ti = _number(row, "t", path, line)
                    rate = _number(row, "yaw_dps", path, line)
                    if t and not ti > t[-1]:
                        raise ImuError(f"IMU log {path} line {line}: t {ti:g} is not after the row before "
                                       f"({t[-1]:g}); rows must be in time order")
                    if abs(rate) > MAX_RATE_DPS:
                        raise ImuError(f"IMU log {path} line {line}: yaw_dps {rate:g} is beyond a gyroscope's "
                                       f"+-{MAX_RATE_DPS:g} deg/s; is it in another unit?")
                    if has_roll:
                        r = _number(row, "roll_deg", path, line, empty=True)
                        if abs(r) > MAX_ROLL_DEG:
                            raise ImuError(f"IMU log {path} line {line}: roll_deg {r:g} invalid; valid: "
                                           f"-{MAX_ROLL_DEG:g}..{MAX_ROLL_DEG:g} degrees")
                        roll.append(r)
                    t.append(ti)
                    yaw.append(rate)
        except FileNotFoundError:
            raise ImuError(f"IMU log {path} does not exist") from None
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise ImuError(f"IMU log {path} cannot be read as CSV text: {exc}") from None
        if len(t) < 2:
            raise ImuError(f"IMU log {path} has {len(t)} rows; needs at least 2 samples")
        return cls(path, tuple(v - offset for v in t), tuple(yaw), tuple(roll) if has_roll else None)

    def turn(self, t0: float, t1: float) -> float:
        """Degrees turned over [t0, t1], by :class:`~crossing_assist.runtime.gyro.YawIntegrator`'s
        rule (:meth:`turns`)."""
        return float(self.turns(np.asarray(t0), np.asarray(t1))) if t1 > t0 else 0.0

    def between(self, t0: float, t1: float) -> float:
        """Mean turn rate (deg/s) over [t0, t1] (0 when t1 <= t0)."""
        return self.turn(t0, t1) / (t1 - t0) if t1 > t0 else 0.0

    def reporting(self, t: float) -> bool:
        """Whether the gyroscope had reported within :data:`MAX_SAMPLE_GAP_S` before ``t``
        (the live loop's rule: outside the log, or in a gap in it, it is not reporting)."""
        i = bisect.bisect_right(self.t, t) - 1
        return i >= 0 and t - self.t[i] <= MAX_SAMPLE_GAP_S

    def roll_at(self, t: float) -> float | None:
        """The camera's roll at ``t``, interpolated between the two samples around it; None
        without a roll column, where the log does not report, or where no roll was known."""
        if self.roll_deg is None or not self.reporting(t):
            return None
        i = bisect.bisect_right(self.t, t) - 1
        r = self.roll_deg[i]
        if i + 1 < len(self.t) and self.t[i + 1] - self.t[i] <= MAX_SAMPLE_GAP_S and math.isfinite(self.roll_deg[i + 1]):
            r += (t - self.t[i]) / (self.t[i + 1] - self.t[i]) * (self.roll_deg[i + 1] - r)
        return r if math.isfinite(r) else None

    @cached_property
    def _angle(self) -> tuple[np.ndarray, np.ndarray]:
        """The angle turned since the first sample as a piecewise-linear function of time
        (breakpoints, values), by :func:`~crossing_assist.runtime.gyro.integrate`'s rule."""
        t = np.asarray(self.t)
        cover = np.minimum(np.diff(t), MAX_SAMPLE_GAP_S)
        angle = np.concatenate([[0.0], np.cumsum(np.asarray(self.yaw_dps[1:]) * cover)])
        xs = np.empty(2 * len(t) - 1)
        ys = np.empty_like(xs)
        xs[0], ys[0] = t[0], 0.0
        xs[1::2], ys[1::2] = t[1:] - cover, angle[:-1]   # each sample's stretch starts flat ...
        xs[2::2], ys[2::2] = t[1:], angle[1:]             # ... and ends at its own time
        return xs, ys

    def turns(self, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """Degrees turned over many intervals at once (arrays of their starts and ends, each end
        after its start)."""
        xs, ys = self._angle
        return np.interp(t1, xs, ys) - np.interp(t0, xs, ys)

    def shifted(self, offset: float) -> "ImuLog":
        """The log with ``offset`` seconds more taken off its times (its ``t = offset`` is the
        video's first frame)."""
        return replace(self, t=tuple(v - offset for v in self.t))

    def coverage(self, times: list[float]) -> float:
        """Share of ``times`` (frame times) at which the log reports."""
        return sum(self.reporting(t) for t in times) / len(times) if times else 0.0

    def replay(self, gyro: YawIntegrator, start: float, *, clock: Callable[[], float] = time.monotonic,
               sleep: Callable[[float], None] = time.sleep) -> "Replay":
        """Feed the log's gyroscope samples into ``gyro`` as a sensor would, each at ``start + t``
        on ``clock``, on a thread; close the returned :class:`Replay` to stop it."""
        return Replay(self, gyro, start, clock, sleep)


class Replay:
    """A thread handing a log's samples to a :class:`YawIntegrator` in real time (a context manager)."""

    def __init__(self, log: ImuLog, gyro: YawIntegrator, start: float, clock: Callable[[], float],
                 sleep: Callable[[float], None]) -> None:
        self._ended = threading.Event()

        def feed() -> None:
            for t, rate in zip(log.t, log.yaw_dps):
                while not self._ended.is_set() and (wait := start + t - clock()) > 0:
                    sleep(min(wait, 0.05))
                if self._ended.is_set():
                    return
                gyro.add(rate, start + t)

        self._thread = threading.Thread(target=feed, name="crossing-imu-replay", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._ended.set()
        self._thread.join(timeout=1.0)

    def __enter__(self) -> "Replay":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _number(row: dict, name: str, path: Path, line: int, empty: bool = False) -> float:
    """The cell ``name`` of ``row`` as a finite number; ``empty``: an empty cell is NaN (unknown)."""
    raw = row.get(name)
    if empty and (raw is None or not raw.strip()):
        return math.nan
    try:
        v = float(raw)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = math.nan
    if not math.isfinite(v):
        raise ImuError(f"IMU log {path} line {line}: {name} {raw!r} is not a finite number")
    return v


@dataclass(frozen=True)
class Alignment:
    """The log's time at the video's first frame that best lines its gyroscope up with the turn
    read from the video's frames, and how well: the correlation of the two turn rates over
    ``frames`` frames on which the picture read a turn."""

    offset: float
    corr: float
    frames: int

    def describe(self) -> str:
        return (f"aligned with the video at --imu-offset {self.offset:+.2f} s (correlation {self.corr:.2f} with the "
                f"picture's turn over {self.frames} frames)")


def picture_turns(frames: Iterable[tuple[float, np.ndarray]], fov_of: Callable[[np.ndarray], float | None],
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The turn read from each pair of consecutive frames (:class:`VisualYaw`): the earlier
    frame's time, the later one's and the rate (deg/s; 0 where it cannot tell)."""
    vy, t_prev, rows = VisualYaw(), None, []
    for t, frame in frames:
        rate = vy.update(frame, t, fov_of(frame))
        if t_prev is not None:
            rows.append((t_prev, t, rate))
        t_prev = t
    a = np.asarray(rows, dtype=float).reshape(-1, 3)
    return a[:, 0], a[:, 1], a[:, 2]


def align(log: ImuLog, t0: np.ndarray, t1: np.ndarray, picture_dps: np.ndarray, *,
          search_s: float = ALIGN_SEARCH_S, step_s: float = ALIGN_STEP_S) -> Alignment:
    """The offset (within ``search_s`` either way) at which the log's turn rate over each frame
    pair [t0, t1] (the video's time) correlates best with the picture's, ``picture_dps``
    (:func:`picture_turns`); only pairs on which the picture read a turn count. Raises
    :class:`ImuError` where the video shows too few turns to tell, or no offset matches."""
    known = picture_dps != 0
    t0, t1, pic = t0[known], t1[known], picture_dps[known]
    if len(pic) < ALIGN_MIN_TURNS or pic.std() < ALIGN_MIN_SD_DPS:
        raise ImuError(f"IMU log {log.path}: the video shows too few turns to align the log with it ({len(pic)} frames "
                       f"read a turn); turn the phone now and then while filming, or give --imu-offset SECONDS")
    best = Alignment(0.0, -math.inf, len(pic))
    worst = math.inf
    for o in np.arange(-search_s, search_s + step_s / 2, step_s):
        g = log.turns(t0 + o, t1 + o) / (t1 - t0)
        c = float(np.corrcoef(g, pic)[0, 1]) if g.std() > 0 else 0.0
        if c > best.corr:
            best = Alignment(round(float(o), 6), c, len(pic))
        worst = min(worst, c)
    if best.corr < ALIGN_MIN_CORR:
        why = (" and run opposite to it: is yaw_dps's sign the other way?" if -worst >= ALIGN_MIN_CORR
               else "")
        raise ImuError(f"IMU log {log.path}: its turns do not match the picture's at any offset within "
                       f"+-{search_s:g} s (best correlation {best.corr:.2f} at {best.offset:+.2f} s){why}; "
                       "give --imu-offset SECONDS")
    return best


def line_up(log: ImuLog, offset: float | None, video: str | Path,
            fov_of: Callable[[np.ndarray], float | None]) -> tuple[ImuLog, Alignment | None]:
    """``log`` (loaded at ``offset``) as it is; or with ``offset`` None, shifted to the offset
    :func:`align` finds against the turns read from ``video``'s frames (``fov_of`` giving each
    one's FOV: ``Engine.frame_fov``), and that alignment."""
    from crossing_assist.runtime.sources import VideoSource

    if offset is not None:
        return log, None
    found = align(log, *picture_turns(VideoSource(video, max_width=320), fov_of))
    return log.shifted(found.offset), found
