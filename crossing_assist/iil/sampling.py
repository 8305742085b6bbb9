"""When the expert is asked and what the rollout explores: sampling strategies.

A sampling strategy turns the mixing decision of a step into the agent that really acts:

* :class:`FullHorizon` - roll the mixed policy out for the whole horizon (DAgger & co.);
* :class:`RandomSwitch` - AggreVaTe: the mixed policy until a random switch time ``t_s``
  (drawn per episode from the sampling stream), one exploration step at ``t_s``, then the
  expert to the end (its rewards give the cost-to-go of the explored action);
* :class:`RationalSampling` - UPMS, two configurations:

  - ``thesis`` (Eq. 18-21): ``pi_RS = a * pi_i + (1 - a) * E'`` with ``a = tanh(c U_L)`` (the
    weight on the mixture ``pi_i`` grows with the learner's uncertainty: explore when it is
    certain, exploit when it is not) and ``E' = alpha_T * expert + (1 - alpha_T) * E``, where
    ``E`` is the random explorer (UPMS) or the learner itself (UPMS-NE: no random explorer);
  - ``code`` (the author's public code and this project's earlier variant): keep the mixing
    choice with its own probability ``p_choice``, else ``E'`` with ``E`` the random explorer.
    With an expert whose uncertainty is only 0 or inf, ``p_choice`` is 1 whenever ``alpha_T``
    is 0, so the explorer never acts.

Every strategy gives episode 1 to the mixing choice (the expert's demonstration).
"""

from __future__ import annotations

import numpy as np

from .data import EpisodeContext
from .mixing import EXPERT, EXPLORER, LEARNER, StepView, coefficient, non_preferential, saturation


class Sampling:
    """Base class: ``control(view, chosen, p_choice, rng) -> agent``."""

    name = "sampling"

    def begin_episode(self, ctx: EpisodeContext, rng: np.random.Generator) -> None:
        """Hook called before episode ``ctx.i`` (1-based) of ``ctx.horizon`` steps; ``rng``:
        the sampling stream."""

    def control(self, view: StepView, chosen: str, p_choice: float, rng: np.random.Generator) -> str:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}


class FullHorizon(Sampling):
    """The mixing decision acts at every step."""

    name = "full-horizon"

    def control(self, view, chosen, p_choice, rng):
        return chosen


class RandomSwitch(Sampling):
    """AggreVaTe: mixed policy before the switch time, explorer at it, expert after it. The
    switch time is drawn per episode into ``ctx.switch_time`` (None in episode 1, which is the
    expert's throughout: nothing to explore from yet), where the aggregation reads it."""

    name = "random-switch"

    def __init__(self):
        self._switch: int | None = None

    def begin_episode(self, ctx, rng):
        self._switch = None if ctx.i == 1 else int(rng.integers(0, ctx.horizon))
        ctx.switch_time = self._switch

    def control(self, view, chosen, p_choice, rng):
        if self._switch is None:
            return EXPERT
        if view.t < self._switch:
            return chosen
        return EXPLORER if view.t == self._switch else EXPERT


class RationalSampling(Sampling):
    """UPMS's rational sampling (see the module docstring). ``mode="thesis"``: Eq. 19-21 with
    ``c = scale`` for both agents and ``explorer`` = :data:`EXPLORER` (UPMS) or :data:`LEARNER`
    (UPMS-NE, ``E = pi_hat``). ``mode="code"``: the author's code, ``c_T = atanh(1/2) /
    expert_threshold``."""

    name = "rational-sampling"

    def __init__(self, mode: str = "thesis", *, scale: float | None = None, expert_threshold: float | None = None,
                 explorer: str = EXPLORER):
        if mode not in ("thesis", "code"):
            raise ValueError(f"Unknown rational sampling mode: {mode!r}; valid: thesis, code")
        if explorer not in (EXPLORER, LEARNER):
            raise ValueError(f"Invalid explorer: {explorer!r}; valid: {EXPLORER}, {LEARNER}")
        if mode == "thesis" and not (scale is not None and float(scale) > 0):
            raise ValueError(f"Invalid uncertainty scale: {scale}; valid: > 0")
        self.mode, self.explorer = mode, explorer
        self.c_expert = float(scale) if mode == "thesis" else saturation(expert_threshold)
        self.c_learner = float(scale) if mode == "thesis" else None
        self._first = True

    def begin_episode(self, ctx, rng):
        self._first = ctx.i == 1

    def _e_prime(self, view: StepView, rng) -> str:
        return EXPERT if rng.random() < coefficient(view.u_expert, self.c_expert) else self.explorer

    def control(self, view, chosen, p_choice, rng):
        if self._first:
            return chosen
        keep = non_preferential(view.u_learner, self.c_learner) if self.mode == "thesis" else p_choice
        if rng.random() < keep:
            return chosen
        return self._e_prime(view, rng)
