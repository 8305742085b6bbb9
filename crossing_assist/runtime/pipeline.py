"""One step end to end: frame -> :class:`Prediction` -> :class:`Decision` -> :class:`Cue` -> loop.

Used by the offline demo, the live loop and the benchmark, so they all make the same decisions.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from crossing_assist.runtime.beacon import BeaconConfig, Cue, cue_for, render_cue
from crossing_assist.runtime.decide import Decider, Decision, DecisionConfig
from crossing_assist.runtime.engine import Engine, Prediction


@dataclass(frozen=True)
class Step:
    """Everything one frame produced; ``loop`` is the cue's prepared (n, 2) float32 samples."""

    prediction: Prediction
    decision: Decision
    cue: Cue
    loop: np.ndarray


@lru_cache(maxsize=16)
def cached_loop(cue: Cue, cfg: BeaconConfig) -> np.ndarray:
    """:func:`render_cue` memoised (cues and configs are frozen, hashable values); read-only."""
    loop = render_cue(cue, cfg)
    loop.setflags(write=False)
    return loop


class Pipeline:
    """Engine + decision logic + beacon synthesis for one stream of frames.

    Headings follow the camera: each successful frame's field of view (its orientation's, or
    the user's setting) and its orientation's gate threshold become the decision logic's; when
    either changes (the phone turned between portrait and landscape) the belief starts afresh,
    since old strips no longer mean the same directions. ``decision_cfg``'s other fields
    (watchdog, filter, gate, pulse rates) are kept."""

    def __init__(self, engine: Engine, decision_cfg: DecisionConfig | None = None,
                 beacon_cfg: BeaconConfig | None = None) -> None:
        self.engine = engine
        self.decider = Decider(decision_cfg or engine.decision_config())
        self.beacon_cfg = beacon_cfg or BeaconConfig()

    def step(self, frame_rgb: np.ndarray | None, t: float, yaw_rate_dps: float = 0.0) -> Step:
        """Process a frame taken at ``t`` seconds (None = no new frame, a watchdog tick)."""
        pred = self.engine.predict(frame_rgb) if frame_rgb is not None else Prediction(ok=False, error="no frame")
        obs = pred.observation() if frame_rgb is not None else None
        if pred.ok and pred.fov_deg is not None:
            threshold = self.engine.bundle.calibration.uncertainty.threshold_for(pred.orientation)
            cfg = self.decider.cfg
            if (pred.fov_deg, threshold) != (cfg.fov_deg, cfg.threshold):
                self.decider = Decider(replace(cfg, fov_deg=pred.fov_deg, threshold=threshold))
        decision = self.decider.step(t, obs, yaw_rate_dps)
        cue = cue_for(decision)
        return Step(pred, decision, cue, cached_loop(cue, self.beacon_cfg))
