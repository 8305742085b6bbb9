"""The gate: UPMS (uncertainty-aware policy mixing) at run time (pure, numpy-free arithmetic).

Two policies propose a heading: the *learner* (the filtered vision policy) and the *fallback*
(heading hold: the last confident learner heading, carried by the yaw input). Each gets a
coefficient ``alpha(U) = 1 - tanh(c U)`` from its uncertainty ``U``
(:func:`crossing_assist.upms.coefficient`, shared with the IIL: ``U = inf`` or NaN gives 0); ``c = saturation /
threshold`` with ``saturation = atanh(1/2)`` so that ``alpha(threshold) = 1/2`` (the bundle's
calibrated threshold is where trust is one half). Rational mixing normalises the coefficients
into weights ``w_L = alpha_L / (alpha_L + alpha_F)``, ``w_F = 1 - w_L`` (consistency: a policy
with ``alpha = 0`` never acts; rationality: the surer policy weighs more; neutrality: equal
uncertainties give equal weights). When ``max(alpha_L, alpha_F) < alpha_min`` the decision is
*impossible*: the beacon stops and the stop/scan cue plays.

How the weights become one heading: if both headings exist and differ by at most
``agree_deg`` the heading is the weighted mean ``w_L h_L + w_F h_F``; otherwise the policy
with the larger coefficient acts alone (learner on ties): averaging two different directions
could point between them, into traffic.
"""

from __future__ import annotations

from dataclasses import dataclass

from crossing_assist.upms import SATURATION_HALF, coefficient

GATE_LEARNER = "learner"
GATE_HOLD = "hold"
GATE_STOP = "stop"


@dataclass(frozen=True)
class GateConfig:
    """Gate parameters (see module docstring and docs/runtime.md).

    ``alpha_min``: below it for both policies the decision is impossible (stop); also the
    learner coefficient at which the hold is refreshed. ``hold_time_s`` / ``hold_turn_deg``:
    the hold's uncertainty ``U_F = age / hold_time_s + turned / hold_turn_deg`` (dimensionless,
    threshold 1). ``belief_entropy_threshold``: learner threshold (nats) used when the bundle's
    measure is not ``entropy``. ``agree_deg``: largest heading difference that is averaged.
    ``contradict_strips``: a frame whose most probable strip lies further than this many strip
    widths from the hold drops the hold, however unsure the frame (the camera turned without the
    yaw input saying so, or the hold was wrong).
    """

    saturation: float = SATURATION_HALF
    alpha_min: float = 0.5
    hold_time_s: float = 1.5
    hold_turn_deg: float = 45.0
    agree_deg: float = 15.0
    belief_entropy_threshold: float = 1.2
    contradict_strips: float = 1.5

    def __post_init__(self) -> None:
        for name in ("saturation", "hold_time_s", "hold_turn_deg", "agree_deg", "belief_entropy_threshold",
                     "contradict_strips"):
            if not float(getattr(self, name)) > 0:
                raise ValueError(f"Invalid {name}: {getattr(self, name)}; valid: > 0")
        if not 0.0 < self.alpha_min < 1.0:
            raise ValueError(f"Invalid alpha_min: {self.alpha_min}; valid: 0 < alpha_min < 1")


alpha = coefficient  # the UPMS coefficient, one copy: crossing_assist.upms (NaN and inf give 0)


@dataclass(frozen=True)
class Mix:
    """One gate outcome. ``heading_deg`` is None when ``state == "stop"``."""

    state: str
    heading_deg: float | None
    weight_learner: float
    confidence: float  # max(alpha_L, alpha_F)


def mix(h_learner: float | None, a_learner: float, h_hold: float | None, a_hold: float,
        cfg: GateConfig) -> Mix:
    """Rational mixing of the learner and the hold (headings in degrees, coefficients in [0, 1])."""
    a_l = a_learner if h_learner is not None else 0.0
    a_f = a_hold if h_hold is not None else 0.0
    conf = max(a_l, a_f)
    if conf < cfg.alpha_min:
        return Mix(GATE_STOP, None, 0.0, conf)
    w_l = a_l / (a_l + a_f)
    state = GATE_LEARNER if a_l >= cfg.alpha_min else GATE_HOLD
    if h_learner is not None and h_hold is not None and abs(h_learner - h_hold) <= cfg.agree_deg:
        heading = w_l * h_learner + (1.0 - w_l) * h_hold
    elif a_l >= a_f:
        heading = h_learner
    else:
        heading = h_hold
    return Mix(state, heading, w_l, conf)
