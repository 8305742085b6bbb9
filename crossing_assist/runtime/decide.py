"""The decision logic: filter + gate + freshness, one deterministic step at a time.

:class:`Decider` is the whole state machine the phone app ports (docs/runtime.md,
"Decision logic"; vectors in android_demo/test_vectors.json). Its inputs are the model outputs
of a frame (an :class:`Observation`), the time ``t`` in seconds and the yaw rate in degrees per
second (positive = the user turns right); its output is a :class:`Decision`. Its only state is
the belief, the hold, and three times; nothing depends on wall clocks or randomness.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from crossing_assist.actions import DEFAULT_FOV_DEG, N_BINS, ActionSpace, get_space, heading_to_pan, heading_to_x
from crossing_assist.bundle import UNCERTAINTY_MEASURES
from crossing_assist.runtime import belief as bf
from crossing_assist.runtime.gate import GATE_STOP, GateConfig, alpha, mix
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S

REASON_OK = "ok"
REASON_UNCERTAIN = "uncertain"
REASON_STALE = "stale"
REASON_FAILED = "failed"


@dataclass(frozen=True)
class Observation:
    """A frame's model outputs: ``probs`` (A,) over the bundle's actions, ``uncertainty`` = the
    bundle's measure (``calibration.uncertainty.measure``); ``ok=False`` = inference failed."""

    probs: np.ndarray | None
    uncertainty: float
    ok: bool = True


@dataclass(frozen=True)
class DecisionConfig:
    """Everything the decision logic depends on. ``threshold`` is the bundle's
    ``calibration.uncertainty.threshold`` for ``measure``; ``watchdog_s``: longest time without
    a successful frame before the beacon stops; pulse rates in Hz."""

    n_actions: int = 13
    fov_deg: float = DEFAULT_FOV_DEG
    measure: str = "entropy"
    threshold: float = 1.2
    watchdog_s: float = DEFAULT_WATCHDOG_S
    rate_min_hz: float = 2.0
    rate_max_hz: float = 6.0
    filter: bf.FilterConfig = field(default_factory=bf.FilterConfig)
    gate: GateConfig = field(default_factory=GateConfig)

    def __post_init__(self) -> None:
        get_space(self.n_actions)
        if self.measure not in UNCERTAINTY_MEASURES:
            raise ValueError(f"Unknown uncertainty measure: {self.measure!r}; valid: {', '.join(UNCERTAINTY_MEASURES)}")
        if not float(self.threshold) > 0:
            raise ValueError(f"Invalid threshold: {self.threshold}; valid: > 0")
        if not float(self.watchdog_s) > 0:
            raise ValueError(f"Invalid watchdog_s: {self.watchdog_s}; valid: > 0")
        if not 0 < self.rate_min_hz <= self.rate_max_hz:
            raise ValueError(f"Invalid pulse rates: {self.rate_min_hz}..{self.rate_max_hz} Hz; valid: 0 < min <= max")

    @property
    def learner_threshold(self) -> float:
        """Threshold for the belief's uncertainty (:meth:`learner_uncertainty`): the bundle's, when
        its measure reads a probability vector (entropy, far_mass), else the gate's
        ``belief_entropy_threshold`` (nats)."""
        return self.threshold if self.measure in bf.PROBS_MEASURES else self.gate.belief_entropy_threshold

    def learner_uncertainty(self, belief: np.ndarray, space: ActionSpace) -> float:
        """The belief's uncertainty, summed into the action space: the bundle's measure when a
        probability vector gives it (entropy, far_mass), else its entropy (nats)."""
        return bf.PROBS_MEASURES.get(self.measure, bf.entropy)(space.bin_probs_to_action_probs(belief))


@dataclass(frozen=True)
class Decision:
    """One decision. ``heading_deg``/``pan`` are None and ``stop`` is True when the beacon is
    off (the stop/scan cue plays); ``pan`` in [-1, 1] (-1 = left); ``rate_hz`` = pulse rate."""

    t: float
    gate: str
    reason: str
    stop: bool
    heading_deg: float | None
    pan: float | None
    rate_hz: float
    frame_weight: float
    learner_action: int
    learner_heading: float | None
    learner_u: float
    alpha_learner: float
    hold_heading: float | None
    hold_u: float
    alpha_hold: float
    weight_learner: float
    belief: np.ndarray = field(repr=False)

    def to_json(self) -> dict:
        """Plain-JSON dict (floats kept at full precision; belief as a list)."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "belief"}
        out["belief"] = [float(v) for v in self.belief]
        for k, v in out.items():
            if isinstance(v, float) and not math.isfinite(v):
                out[k] = None
        return out


def frame_weight(obs: Observation, c_frame: float, threshold: float) -> float:
    """Evidence weight of a frame before time scaling: ``alpha(U) = 1 - tanh(c U)`` when
    ``U < threshold`` (so in (1/2, 1]), else 0: frames at or beyond the calibrated threshold,
    failed frames and frames whose ``argmax probs`` is unknown carry no evidence."""
    if not obs.ok or obs.probs is None or not math.isfinite(obs.uncertainty):
        return 0.0
    if int(np.argmax(obs.probs)) == 0 or not obs.uncertainty < threshold:
        return 0.0
    return alpha(obs.uncertainty, c_frame)


def edge_side(heading_deg: float, fov_deg: float) -> int:
    """+1 / -1 when ``heading_deg`` lies in the right / left edge strip of a camera ``fov_deg``
    across (or beyond it, short of 90 degrees), else 0."""
    if not abs(heading_deg) < 90.0:
        return 0
    x = heading_to_x(heading_deg, fov_deg)
    return 1 if x >= (N_BINS - 1) / N_BINS else -1 if x <= 1.0 / N_BINS else 0


def turned_out_of_edge(side: int, moved_deg: float, turn_deg: float, fov_deg: float) -> bool:
    """A heading taken in edge strip ``side`` (+1 right, -1 left, 0 none), now at ``moved_deg``
    after a turn of ``turn_deg`` towards that edge, that has left the strip: an edge strip means
    "at this edge or beyond", so where the goal is is then unknown (steps 3 and 10)."""
    return side * turn_deg > 0 and edge_side(moved_deg, fov_deg) != side


def turned(decision: Decision, turn_deg: float, fov_deg: float) -> Decision:
    """Step 10 (docs/runtime.md): ``decision`` as it is played once the camera has turned
    ``turn_deg`` (a gyroscope's, + = right) since its frame's capture.

    A decision is made from a frame the model took time to read, and it plays until the next
    one, so while the user turns it lags their facing by the turn since that capture. The
    heading moves by the turn (the goal stays put in the world), except that a heading in an
    edge strip turned towards moves by half of it: an edge strip means "at this edge or beyond",
    so after the turn the goal lies anywhere from the moved heading back out to the edge
    (:func:`~crossing_assist.runtime.belief.spread_edge`), whose middle this is. Once that turn
    has carried the moved heading out of the edge strip, where the goal is is unknown, as for
    step 3's hold: the decision becomes a stop (``uncertain``) until the next one. A stop stays a
    stop; a turn that is not a finite number turns nothing."""
    if decision.heading_deg is None or not math.isfinite(turn_deg) or turn_deg == 0.0:
        return decision
    side = edge_side(decision.heading_deg, fov_deg)
    if turned_out_of_edge(side, decision.heading_deg - turn_deg, turn_deg, fov_deg):
        return replace(decision, gate=GATE_STOP, reason=REASON_UNCERTAIN, stop=True, heading_deg=None, pan=None)
    h = decision.heading_deg - (turn_deg / 2.0 if side * turn_deg > 0 else turn_deg)
    return replace(decision, heading_deg=h, pan=heading_to_pan(h, fov_deg / 2.0))


def stale(decision: Decision, turn_deg: float, fov_deg: float) -> Decision:
    """Step 10 without the turn's sign: ``decision`` as it is played once the camera has turned
    ``turn_deg`` since its frame's capture, where only the size of that turn is known (the app's
    gyroscope reporting but not followed: not yet confirmed by the picture, or found turning the
    wrong way). It cannot be turned back, so it plays as decided while the turn stays within half
    a strip (a twelfth of ``fov_deg``) and as a stop (``uncertain``) beyond, until the next
    decision. A stop stays a stop; a turn that is not a finite number changes nothing."""
    if decision.heading_deg is None or not math.isfinite(turn_deg) or abs(turn_deg) <= fov_deg / N_BINS / 2.0:
        return decision
    return replace(decision, gate=GATE_STOP, reason=REASON_UNCERTAIN, stop=True, heading_deg=None, pan=None)


class Decider:
    """The stateful decision step. Call :meth:`step` with non-decreasing ``t``."""

    def __init__(self, cfg: DecisionConfig) -> None:
        self.cfg = cfg
        self.space: ActionSpace = get_space(cfg.n_actions)
        self.c_frame = cfg.gate.saturation / cfg.threshold
        self.c_learner = cfg.gate.saturation / cfg.learner_threshold
        self.reset()

    def reset(self) -> None:
        """Back to the start: uniform belief, no hold, no frame seen."""
        self.belief = bf.uniform_belief()
        self.t_prev: float | None = None
        self.t_last_ok: float | None = None
        self.hold_heading: float | None = None
        self.hold_t = 0.0
        self.hold_turned = 0.0
        self.hold_edge = 0

    def _evidence(self, t: float, obs: Observation | None) -> float:
        """Step 4: tempered Bayes update with this frame; returns the weight used."""
        if obs is None or not obs.ok:
            return 0.0
        cfg = self.cfg
        w = frame_weight(obs, self.c_frame, cfg.threshold)
        since = cfg.filter.tau_evidence_s if self.t_last_ok is None else t - self.t_last_ok
        w *= min(1.0, max(0.0, since) / cfg.filter.tau_evidence_s)
        if w > 0.0:
            q = bf.bin_likelihood(obs.probs, self.space)
            self.belief = bf.update(self.belief, q, w, cfg.filter.eps)
        self.t_last_ok = t
        return w

    def _contradict(self, obs: Observation | None) -> None:
        """Step 4b: a frame whose most probable strip lies more than ``contradict_strips`` strip
        widths from the hold drops it, however unsure the frame: without a yaw input a turned
        camera's hold stays where the goal was (a 30 deg/s scan played it 2 strips and more off on a
        quarter of its frames), and a frame that sees the goal elsewhere is what says so. A frame
        that sees no goal (argmax unknown) leaves the hold, which bridges such frames."""
        if obs is None or not obs.ok or obs.probs is None or self.hold_heading is None \
                or not abs(self.hold_heading) < 90.0:
            return
        a = int(np.argmax(obs.probs))
        if a == 0:
            return
        seen = self.space.action_center_x(a)
        if abs(heading_to_x(self.hold_heading, self.cfg.fov_deg) - seen) * N_BINS > self.cfg.gate.contradict_strips:
            self.hold_heading = None

    def _hold(self, t: float) -> tuple[float | None, float, float]:
        """Step 6: the hold's heading (None when unusable), uncertainty and coefficient."""
        if self.hold_heading is None or not abs(self.hold_heading) < 90.0:
            return None, math.inf, 0.0
        g = self.cfg.gate
        u_f = (t - self.hold_t) / g.hold_time_s + self.hold_turned / g.hold_turn_deg
        return self.hold_heading, u_f, alpha(u_f, g.saturation)

    def step(self, t: float, obs: Observation | None, yaw_rate_dps: float = 0.0) -> Decision:
        """Advance to time ``t`` (s) with this frame's outputs (``None`` = no new frame: a tick).

        The numbered steps are those of docs/runtime.md ("Decision logic")."""
        cfg = self.cfg
        dt = 0.0 if self.t_prev is None else max(0.0, t - self.t_prev)  # 1
        self.t_prev = t if self.t_prev is None else max(t, self.t_prev)
        psi = yaw_rate_dps * dt
        self.belief = bf.predict(self.belief, dt, yaw_rate_dps, cfg.fov_deg, cfg.filter)  # 2
        if self.hold_heading is not None:  # 3
            self.hold_heading -= psi
            self.hold_turned += abs(psi)
            # a hold taken in an edge strip means "at this edge or beyond" (as the belief's edge
            # strips, bf.spread_edge): turned towards that edge out of the strip, where the goal is
            # now is unknown; turning away keeps it
            if turned_out_of_edge(self.hold_edge, self.hold_heading, psi, cfg.fov_deg):
                self.hold_heading = None
        if obs is not None and self.t_last_ok is not None and t - self.t_last_ok > cfg.watchdog_s:
            # 4a: the first frame after a stall: what was believed before it is stale (the user
            # may have turned or walked on), so the frame meets a fresh belief and no hold
            self.belief, self.hold_heading = bf.uniform_belief(), None
        w = self._evidence(t, obs)  # 4
        self._contradict(obs)  # 4b
        a_l, h_l = bf.belief_heading(self.belief, self.space, cfg.fov_deg)  # 5
        u_l = cfg.learner_uncertainty(self.belief, self.space) if h_l is not None else math.inf
        al_l = alpha(u_l, self.c_learner)
        h_f, u_f, al_f = self._hold(t)  # 6
        m = mix(h_l, al_l, h_f, al_f, cfg.gate)  # 7
        if obs is not None and not obs.ok:  # 8
            reason = REASON_FAILED
        elif self.t_last_ok is None or t - self.t_last_ok > cfg.watchdog_s:
            reason = REASON_STALE
        else:
            reason = REASON_UNCERTAIN if m.state == GATE_STOP else REASON_OK
            if h_l is not None and al_l >= cfg.gate.alpha_min:  # refresh the hold from fresh evidence
                self.hold_heading, self.hold_t, self.hold_turned = h_l, t, 0.0
                self.hold_edge = edge_side(h_l, cfg.fov_deg)
        stop = reason != REASON_OK  # 9
        heading = None if stop else m.heading_deg
        q = (m.confidence - cfg.gate.alpha_min) / (1.0 - cfg.gate.alpha_min)
        rate = cfg.rate_min_hz + min(1.0, max(0.0, q)) * (cfg.rate_max_hz - cfg.rate_min_hz)
        return Decision(
            t=float(t), gate=GATE_STOP if stop else m.state, reason=reason, stop=stop,
            heading_deg=heading, pan=None if heading is None else heading_to_pan(heading, cfg.fov_deg / 2),
            rate_hz=rate, frame_weight=w, learner_action=a_l, learner_heading=h_l, learner_u=u_l,
            alpha_learner=al_l, hold_heading=h_f, hold_u=u_f, alpha_hold=al_f,
            weight_learner=m.weight_learner, belief=self.belief.copy(),
        )
