"""A gyroscope's turn for the live loop: samples integrated into turns between two times, and the
picture's check of the gyroscope's sign (the phone app's ``YawIntegrator`` and ``GyroCheck``,
android_demo/www/js/live.js, with the same rules).

A board with an IMU hands its yaw-rate samples to :meth:`YawIntegrator.add` from its own thread;
:func:`~crossing_assist.runtime.live.run_live` then tells the decision logic the gyroscope's turn
between captures and turns the beacon with the user between decisions (decision step 10), as the
app does. Without one, a decision the picture's turn makes stale is a stop, which silences the
beacon while the user turns, and for most of a walk: the step sway alone (2.5 deg at 0.9 Hz)
left it on for 22 % of held-out goal-in-view frames, against 91 % turned by a gyroscope
(docs/results.md, "A walker's sway").
"""

from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass, replace
from typing import Sequence

#: A sample's rate covers the time since the sample before, at most this long: a longer gap is a
#: paused sensor, and a sensor whose last sample is older than this is not reporting.
MAX_SAMPLE_GAP_S = 0.2
KEEP_S = 3.0   # samples kept: longer than any pair of frames the watchdog lets through
#: The gyroscope's present rate is its mean over this long (the app's ``RATE_S``).
RATE_S = 0.1


def integrate(samples: Sequence[tuple[float, float]], t0: float, t1: float) -> float:
    """Degrees turned over [t0, t1] by ``samples`` ((time, rate deg/s) in time order): each
    sample's rate covers the time since the sample before, at most :data:`MAX_SAMPLE_GAP_S`."""
    angle = 0.0
    for (t_before, _), (t, rate) in zip(samples, samples[1:]):
        overlap = min(t, t1) - max(t_before, t - MAX_SAMPLE_GAP_S, t0)
        if overlap > 0:
            angle += rate * overlap
    return angle


class YawIntegrator:
    """Gyroscope samples (turn rate, deg/s, + right; at times on the frames' clock) integrated into
    the turn between two times, however the sensor's rate and the frame rate compare. Thread-safe:
    an IMU thread adds, the live loop and its audio follower read."""

    def __init__(self) -> None:
        self._samples: deque[tuple[float, float]] = deque()
        self._lock = threading.Lock()

    def add(self, rate_dps: float, t: float) -> None:
        """A sample: turn rate ``rate_dps`` at time ``t``; a non-finite one, or one not after the
        last, is ignored."""
        if not (math.isfinite(rate_dps) and math.isfinite(t)):
            return
        with self._lock:
            if self._samples and not t > self._samples[-1][0]:
                return
            self._samples.append((float(t), float(rate_dps)))
            while len(self._samples) > 2 and self._samples[1][0] < t - KEEP_S:
                self._samples.popleft()

    def reporting(self, t: float) -> bool:
        """Whether a sample came within :data:`MAX_SAMPLE_GAP_S` before ``t``."""
        with self._lock:
            return bool(self._samples) and t - self._samples[-1][0] <= MAX_SAMPLE_GAP_S

    def turn(self, t0: float, t1: float) -> float:
        """Degrees turned over [t0, t1] (0 when t1 <= t0; a stretch no sample covers adds nothing)."""
        if not t1 > t0:
            return 0.0
        with self._lock:
            samples = list(self._samples)
        return integrate(samples, t0, t1)

    def between(self, t0: float, t1: float) -> float:
        """Mean turn rate (deg/s) over [t0, t1], as the app's ``between`` (0 when t1 <= t0)."""
        return self.turn(t0, t1) / (t1 - t0) if t1 > t0 else 0.0


@dataclass(frozen=True)
class GyroCheckConfig:
    """How the picture checks a gyroscope (:class:`GyroCheck`).

    **Clear turns** (a user scanning for the crossing): frames count when both read a turn of
    ``turn_dps`` or more; of the last ``window`` counted, once ``least`` were seen, a share of
    ``contradicted`` or more the other way is 'wrong' for good, and otherwise 'ok'. They confirm
    the gyroscope when as large a share agrees *and* the two agree in size (below).

    **A walker's sway** (its fastest turn ~14 deg/s) never reads that clear, so a walk begun
    facing the crossing would never confirm a gyroscope. The sway confirms it too (never condemns
    it) once the last ``sway_window`` frames on which either read a turn of ``sway_dps`` or more
    agree in size. A frame where one turns and the other does not counts against it; a frame is
    left out only where the picture read no turn (0: it cannot tell) or either reads
    ``sway_max_dps`` or more: no sway turns that fast, and the picture's rare misreads (a zebra's
    stripes under a walker's feet matched a period off: -200 deg/s for one frame) would swamp it.
    The sway is a 0.9 Hz swing, so a frame stamped 0.1 s late against the gyroscope already turns
    the two series' cosine to 0.84 (a phone's browser without a capture time stamps its frames
    when shown): the sway is compared with the gyroscope's turn over the frame's interval moved
    back by each of ``sway_lags_s`` too (a window each), and one agreeing confirms.

    **Agreeing in size**: the cosine of the two rate series at least ``agree_cos``, and the
    picture's turn ``agree_scale`` times the gyroscope's or less either way (least squares). A
    gyroscope read the wrong way gives a cosine near -1, one reading another axis (a walker's
    bob, twice the sway's frequency) or noise near 0: two independent series of 16 reach 0.85
    about 8 times in a million. Sign votes alone confirmed a gyroscope reading another axis
    whenever its turns and the picture's both passed 15 deg/s often enough.
    scripts/walk_confirm.py measures the rule on synthetic walks."""

    turn_dps: float = 15.0
    window: int = 12
    least: int = 8
    contradicted: float = 0.75
    sway_dps: float = 5.0
    sway_max_dps: float = 30.0
    sway_window: int = 16
    sway_lags_s: tuple[float, ...] = (0.0, 0.1, 0.2)
    agree_cos: float = 0.85
    agree_scale: float = 1.5


GYRO_CHECK = GyroCheckConfig()


class GyroCheck:
    """The gyroscope's sign checked against the picture's turn, frame by frame (the app's
    ``GyroCheck``, :class:`GyroCheckConfig`). A gyroscope mounted or read the wrong way turns the
    beacon away from the crossing as the user turns toward it; once found ``'wrong'`` it is not
    followed again. A turn in the picture alone (a bus crossing a still view) or the gyroscope's
    alone (a blank wall) proves nothing and is not voted on."""

    def __init__(self, cfg: GyroCheckConfig = GYRO_CHECK) -> None:
        self.cfg = cfg
        self.turns: deque[tuple[float, float]] = deque(maxlen=cfg.window)   # clear turns: (gyroscope, picture)
        # a sway's turns, alike: one window for each of sway_lags_s
        self.sway = [deque(maxlen=cfg.sway_window) for _ in cfg.sway_lags_s]
        self.swayed = False   # a window of the sway has agreed: confirmed until found 'wrong'
        self.verdict = "unchecked"                           # 'unchecked' | 'ok' | 'wrong'

    def add(self, gyro_dps: float, camera_dps: float, lagged: Sequence[float] = ()) -> str:
        """One frame's turn rates (deg/s, + right), the gyroscope's and the picture's; the verdict.
        ``lagged``: the gyroscope's mean rate over the frame's interval moved back by each of
        ``sway_lags_s`` after the first (:meth:`YawIntegrator.between`); without it the sway is
        compared at no lag only."""
        c = self.cfg
        if self.verdict == "wrong" or not (math.isfinite(gyro_dps) and math.isfinite(camera_dps)):
            return self.verdict
        for window, g in zip(self.sway if not self.swayed else (), (gyro_dps, *lagged)):   # once swayed, done
            if camera_dps != 0 and max(abs(g), abs(camera_dps)) >= c.sway_dps \
                    and abs(g) < c.sway_max_dps and abs(camera_dps) < c.sway_max_dps:
                window.append((g, camera_dps))   # NaN fails the comparisons
                self.swayed = self.swayed or (len(window) >= c.sway_window and self.agree(window))
        if not (abs(gyro_dps) >= c.turn_dps and abs(camera_dps) >= c.turn_dps):
            return self.verdict
        self.turns.append((gyro_dps, camera_dps))
        if len(self.turns) >= c.least:
            self.verdict = "wrong" if self._against() >= c.contradicted * len(self.turns) else "ok"
        return self.verdict

    def _against(self) -> int:
        return sum(g * p < 0 for g, p in self.turns)

    def confirmed(self) -> bool:
        """The picture vouches for the gyroscope (:meth:`confirmation`)."""
        return self.confirmation() is not None

    def confirmation(self) -> str | None:
        """How the picture vouches for the gyroscope: ``'clear turns'`` ('ok', with as large a
        share of them agreeing as ``contradicted`` is of them contradicting for 'wrong', agreeing in
        size too); else, not found 'wrong', ``'sway'`` once a full window of a sway's turns agreed in
        size at one of the lags (it stays so: the windows slide with every step, and a gyroscope
        followed now and then would switch the beacon's rule back and forth); else None."""
        c = self.cfg
        if self.verdict == "wrong":
            return None
        if (self.verdict == "ok" and len(self.turns) - self._against() >= c.contradicted * len(self.turns)
                and self.agree(self.turns)):
            return "clear turns"
        return "sway" if self.swayed else None

    def agree(self, pairs) -> bool:
        """(gyroscope, picture) turn rates agreeing in size: cosine and least-squares scale."""
        c = self.cfg
        gp = sum(g * p for g, p in pairs)
        gg = sum(g * g for g, _ in pairs)
        pp = sum(p * p for _, p in pairs)
        return gp >= c.agree_cos * math.sqrt(gg * pp) and gg / c.agree_scale <= gp <= gg * c.agree_scale


class GyroFollow:
    """Whether the decision logic is told the gyroscope's turn with a frame (the live loop's and
    the offline demo's rule, as the app's): once the picture's turn has confirmed the gyroscope's
    sign (:class:`GyroCheck`), or from the start with ``follow=True`` (the app's opt-in); never
    after the picture found it the wrong way. ``confirmed_at``: the frame time it was first
    followed (None: not yet). :meth:`scale` compares the two rates' sizes."""

    def __init__(self, follow: bool = False, cfg: GyroCheckConfig = GYRO_CHECK) -> None:
        self.check = GyroCheck(cfg)
        self.follow = follow
        self.confirmed_at: float | None = None
        self.confirmed_by: str | None = None   # GyroCheck.confirmation() when first followed
        self._sums = [0.0, 0.0, 0]   # sum gyro * picture, sum gyro^2, frames: where the picture read a turn

    def tell(self, seen, gyro, since: float | None, at: float):
        """``seen`` (:class:`~crossing_assist.runtime.pipeline.Seen`, its turn read from the frames
        or not) as the decision logic is told it while ``gyro`` (a :class:`YawIntegrator`, or a
        recorded :class:`~crossing_assist.runtime.imu.ImuLog`) reports at ``at``, its frame's
        capture on the gyroscope's clock: the gyroscope's turn rate since ``since`` (None: the first
        frame, no turn) is checked against the picture's and, where followed, told instead
        (``yaw_source`` ``"gyro"``). The caller checks that it reports."""
        gyro_dps = gyro.between(since, at) if since is not None else 0.0
        picture_dps = seen.yaw_rate_dps if seen.yaw_source == "camera" else None
        lagged = [gyro.between(since - lag, at - lag) for lag in self.check.cfg.sway_lags_s[1:]] \
            if since is not None and picture_dps is not None and not self.check.swayed else []
        if self.followed(seen.t, gyro_dps, picture_dps, lagged):
            return replace(seen, yaw_rate_dps=gyro_dps, yaw_source="gyro")
        return seen

    def followed(self, t: float, gyro_dps: float, picture_dps: float | None, lagged: Sequence[float] = ()) -> bool:
        """A frame at ``t``: the gyroscope's turn rate since the frame before and the picture's
        (None: no turn is read from the frames, so nothing is checked), ``lagged`` as
        :meth:`GyroCheck.add` takes it; whether to follow it."""
        if picture_dps is not None:
            self.check.add(gyro_dps, picture_dps, lagged)
            if picture_dps != 0 and math.isfinite(gyro_dps) and math.isfinite(picture_dps):
                self._sums[0] += gyro_dps * picture_dps
                self._sums[1] += gyro_dps * gyro_dps
                self._sums[2] += 1
        by = self.check.confirmation()
        ok = self.check.verdict != "wrong" and (self.follow or by is not None)
        if ok and self.confirmed_at is None:
            self.confirmed_at, self.confirmed_by = t, by
        return ok

    def scale(self, least: int = 10) -> float | None:
        """How many times the gyroscope's rate the picture's turn is, by least squares over the
        frames on which the picture read a turn (None: fewer than ``least`` such frames, or a
        gyroscope reading no turn). About 1 for a gyroscope in deg/s; 57 for one in rad/s."""
        gp, gg, n = self._sums
        return gp / gg if n >= least and gg > 1e-9 else None
