"""One step end to end: frame -> :class:`Prediction` -> :class:`Decision` -> :class:`Cue` -> loop.

Used by the offline demo, the live loop and the benchmark, so they all make the same decisions.
:func:`open_pipeline` is the one wiring of a bundle into engine + decision logic (filter, gate,
watchdog period) + beacon that ``crossing-demo`` uses live and offline; :func:`trace_record`
is the one trace.jsonl line of a step, written by both.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from crossing_assist.geometry import level, rolled_too_far
from crossing_assist.runtime.beacon import BeaconConfig, Cue, cue_for, render_cue
from crossing_assist.runtime.decide import Decider, Decision, DecisionConfig, stale, turned
from crossing_assist.runtime.engine import Engine, Prediction
from crossing_assist.runtime.visual_yaw import VisualYaw
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S


@dataclass(frozen=True)
class Step:
    """Everything one frame produced; ``loop`` is the cue's prepared (n, 2) float32 samples.
    ``late``: live, the decision came after the watchdog period from its frame's capture (a
    board too slow for the bundle), so ``cue`` and ``loop`` are the stop cue that played instead.
    ``yaw_rate_dps``: the turn rate the decision logic was told with this frame. ``stale_turn_deg``:
    live, with no gyroscope, the turn read from the frames by the end of its play that made it a
    stop when decided (:meth:`Pipeline.heard`; ``decision``, ``cue`` and ``loop`` are then the
    stop's); ``cut_turn_deg``: the one that stopped the decision before it, still playing, when
    this frame was read. ``yaw_source``: where that rate came from, ``"gyro"``, ``"camera"`` (the
    frames) or ``"off"``; ``turn_deg``: live, with a gyroscope reporting, its turn from the capture
    to the decision, by which the decision played was turned (or stopped once stale)."""

    prediction: Prediction
    decision: Decision
    cue: Cue
    loop: np.ndarray
    late: bool = False
    yaw_rate_dps: float = 0.0
    stale_turn_deg: float | None = None
    cut_turn_deg: float | None = None
    yaw_source: str = "camera"
    turn_deg: float | None = None


@dataclass(frozen=True)
class Seen:
    """A frame read, before the model (:meth:`Pipeline.read`): the frame (levelled when its roll
    was given and a turn is read from it), its capture time, the roll still to level (None when
    none), and the turn rate the decision logic will be told with it, and where it came from
    (``"gyro"``, ``"camera"``: read from the frames, ``"off"``)."""

    frame: np.ndarray | None
    t: float
    roll_deg: float | None
    yaw_rate_dps: float
    yaw_source: str = "camera"


@lru_cache(maxsize=16)
def cached_loop(cue: Cue, cfg: BeaconConfig) -> np.ndarray:
    """:func:`render_cue` memoised (cues and configs are frozen, hashable values); read-only."""
    loop = render_cue(cue, cfg)
    loop.setflags(write=False)
    return loop


class Pipeline:
    """Engine + decision logic + beacon synthesis for one stream of frames.

    Headings follow the camera: each frame's field of view (its orientation's, or the user's
    setting; known from its size, so also for a frame the model then fails on, as the app does)
    and the gate threshold of its orientation and FOV become the decision logic's; when either
    changes (the phone turned between portrait and landscape) the belief starts afresh, since old
    strips no longer mean the same directions. A frame whose FOV cannot be known (a refused
    size) makes the next one with a FOV start afresh too. ``decision_cfg``'s other fields
    (watchdog, filter, gate, pulse rates) are kept.

    Turns: a yaw rate given with a frame (a gyroscope) is the decision logic's; without one the
    turn since the last frame is read from the frames themselves (:class:`VisualYaw`), unless
    ``visual_yaw`` is False (then none: the belief and the hold stay put while the view moves); a
    frame given with its roll is read levelled, as the model sees it."""

    def __init__(self, engine: Engine, decision_cfg: DecisionConfig | None = None,
                 beacon_cfg: BeaconConfig | None = None, *, visual_yaw: bool = True) -> None:
        self.engine = engine
        self.decider = Decider(decision_cfg or engine.decision_config())
        self.beacon_cfg = beacon_cfg or BeaconConfig()
        self.visual_yaw = VisualYaw() if visual_yaw else None
        self._fov_lost = False   # a frame's FOV could not be known: the next known one starts afresh

    def step(self, frame_rgb: np.ndarray | None, t: float, yaw_rate_dps: float | None = None,
             roll_deg: float | None = None) -> Step:
        """Process a frame taken at ``t`` seconds (None = no new frame, a watchdog tick); ``yaw_rate_dps``:
        the turn rate from a gyroscope (None: read from the frames, or none, see the class);
        ``roll_deg``: the camera's roll when it was taken, from an orientation sensor (None: none;
        the frame is used as it is, :meth:`Engine.predict`). :meth:`read`, then :meth:`decide`."""
        return self.decide(self.read(frame_rgb, t, yaw_rate_dps, roll_deg))

    def read(self, frame_rgb: np.ndarray | None, t: float, yaw_rate_dps: float | None = None,
             roll_deg: float | None = None) -> Seen:
        """The first half of :meth:`step`, before the model: the frame levelled and its turn since
        the last one (cheap; the live loop checks the decision still playing with it)."""
        if roll_deg is not None and frame_rgb is not None and self.visual_yaw and not rolled_too_far(roll_deg):
            # levelled here, once: the turn is read from the frame the model sees, as the app reads it
            # (unlevelled, a turn moves the picture along the rolled axis: 0.3-0.7 deg mean error a
            # frame at 10-30 deg of roll against 0.1, docs/runtime.md)
            try:
                frame_rgb, roll_deg = level(frame_rgb, roll_deg, self.engine.bundle.geometry.pad_rgb), None
            except Exception:  # noqa: BLE001  an unreadable frame: the engine says why
                pass
        source = "gyro" if yaw_rate_dps is not None else "camera" if self.visual_yaw else "off"
        if yaw_rate_dps is None:
            yaw_rate_dps = 0.0
            if self.visual_yaw:
                fov = self.engine.frame_fov(frame_rgb) if frame_rgb is not None else None
                seen = self.visual_yaw.update(frame_rgb, t, fov)
                yaw_rate_dps = seen if frame_rgb is not None else 0.0
        elif self.visual_yaw:
            self.visual_yaw.reset()     # the gyroscope's turn; a later frame without one starts afresh
        return Seen(frame_rgb, t, roll_deg, float(yaw_rate_dps), source)

    def decide(self, seen: Seen) -> Step:
        """The second half of :meth:`step`: the model, the decision logic and the cue."""
        frame_rgb = seen.frame
        pred = (self.engine.predict(frame_rgb, roll_deg=seen.roll_deg) if frame_rgb is not None
                else Prediction(ok=False, error="no frame"))
        obs = pred.observation() if frame_rgb is not None else None
        if pred.fov_deg is not None:
            threshold = self.engine.bundle.calibration.uncertainty.threshold_for(pred.orientation, pred.fov_deg)
            cfg = self.decider.cfg
            if self._fov_lost or (pred.fov_deg, threshold) != (cfg.fov_deg, cfg.threshold):
                self.decider = Decider(replace(cfg, fov_deg=pred.fov_deg, threshold=threshold))
                self._fov_lost = False
        elif frame_rgb is not None:
            self._fov_lost = True
        decision = self.decider.step(seen.t, obs, seen.yaw_rate_dps)
        cue = cue_for(decision)
        return Step(pred, decision, cue, cached_loop(cue, self.beacon_cfg), yaw_rate_dps=seen.yaw_rate_dps,
                    yaw_source=seen.yaw_source)

    def heard(self, step: Step, turn_deg: float) -> Step:
        """``step`` as a player with no gyroscope plays it once the camera has turned ``turn_deg``
        since its frame's capture (the turn read from the frames, carried on at their rate to the
        end of its play). Nothing measures the turn once the frame is read, so the decision cannot
        be turned with the user (step 10 with a gyroscope); past half a strip it plays as a stop
        (:func:`~crossing_assist.runtime.decide.stale`; the live loop checks it when decided and
        again when the next frame is read). Decided as it is, a 30 deg/s scan heard 0.2 s late was
        10.5 % confidently wrong (docs/runtime.md, step 10)."""
        played = stale(step.decision, turn_deg, self.decider.cfg.fov_deg)
        if played is step.decision:
            return step
        cue = cue_for(played)
        return replace(step, decision=played, cue=cue, loop=cached_loop(cue, self.beacon_cfg), stale_turn_deg=turn_deg)

    def turned(self, step: Step, turn_deg: float) -> Step:
        """``step`` as played once the camera has turned ``turn_deg`` since its frame's capture, by
        a gyroscope followed (decision step 10, :func:`~crossing_assist.runtime.decide.turned`)."""
        played = turned(step.decision, turn_deg, self.decider.cfg.fov_deg)
        if played is step.decision:
            return replace(step, turn_deg=turn_deg)
        cue = cue_for(played)   # rendered, not cached: a turned cue's pan takes any value
        return replace(step, decision=played, cue=cue, loop=render_cue(cue, self.beacon_cfg), turn_deg=turn_deg)


def open_pipeline(bundle: str | os.PathLike, *, fov_deg: float | None = None, watchdog_s: float = DEFAULT_WATCHDOG_S,
                  beacon: BeaconConfig | None = None, engine: Engine | None = None,
                  visual_yaw: bool = True, threads: int = 1) -> Pipeline:
    """The demo's pipeline for ``bundle``: its :class:`Engine` (``fov_deg``: the camera's
    horizontal FOV, None = the bundle's per orientation; or the given ``engine``), the bundle's
    decision config with ``watchdog_s`` as the stale-frame period, ``beacon`` (default
    :class:`BeaconConfig`) and turns read from the frames unless ``visual_yaw`` is False;
    ``threads``: onnxruntime's for a new engine (0: its default). The live and the offline demo
    both build theirs here."""
    engine = engine or Engine(bundle, fov_deg=fov_deg, threads=threads)
    return Pipeline(engine, engine.decision_config(watchdog_s=watchdog_s), beacon or BeaconConfig(),
                    visual_yaw=visual_yaw)


def trace_record(i: int, step: Step) -> dict:
    """One trace.jsonl line: frame index, model outputs, the cue played (``late``: the stop cue
    played because the decision came too late, live only), the turn rate the decision logic was
    told and where it came from (``yaw_source``), the turns that made the decision, or the one
    before it, a stop as played (``stale_turn_deg``, ``cut_turn_deg``; live only), the gyroscope's
    turn it was played turned by (``turn_deg``; live only) and the decision (as played)."""
    p, d = step.prediction, step.decision
    rec = {"frame": i, "ok": p.ok, "error": p.error or None, "action": p.action if p.ok else None,
           "probs": None if p.probs is None else [round(float(v), 5) for v in p.probs],
           "entropy": p.entropy if p.ok else None, "mutual_info": p.mutual_info if p.ok else None,
           "uncertainty": p.uncertainty if p.ok else None, "conformal_set": list(p.conformal_set),
           "cue": step.cue.kind, "late": step.late, "yaw_rate_dps": step.yaw_rate_dps,
           "stale_turn_deg": step.stale_turn_deg, "cut_turn_deg": step.cut_turn_deg,
           "yaw_source": step.yaw_source, "turn_deg": step.turn_deg}
    rec.update(d.to_json())
    rec["belief"] = [round(v, 5) for v in rec["belief"]]
    return rec
