"""Live loop: frames -> decisions -> the cue the audio stream plays, guarded by the watchdog.

With no gyroscope, nothing turns a decision with the user once its frame is read: a decision the
turn read from the frames makes half a strip stale by the end of its play is played as a stop,
checked when it is decided and again when the next frame is read (:meth:`Pipeline.heard`).

Threads: this loop (capture, inference, decision, cue rendering), the watchdog (swaps in the
stop cue when decisions stop coming), and the audio callback (only copies samples). The cue is
handed over by a reference swap (:meth:`CuePlayer.set_loop`), never under a lock.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Callable, Iterable, Iterator

import numpy as np

from crossing_assist.runtime.beacon import KIND_STOP, Cue
from crossing_assist.runtime.beacon import CuePlayer
from crossing_assist.runtime.pipeline import Pipeline, Step, cached_loop
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S, Watchdog


@dataclass(frozen=True)
class LiveConfig:
    """``watchdog_s``: longest time without a fresh decision; ``pace``: a video plays in real
    time as a camera would give it (its ``t`` are offsets from the start; :func:`paced`); ``frozen_check``: a frame identical to
    the previous one (a frozen camera) does not count as fresh; ``max_seconds``: stop after."""

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


def run_live(frames: Iterable[tuple[float, np.ndarray]], pipeline: Pipeline, player: CuePlayer,
             cfg: LiveConfig, *, clock: Callable[[], float] = time.monotonic,
             sleep: Callable[[float], None] = time.sleep,
             on_step: Callable[[int, Step], None] | None = None, video_time: bool = True) -> int:
    """Run until ``frames`` ends (or ``max_seconds``); returns the number of frames read from
    ``frames`` up to the last one processed. ``on_step`` gets each frame's index in ``frames``.

    ``video_time=True``: frame times are offsets from the start of a video (mapped onto
    ``clock`` at the first frame); False: they already are ``clock`` times (camera). With
    ``cfg.pace`` a video plays in real time, dropping the frames a slow model has no time for
    (:func:`paced`).
    """
    stop_loop = cached_loop(Cue(KIND_STOP), pipeline.beacon_cfg)
    player.set_loop(stop_loop)
    dog = Watchdog(cfg.watchdog_s, lambda: player.set_loop(stop_loop), clock=clock).start()
    start = clock()
    prev: np.ndarray | None = None
    last_captured: float | None = None
    playing: Step | None = None   # the last frame's decision, while it plays a direction
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
            seen = pipeline.read(frame, captured - start)
            cut = None      # the turn that stopped the playing decision now, if one did
            if playing is not None:
                # no gyroscope: the turn read since the playing decision's frame, carried on through
                # this frame's model run; past half a strip it is stale, a stop from now on
                checked = pipeline.heard(playing, seen.yaw_rate_dps * (interval + model_s))
                if checked is not playing:
                    player.set_loop(checked.loop)
                    cut = checked.stale_turn_deg
            last_captured = captured
            step = pipeline.decide(seen)
            decided = clock()
            model_s = max(0.0, decided - captured)
            fresh = is_fresh(decided, captured, cfg.watchdog_s)
            if not fresh:   # decided too late to play: the stop cue, and the trace says so
                step = replace(step, cue=Cue(KIND_STOP), loop=stop_loop, late=True)
            else:           # no gyroscope: a stop if the turn goes on past half a strip before the next one
                step = pipeline.heard(step, step.yaw_rate_dps * (model_s + interval))
            if cut is not None:
                step = replace(step, cut_turn_deg=cut)
            playing = step if fresh and not step.decision.stop else None
            player.set_loop(step.loop)
            if fresh:
                dog.beat(captured)
            if on_step is not None:
                on_step(i, step)
            n = i + 1
    finally:
        dog.stop()
        player.set_loop(stop_loop)
    return n
