"""Live loop: frames -> decisions -> the cue the audio stream plays, guarded by the watchdog.

A decision plays from the end of its model run until the next one, while the user may turn. With
a gyroscope (``run_live(gyro=…)``, a board's IMU feeding :class:`~crossing_assist.runtime.gyro.YawIntegrator`)
it is turned with the user until then (:class:`Follower`, decision step 10), as the phone app does.
With none, nothing turns it once its frame is read: a decision the turn read from the frames
makes half a strip stale by the end of its play is played as a stop, checked when it is decided
and again when the next frame is read (:meth:`Pipeline.heard`).

Threads: this loop (capture, inference, decision, cue rendering), the watchdog (swaps in the
stop cue when decisions stop coming), with a gyroscope the follower (re-turns the playing cue
every :data:`FOLLOW_S`), and the audio callback (only copies samples). The cue is handed over by
a reference swap (:meth:`CuePlayer.set_loop`); the loop, the watchdog and the follower queue
theirs under the follower's lock, so a turned cue never replaces a newer one; the audio callback
takes no lock.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace
from typing import Callable, Iterable, Iterator

import numpy as np

from crossing_assist.runtime.beacon import KIND_STOP, Cue
from crossing_assist.runtime.beacon import CuePlayer
from crossing_assist.runtime.gyro import RATE_S, GyroFollow, YawIntegrator
from crossing_assist.runtime.pipeline import Pipeline, Step, cached_loop
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S, Ticker, Watchdog


#: How often the decision playing is turned again with the gyroscope between decisions (s).
FOLLOW_S = 0.05


@dataclass(frozen=True)
class LiveConfig:
    """``watchdog_s``: longest time without a fresh decision; ``pace``: a video plays in real
    time as a camera would give it (its ``t`` are offsets from the start; :func:`paced`);
    ``frozen_check``: a frame identical to the previous one (a frozen camera) does not count as
    fresh; ``max_seconds``: stop after."""

    watchdog_s: float = DEFAULT_WATCHDOG_S
    pace: bool = False
    frozen_check: bool = True
    max_seconds: float | None = None


def same_frame(a: np.ndarray | None, b: np.ndarray) -> bool:
    """The frozen-frame rule (shared with the phone app's ``sameFrame``): a frame is a repeat
    of the previous one when both have the same shape and every byte is equal. A live sensor's
    noise changes some pixel of every real frame, so only a frozen camera repeats exactly."""
    return a is not None and a.shape == b.shape and np.array_equal(a, b)


_same = same_frame


def is_fresh(now: float, captured: float, watchdog_s: float) -> bool:
    """The freshness rule (shared with the phone app's ``isFresh``): a decision made at ``now``
    from a frame captured at ``captured`` (seconds) counts only within ``watchdog_s``."""
    return now - captured <= watchdog_s


def paced(frames: Iterable[tuple[int, tuple[float, np.ndarray]]], start: float, clock: Callable[[], float],
          sleep: Callable[[float], None]) -> Iterator[tuple[int, tuple[float, np.ndarray]]]:
    """A video's numbered frames as a camera would hand them over, ``t`` seconds after ``start``:
    it waits for a frame that is not due yet, and when the loop is behind (a model slower than
    the video's frame period) gives only the newest frame due, dropping those it had no time for,
    as :class:`~crossing_assist.runtime.sources.CameraSource` does. Played one by one instead, a
    slow model fell further behind each frame until every decision came too late to play."""
    it = iter(frames)
    nxt = next(it, None)
    while nxt is not None:
        cur, nxt = nxt, next(it, None)
        while nxt is not None and start + nxt[1][0] <= clock():
            cur, nxt = nxt, next(it, None)
        wait = start + cur[1][0] - clock()
        if wait > 0:
            sleep(wait)
        yield cur


class Follower:
    """Decision step 10 with a gyroscope, between decisions: the decision playing is played turned
    by the gyroscope's turn since its frame's capture (:func:`~crossing_assist.runtime.decide.turned`;
    the gyroscope followed), or, while it reports but is not followed (not yet confirmed by the
    picture), as a stop once that turn, carried on at the gyroscope's present rate to the end of
    its play, passes half a strip (:func:`~crossing_assist.runtime.decide.stale`; as it stood, a
    walker's sway left held-out landscape frames 1.25 % confidently wrong, carried 0.23 %).
    Re-played every ``period_s`` on its own thread (the app: at every gyroscope sample) until the next
    cue. Every cue the live loop and the watchdog queue goes through :meth:`play` or :meth:`stop`,
    under one lock, so a turned cue never replaces a newer one. A gyroscope that stops reporting
    while a decision plays is a fault: the stop cue."""

    def __init__(self, player: CuePlayer, pipeline: Pipeline, gyro: YawIntegrator, stop_loop: np.ndarray,
                 clock: Callable[[], float], period_s: float = FOLLOW_S) -> None:
        self.player, self.pipeline, self.gyro, self.stop_loop = player, pipeline, gyro, stop_loop
        self.clock, self.period_s = clock, period_s
        self._lock = threading.Lock()
        self._playing: tuple[Step, float, float, bool] | None = None   # the step, its capture, its play's end, followed
        self._ticker = Ticker(period_s, self.tick, "crossing-follow")

    def start(self) -> "Follower":
        self._ticker.start()
        return self

    def close(self) -> None:
        self._ticker.stop()

    def play(self, step: Step, captured: float | None = None, followed: bool = False, until: float = 0.0) -> Step:
        """Queue ``step``'s cue; with ``captured`` (a fresh direction, the gyroscope reporting),
        played turned (``followed``) or stopped once stale from now until the next cue, expected
        at ``until``. Returns the step as it plays now."""
        with self._lock:
            fresh = captured is not None and not step.decision.stop
            self._playing = (step, captured, until, followed) if fresh else None
            played = self._turn(*self._playing) if self._playing else step
            self.player.set_loop(played.loop)
            return played

    def stop(self) -> None:
        """The stop cue now (the watchdog's, the end), and nothing turned until the next cue."""
        with self._lock:
            self._playing = None
            self.player.set_loop(self.stop_loop)

    def tick(self) -> None:
        with self._lock:
            if self._playing is None:
                return
            if not self.gyro.reporting(self.clock()):
                self._playing = None
                self.player.set_loop(self.stop_loop)
                return
            self.player.set_loop(self._turn(*self._playing).loop)

    def _turn(self, step: Step, captured: float, until: float, followed: bool) -> Step:
        now = self.clock()
        turn = self.gyro.turn(captured, now)
        if followed:
            return self.pipeline.turned(step, turn)
        carried = turn + self.gyro.between(now - RATE_S, now) * max(0.0, until - now)
        return replace(self.pipeline.heard(step, carried), turn_deg=carried)


def run_live(frames: Iterable[tuple[float, np.ndarray]], pipeline: Pipeline, player: CuePlayer,
             cfg: LiveConfig, *, clock: Callable[[], float] = time.monotonic,
             sleep: Callable[[float], None] = time.sleep,
             on_step: Callable[[int, Step], None] | None = None, video_time: bool = True,
             gyro: YawIntegrator | None = None, follow_gyro: bool | GyroFollow = False,
             roll_at: Callable[[float], float | None] | None = None, start: float | None = None) -> int:
    """Run until ``frames`` ends (or ``max_seconds``); returns the number of frames read from
    ``frames`` up to the last one processed. ``on_step`` gets each frame's index in ``frames``.

    ``video_time=True``: frame times are offsets from the start of a video (mapped onto
    ``clock`` at the first frame); False: they already are ``clock`` times (camera). With
    ``cfg.pace`` a video plays in real time, dropping the frames a slow model has no time for
    (:func:`paced`).

    ``gyro``: a gyroscope's samples on the frames' clock (:class:`YawIntegrator`, fed by the
    caller's IMU thread). While it reports, each decision plays from its model run's end turned
    with the user by the gyroscope's turn since its capture (:class:`Follower`), and the decision
    logic is told the gyroscope's turn between captures, once the picture's turn has confirmed the
    gyroscope's sign (:class:`GyroCheck`; ``follow_gyro=True``: from the start, as the app's
    opt-in; a :class:`GyroFollow`: its rule, which then tells when it was confirmed), never after
    finding it the wrong way. Until then the decision plays as a stop once the
    gyroscope's turn since its capture, carried on to the end of its play, passes half a strip.
    Without a gyroscope reporting, a decision the turn read from the frames makes half a strip
    stale is a stop (checked when it is decided, and when the next frame is read).

    ``roll_at``: the camera's roll (degrees, as :func:`~crossing_assist.geometry.level` takes it)
    at a frame's time ``t``, None where unknown; the frame is levelled by it. ``start``: the
    ``clock`` time of a video's ``t = 0`` (default: now), so that a recorded IMU log replayed
    onto the same clock (:meth:`~crossing_assist.runtime.imu.ImuLog.replay`) lines up with it.
    """
    stop_loop = cached_loop(Cue(KIND_STOP), pipeline.beacon_cfg)
    follower = Follower(player, pipeline, gyro or YawIntegrator(), stop_loop, clock)
    follower.stop()
    if gyro is not None:
        follower.start()
    follow = follow_gyro if isinstance(follow_gyro, GyroFollow) else GyroFollow(follow_gyro)
    dog = Watchdog(cfg.watchdog_s, follower.stop, clock=clock).start()
    start = clock() if start is None else start
    prev: np.ndarray | None = None
    last_captured: float | None = None
    playing: Step | None = None   # no gyroscope: the last frame's decision, while it plays a direction
    model_s = 0.0                 # the last frame's capture to its decision: how long one waits for the next
    n = 0
    numbered: Iterable[tuple[int, tuple[float, np.ndarray]]] = enumerate(frames)
    if cfg.pace and video_time:
        numbered = paced(numbered, start, clock, sleep)
    try:
        for i, (t, frame) in numbered:
            if cfg.max_seconds is not None and clock() - start > cfg.max_seconds:
                break
            captured = start + t if video_time else t
            if cfg.frozen_check and _same(prev, frame):
                continue  # a frozen camera repeats its last frame: not fresh, let the watchdog act
            prev = frame
            interval = 0.0 if last_captured is None else max(0.0, captured - last_captured)
            seen = pipeline.read(frame, captured - start, roll_deg=roll_at(t) if roll_at else None)
            reporting = gyro is not None and gyro.reporting(captured)
            if reporting:   # the gyroscope's turn since the frame before, checked against the picture's
                seen = follow.tell(seen, gyro, captured - interval if interval else None, captured)
            followed = seen.yaw_source == "gyro"
            cut = None      # the turn that stopped the playing decision now, if one did
            if playing is not None and not reporting:
                # no gyroscope: the turn read since the playing decision's frame, carried on through
                # this frame's model run; past half a strip it is stale, a stop from now on
                checked = pipeline.heard(playing, seen.yaw_rate_dps * (interval + model_s))
                if checked is not playing:
                    follower.play(checked)
                    cut = checked.stale_turn_deg
            last_captured = captured
            step = pipeline.decide(seen)
            decided = clock()
            model_s = max(0.0, decided - captured)
            fresh = is_fresh(decided, captured, cfg.watchdog_s)
            if not fresh:   # decided too late to play: the stop cue, and the trace says so
                step = replace(step, cue=Cue(KIND_STOP), loop=stop_loop, late=True)
            elif not reporting:   # no gyroscope: a stop if the turn goes on past half a strip before the next one
                step = pipeline.heard(step, step.yaw_rate_dps * (model_s + interval))
            if cut is not None:
                step = replace(step, cut_turn_deg=cut)
            playing = step if fresh and not reporting and not step.decision.stop else None
            step = follower.play(step, captured if fresh and reporting else None, followed, until=decided + interval)
            if fresh:
                dog.beat(captured)
            if on_step is not None:
                on_step(i, step)
            n = i + 1
    finally:
        dog.stop()
        follower.close()
        follower.stop()
    return n
