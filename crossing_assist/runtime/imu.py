"""A motion-sensor log recorded with a video, replayed with it: ``crossing-demo VIDEO --imu LOG.csv``.

A phone that films a walk can log its gyroscope and tilt at the same time. Given that log, the
demo hears the video as the phone app would have played it: the decision logic is told the
gyroscope's turn between frames once the picture's turn has confirmed its sign (or from the start
with ``--follow-gyro``), live the beacon is turned with the user between decisions (decision step
10), and each frame is levelled by the camera's roll. Without one, the turn is read from the frames
and a rolled video is used as it is.

The log is a CSV file with a header naming its columns, in any order; others are ignored:

- ``t``: seconds, increasing; the video's first frame is at ``t = offset`` (``--imu-offset``, 0 by
  default);
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
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from crossing_assist.errors import UserError
from crossing_assist.runtime.gyro import MAX_SAMPLE_GAP_S, YawIntegrator, integrate

MAX_RATE_DPS = 2000.0   # a phone gyroscope's full scale: a larger rate is a unit mix-up (rad/s read as deg/s is smaller)
MAX_ROLL_DEG = 180.0
MAX_ROWS = 10_000_000


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

    def _around(self, t0: float, t1: float) -> list[tuple[float, float]]:
        """The samples that can cover [t0, t1]: from the one before the first after ``t0`` to
        the first at or after ``t1``."""
        i0 = max(0, bisect.bisect_right(self.t, t0) - 1)
        i1 = min(len(self.t), bisect.bisect_left(self.t, t1) + 1)
        return list(zip(self.t[i0:i1], self.yaw_dps[i0:i1]))

    def turn(self, t0: float, t1: float) -> float:
        """Degrees turned over [t0, t1], by :class:`~crossing_assist.runtime.gyro.YawIntegrator`'s rule."""
        return integrate(self._around(t0, t1), t0, t1) if t1 > t0 else 0.0

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
