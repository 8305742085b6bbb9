"""When the expert is asked and what the rollout explores: sampling strategies.

A sampling strategy turns the mixing decision of a step into the agent that really acts:

* :class:`FullHorizon` - roll the mixed policy out for the whole horizon (DAgger & co.);
* :class:`RandomSwitch` - AggreVaTe: the mixed policy until a random switch time ``t_s``
  (drawn per episode from the rng), one exploration step at ``t_s``, then the expert to the
  end (its rewards give the cost-to-go of the explored action);
* :class:`RationalSampling` - UPMS: the mixing choice acts with its own probability
  ``p_choice``; otherwise the exploration policy ``E'`` acts, which is the expert with
  probability ``alpha_T`` and the explorer otherwise.
"""

from __future__ import annotations

import numpy as np

from .mixing import EXPERT, EXPLORER, coefficient, saturation


class Sampling:
    """Base class: ``control(t, chosen, p_choice, u_expert, rng) -> agent``."""

    name = "sampling"

    def begin_episode(self, i: int, horizon: int, rng: np.random.Generator) -> None:
        """Hook called before episode ``i`` (1-based) with the horizon (steps)."""

    def control(self, t: int, chosen: str, p_choice: float, u_expert: float,
                rng: np.random.Generator) -> str:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}


class FullHorizon(Sampling):
    """The mixing decision acts at every step."""

    name = "full-horizon"

    def control(self, t, chosen, p_choice, u_expert, rng):
        return chosen


class RandomSwitch(Sampling):
    """AggreVaTe: mixed policy before ``switch_time``, explorer at it, expert after it.
    Episode 1 is the expert's throughout (nothing to explore from yet)."""

    name = "random-switch"

    def __init__(self):
        self.switch_time: int | None = None
        self._first = True

    def begin_episode(self, i, horizon, rng):
        self._first = i == 1
        self.switch_time = None if self._first else int(rng.integers(0, horizon))

    def control(self, t, chosen, p_choice, u_expert, rng):
        if self._first:
            return EXPERT
        if t < self.switch_time:
            return chosen
        return EXPLORER if t == self.switch_time else EXPERT


class RationalSampling(Sampling):
    """UPMS: keep the mixing choice with probability ``p_choice``, else act with
    ``E' = alpha_T * expert + (1 - alpha_T) * explorer``. Needs a continuous expert
    confidence: with ``U_T`` only 0 or inf, ``p_choice`` is 1 whenever the expert answers."""

    name = "rational-sampling"

    def __init__(self, expert_threshold: float):
        self.c_expert = saturation(expert_threshold)

    def control(self, t, chosen, p_choice, u_expert, rng):
        if rng.random() < p_choice:
            return chosen
        return EXPERT if rng.random() < coefficient(u_expert, self.c_expert) else EXPLORER
