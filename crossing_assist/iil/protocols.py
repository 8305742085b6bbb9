"""The seams of interactive imitation learning, typed: who the loop talks to.

* :class:`Expert` - ``act(obs) -> (action or None, uncertainty in [0, inf])``; ``None`` (no
  answer) comes with ``inf``.
* :class:`Learner` - acts with an uncertainty, is refit on the aggregate ``D`` after each
  episode, sees every visited step, and saves/loads its state for resumable runs.
* :class:`IILEnv` - what an environment offers beyond gymnasium's ``reset``/``step`` (checked on
  ``env.unwrapped``): the scripted expert's ``oracle()``, ``safe_action()`` (what the expert does
  when it must act but gave nothing), and ``iil_defaults`` (:class:`IILDefaults`: uncertainty
  thresholds in this environment's units). Its ``step`` reports ``info["out_of_bounds"]`` (bool)
  and ``info["reward_terms"]`` (dict of floats that sum to the reward inside bounds).
* :class:`RiskCritic` - a learner that also predicts its failure risk (ThriftyDAgger's): the
  gate composes it and reads its refit thresholds at the start of each episode.

Actions are an ``int`` (Discrete spaces) or a float32 vector (bounded 1-D Box spaces).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from .data import Aggregate, Step

Action = int | np.ndarray


@runtime_checkable
class Expert(Protocol):
    """``act(obs)``: H x W x 3 uint8 frame -> (action or None, uncertainty >= 0; inf with None)."""

    def act(self, obs: np.ndarray) -> tuple[Action | None, float]: ...


@runtime_checkable
class Learner(Protocol):
    """The learner contract (see :mod:`crossing_assist.iil.learners`).

    ``act(obs, t, rng)``: the action at step ``t`` (0-based) and its uncertainty (>= 0, in the
    learner's own units; ``(None, inf)`` when it cannot act yet). ``fit(data, episode, rng)``:
    refit on ``D`` after episode ``episode`` (1-based); returns statistics, at least ``loss`` and
    ``samples``. ``observe_episode(trace)``: every visited step (for learners that learn from
    unlabelled states). ``trained``: whether it has been fit at least once."""

    @property
    def trained(self) -> bool: ...

    def act(self, obs: np.ndarray, t: int, rng: np.random.Generator) -> tuple[Action | None, float]: ...

    def fit(self, data: Aggregate, episode: int, rng: np.random.Generator) -> dict[str, Any]: ...

    def observe_episode(self, trace: Sequence[Step]) -> None: ...

    def state_dict(self) -> dict: ...

    def load_state_dict(self, state: dict) -> None: ...


@runtime_checkable
class RiskCritic(Protocol):
    """A learner with a failure-risk critic: ``risk(obs)`` in [0, 1] and the gate thresholds
    refit after each fit (``inf`` before the first)."""

    novelty_threshold: float
    risk_threshold: float

    def risk(self, obs: np.ndarray) -> float: ...


@dataclass(frozen=True)
class IILDefaults:
    """An environment's defaults for :class:`crossing_assist.iil.config.AlgoParams` fields left
    ``None``: uncertainty thresholds where UPMS's coefficient is 1/2 (``code`` configuration),
    each in that agent's units, and the largest action distance counted as agreement."""

    expert_threshold: float
    learner_threshold: float
    ensemble_threshold: float
    hg_threshold: float
    max_discrepancy: float | None = None


@runtime_checkable
class IILEnv(Protocol):
    """What the loop and the scripted expert need from ``env.unwrapped`` (module docstring)."""

    iil_defaults: IILDefaults

    def oracle(self) -> tuple[Action | None, float]:
        """The privileged expert action (None: none) and the risk in [0, 1] of the state."""
        ...

    def safe_action(self) -> Action: ...


def iil_env(env: Any) -> IILEnv:
    """``env.unwrapped`` checked against :class:`IILEnv`; ``TypeError`` naming what is missing."""
    inner = getattr(env, "unwrapped", env)
    missing = [m for m in ("oracle", "safe_action", "iil_defaults") if not hasattr(inner, m)]
    if missing:
        raise TypeError(f"Invalid environment: {type(inner).__name__} lacks {', '.join(missing)}; "
                        "an IIL environment implements crossing_assist.iil.protocols.IILEnv")
    if not isinstance(inner.iil_defaults, IILDefaults):
        raise TypeError(f"Invalid environment: {type(inner).__name__}.iil_defaults is "
                        f"{type(inner.iil_defaults).__name__}; expected IILDefaults")
    return inner
