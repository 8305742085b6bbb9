"""Who acts: the mixing laws of the thesis and its baselines (numpy only, pure functions).

Agents are named by the constants :data:`EXPERT`, :data:`LEARNER` and :data:`EXPLORER`.
Each mixing strategy answers one question per step: *who should act now*, given the episode
index ``i`` (1-based), the two uncertainties and an explicit ``rng``. It returns the chosen
agent and the probability with which it was chosen (UPMS's sampling step needs it).

UPMS (uncertainty-aware policy mixing) uses the preferential coefficient
``alpha(U) = 1 - tanh(c U)`` (:func:`crossing_assist.upms.coefficient`, shared with the runtime's
gate: ``U = inf`` or NaN gives 0) and the rational law
``p_expert = alpha_T / (alpha_T + alpha_L)``. Two ways to set ``c`` (the two configurations):

* ``thesis``: ``c = 30`` for every agent (the thesis multiplies the uncertainty by 30, so that
  ``1 - tanh(30 sigma^2)`` saturates near DropoutDAgger's threshold sigma^2 = 0.1);
* ``code`` (this project's earlier variant): ``c = atanh(1/2) / threshold`` per agent, so
  ``alpha(threshold) = 1/2``.

Its four laws, tested exactly:

* consistency: the two probabilities are in [0, 1] and sum to 1;
* rationality: the less uncertain agent is never less likely to act;
* neutrality: equal uncertainties (and equal ``c``) give 1/2 each;
* impossibility: both coefficients 0 -> the always-attentive expert acts (probability 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..upms import SATURATION_HALF, coefficient, saturation  # noqa: F401 (re-exported: the one copy)
from .data import EpisodeContext
from .protocols import RiskCritic

EXPERT, LEARNER, EXPLORER = "expert", "learner", "explorer"
AGENTS = (EXPERT, LEARNER, EXPLORER)


def non_preferential(uncertainty: float, c: float) -> float:
    """``tanh(c U)`` in [0, 1] (= 1 - alpha): the thesis's weight on the mixture in rational
    sampling, which grows with the learner's uncertainty; ``U = inf`` gives 1."""
    return 1.0 - coefficient(uncertainty, c)


def rational_mixing(u_expert: float, u_learner: float, c_expert: float, c_learner: float) -> float:
    """Probability that the expert acts under UPMS's rational law; 1.0 when impossible.

    Consistency: the learner's probability is ``1 - result``. Impossibility (both
    coefficients 0, e.g. both uncertainties infinite) hands control to the expert.
    """
    a_t = coefficient(u_expert, c_expert)
    a_l = coefficient(u_learner, c_learner)
    total = a_t + a_l
    if total <= 0.0:
        return 1.0
    return a_t / total


def beta_schedule(i: int, p: float) -> float:
    """DAgger's expert probability at episode ``i`` (1-based): ``beta_i = p ** (i - 1)``."""
    if i < 1:
        raise ValueError(f"Invalid episode index: {i}; episodes are numbered from 1")
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"Invalid decay p: {p}; valid: 0 <= p <= 1")
    return float(p) ** (i - 1)


@dataclass(frozen=True)
class StepView:
    """What a mixing strategy may look at: episode ``i`` (1-based), step ``t`` (0-based),
    expert uncertainty (inf when the expert gave no action), learner uncertainty, the
    expert's and learner's proposed actions (for discrepancy gates; may be None), the
    learner's novelty, a failure risk in [0, 1] given by the caller, and the observation
    ``obs`` (H x W x 3 uint8; None where a caller has none) for gates with their own critic."""

    i: int
    t: int
    u_expert: float
    u_learner: float
    expert_action: object = None
    learner_action: object = None
    novelty: float = 0.0
    risk: float = 0.0
    obs: np.ndarray | None = field(default=None, repr=False, compare=False)


class Mixing:
    """Base class: ``choose(view, rng) -> (agent, probability of that choice)``."""

    name = "mixing"

    def choose(self, view: StepView, rng: np.random.Generator) -> tuple[str, float]:
        raise NotImplementedError

    def begin_episode(self, ctx: EpisodeContext) -> None:
        """Hook called before episode ``ctx.i``; stateful gates reset here."""

    def describe(self) -> dict:
        return {"name": self.name, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}


def _bernoulli(p_expert: float, rng: np.random.Generator) -> tuple[str, float]:
    if p_expert >= 1.0:
        return EXPERT, 1.0
    if p_expert <= 0.0:
        return LEARNER, 1.0
    if rng.random() < p_expert:
        return EXPERT, p_expert
    return LEARNER, 1.0 - p_expert


class ExpertOnly(Mixing):
    """The expert always acts (supervised learning from demonstrations)."""

    name = "expert-only"

    def choose(self, view, rng):
        return EXPERT, 1.0


class BetaDecay(Mixing):
    """DAgger: the expert acts with probability ``p ** (i - 1)``, drawn per step."""

    name = "beta-decay"

    def __init__(self, p: float = 0.5):
        beta_schedule(1, p)
        self.p = float(p)

    def choose(self, view, rng):
        return _bernoulli(beta_schedule(view.i, self.p), rng)


class GeometricMixture(Mixing):
    """SMILe: the expert acts with probability ``(1 - alpha) ** (i - 1)``; otherwise the
    learner (itself a geometric mixture of the policies trained so far) acts."""

    name = "smile"

    def __init__(self, alpha: float = 0.3):
        if not 0.0 < alpha <= 1.0:
            raise ValueError(f"Invalid SMILe alpha: {alpha}; valid: 0 < alpha <= 1")
        self.alpha = float(alpha)

    def choose(self, view, rng):
        return _bernoulli((1.0 - self.alpha) ** (view.i - 1), rng)


class LearnerThreshold(Mixing):
    """DropoutDAgger / EnsembleDAgger: the learner acts when its uncertainty is below
    ``threshold`` and (when ``max_discrepancy`` is set and the expert answered) its action is
    within ``max_discrepancy`` of the expert's; otherwise the expert acts. Episode 1: expert."""

    name = "learner-threshold"

    def __init__(self, threshold: float, max_discrepancy: float | None = None):
        self.threshold = float(threshold)
        self.max_discrepancy = max_discrepancy

    def choose(self, view, rng):
        if view.i == 1:
            return EXPERT, 1.0
        ok = view.u_learner < self.threshold
        if ok and self.max_discrepancy is not None and view.expert_action is not None:
            ok = action_distance(view.learner_action, view.expert_action) <= self.max_discrepancy
        return (LEARNER, 1.0) if ok else (EXPERT, 1.0)


class RationalMixing(Mixing):
    """UPMS: expert with probability ``alpha_T / (alpha_T + alpha_L)``; impossible -> expert.
    Episode 1 is the expert's (the learner has seen nothing yet). ``scale`` given: the thesis's
    ``c = scale`` for both agents; otherwise ``c = atanh(1/2) / threshold`` per agent."""

    name = "rational"

    def __init__(self, expert_threshold: float | None = None, learner_threshold: float | None = None,
                 scale: float | None = None):
        if scale is not None:
            if not float(scale) > 0:
                raise ValueError(f"Invalid uncertainty scale: {scale}; valid: > 0")
            self.c_expert = self.c_learner = float(scale)
        else:
            self.c_expert = saturation(expert_threshold)
            self.c_learner = saturation(learner_threshold)

    def choose(self, view, rng):
        if view.i == 1:
            return EXPERT, 1.0
        return _bernoulli(rational_mixing(view.u_expert, view.u_learner, self.c_expert, self.c_learner), rng)


class ExpertGate(Mixing):
    """HG-DAgger: the expert takes over when it answers with uncertainty below ``threshold``
    (its intervention rule) and keeps control while it keeps answering that confidently."""

    name = "expert-gate"

    def __init__(self, threshold: float):
        self.threshold = float(threshold)

    def choose(self, view, rng):
        if view.i == 1 or (view.expert_action is not None and view.u_expert < self.threshold):
            return EXPERT, 1.0
        return LEARNER, 1.0


class ThriftyGate(Mixing):
    """ThriftyDAgger: the learner cedes control when novelty (ensemble variance) exceeds
    ``novelty_threshold`` or the failure risk exceeds ``risk_threshold``; the expert hands back
    when its action matches the learner's and the risk is low again.

    With a ``critic`` (:class:`crossing_assist.iil.protocols.RiskCritic`, the ThriftyDAgger
    learner) the gate reads the critic's refit thresholds at the start of every episode and the
    risk of each step where the learner proposes an action from ``critic.risk(view.obs)``;
    without one, the thresholds given here and the risk in the view are used."""

    name = "thrifty"

    def __init__(self, novelty_threshold: float = math.inf, risk_threshold: float = math.inf,
                 handback_distance: float = 0.0, critic: RiskCritic | None = None):
        self.novelty_threshold = float(novelty_threshold)
        self.risk_threshold = float(risk_threshold)
        self.handback_distance = float(handback_distance)
        self._critic = critic
        self._expert_in_control = False

    def begin_episode(self, ctx):
        self._expert_in_control = False
        if self._critic is not None:
            self.novelty_threshold = float(self._critic.novelty_threshold)
            self.risk_threshold = float(self._critic.risk_threshold)

    def _risk(self, view: StepView) -> float:
        if self._critic is None:
            return view.risk
        return self._critic.risk(view.obs) if view.learner_action is not None else 0.0

    def choose(self, view, rng):
        if view.i == 1:
            return EXPERT, 1.0
        risk = self._risk(view)
        if self._expert_in_control:
            same = (view.expert_action is not None and
                    action_distance(view.learner_action, view.expert_action) <= self.handback_distance)
            if same and risk <= self.risk_threshold:
                self._expert_in_control = False
        elif view.novelty > self.novelty_threshold or risk > self.risk_threshold:
            self._expert_in_control = True
        return (EXPERT, 1.0) if self._expert_in_control else (LEARNER, 1.0)


class PerStepSchedule(Mixing):
    """Forward Training: time step ``t`` is the learner's once its block's policy is trained
    (blocks trained before episode ``i`` cover steps ``t < (i - 1) * block``), the expert's
    otherwise."""

    name = "forward"

    def __init__(self, block: int):
        if block < 1:
            raise ValueError(f"Invalid Forward Training block: {block}; valid: >= 1 step")
        self.block = int(block)

    def choose(self, view, rng):
        return (LEARNER, 1.0) if view.t < (view.i - 1) * self.block else (EXPERT, 1.0)


def action_distance(a, b) -> float:
    """Distance between two actions: 0/1 for discrete actions, Euclidean for vectors; inf if missing."""
    if a is None or b is None:
        return math.inf
    a_arr, b_arr = np.atleast_1d(np.asarray(a, dtype=float)), np.atleast_1d(np.asarray(b, dtype=float))
    if a_arr.size == 1 and b_arr.size == 1 and float(a_arr[0]).is_integer() and float(b_arr[0]).is_integer():
        return 0.0 if a_arr[0] == b_arr[0] else 1.0
    return float(np.linalg.norm(a_arr - b_arr))
