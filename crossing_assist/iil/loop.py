"""The one loop: the thesis's Algorithm 4.1 (generalised interactive imitation learning).

For episode ``i = 1..N``:

1. **mix** - at each step the mixing strategy says who should act (expert / learner), from
   the episode index and both agents' uncertainties;
2. **sample** - the sampling strategy turns that into who really acts (the explorer for
   AggreVaTe's switch step or UPMS's exploration policy ``E'``) and rolls out ``horizon`` steps;
3. **aggregate** - the aggregation strategy picks the labels the episode adds to ``D``;
4. **learn** - the learner is refit on ``D`` (online batch learning after the episode).

Out of bounds does not end the episode: the event is counted, its reward (the simulator's
-1000) is left out of the episode's reward, the environment is reset, and the episode goes
on until ``horizon`` steps were taken, so every episode has the same number of steps.
A **query** is a step whose expert action was used, to act or as a label.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .aggregation import Aggregation
from .data import Aggregate, Step
from .mixing import EXPERT, EXPLORER, LEARNER, Mixing, StepView
from .sampling import Sampling


@dataclass
class Setup:
    """One algorithm instance: the three strategies and a learner (plus an optional hook run
    after each fit, e.g. ThriftyDAgger copying refit thresholds into its gate)."""

    name: str
    mixing: Mixing
    sampling: Sampling
    aggregation: Aggregation
    learner: object
    after_fit: Callable[[], None] | None = None
    risk: Callable[[np.ndarray], float] | None = None

    def describe(self) -> dict:
        return {"algorithm": self.name, "mixing": self.mixing.describe(), "sampling": self.sampling.describe(),
                "aggregation": self.aggregation.describe(), "learner": type(self.learner).__name__}


@dataclass
class EpisodeResult:
    """Per-episode metrics (see :func:`run_episode`) and the trace of steps."""

    metrics: dict
    trace: list[Step] = field(repr=False)


def explore(space, rng: np.random.Generator):
    """A uniformly random action of a Discrete or Box space, drawn from ``rng``."""
    if hasattr(space, "n"):
        return int(rng.integers(0, int(space.n)))
    return rng.uniform(space.low, space.high).astype(np.float32)


def _reset(env, rng):
    obs, _ = env.reset(seed=int(rng.integers(0, 2**31 - 1)))
    return obs


def run_episode(env, expert, setup: Setup, i: int, horizon: int, rng: np.random.Generator,
                progress: Callable[[int], None] | None = None) -> EpisodeResult:
    """Roll out episode ``i`` (1-based) for ``horizon`` steps and return its metrics and trace.

    Metrics: ``reward`` (sum, out-of-bounds steps excluded), ``penalties`` (steps with negative
    reward, out-of-bounds steps excluded), ``out_of_bounds`` (events), ``queries``,
    ``expert_steps``, ``learner_steps``, ``explorer_steps``, mean uncertainties, and the sums
    of the environment's ``info["reward_terms"]``.
    """
    setup.mixing.begin_episode(i)
    setup.sampling.begin_episode(i, horizon, rng)
    obs, trace, terms = _reset(env, rng), [], {}
    t0 = time.perf_counter()
    for t in range(horizon):
        a_exp, u_exp = expert.act(obs)
        u_exp = math.inf if a_exp is None else float(u_exp)
        a_lrn, u_lrn = setup.learner.act(obs, t, rng)
        view = StepView(i=i, t=t, u_expert=u_exp, u_learner=float(u_lrn), expert_action=a_exp,
                        learner_action=a_lrn, novelty=float(u_lrn),
                        risk=setup.risk(obs) if setup.risk and a_lrn is not None else 0.0)
        chosen, p_choice = setup.mixing.choose(view, rng)
        actor = setup.sampling.control(t, chosen, p_choice, u_exp, rng)
        if actor == LEARNER and a_lrn is None:
            actor = EXPERT  # an untrained learner (Forward Training's future blocks) cannot act
        if actor == EXPERT:
            action = a_exp if a_exp is not None else env.unwrapped.safe_action()
        elif actor == LEARNER:
            action = a_lrn
        else:
            action = explore(env.action_space, rng)
        nxt, reward, terminated, truncated, info = env.step(action)
        oob = bool(info.get("out_of_bounds", False))
        for k, v in info.get("reward_terms", {}).items():
            terms[k] = terms.get(k, 0.0) + float(v)
        trace.append(Step(t, obs, a_exp, u_exp, a_lrn, float(u_lrn), actor, action,
                          0.0 if oob else float(reward), oob, actor == EXPERT))
        obs = _reset(env, rng) if (terminated or truncated) else nxt
        if progress:
            progress(1)
    return EpisodeResult(_metrics(trace, terms, time.perf_counter() - t0), trace)


def _metrics(trace: list[Step], terms: dict, seconds: float) -> dict:
    ok = [s for s in trace if not s.out_of_bounds]
    u_l = [s.u_learner for s in trace if math.isfinite(s.u_learner)]
    u_e = [s.u_expert for s in trace if math.isfinite(s.u_expert)]
    return {
        "steps": len(trace),
        "reward": float(sum(s.reward for s in ok)),
        "penalties": int(sum(1 for s in ok if s.reward < 0)),
        "out_of_bounds": int(sum(s.out_of_bounds for s in trace)),
        "expert_steps": int(sum(s.actor == EXPERT for s in trace)),
        "learner_steps": int(sum(s.actor == LEARNER for s in trace)),
        "explorer_steps": int(sum(s.actor == EXPLORER for s in trace)),
        "mean_u_learner": float(np.mean(u_l)) if u_l else math.nan,
        "mean_u_expert": float(np.mean(u_e)) if u_e else math.nan,
        "seconds_rollout": round(seconds, 3),
        **{f"term_{k}": float(v) for k, v in sorted(terms.items())},
    }


def aggregate_and_learn(result: EpisodeResult, setup: Setup, data: Aggregate, i: int,
                        rng: np.random.Generator) -> dict:
    """Steps 3-4: add the episode's labels to ``data``, count queries, refit the learner.
    Returns metrics to merge into the episode's: ``queries``, ``labels``, ``self_labels``,
    ``loss``, ``seconds_fit`` (and the learner's extra fit statistics)."""
    trace = result.trace
    picked = setup.aggregation.select(trace, i, setup.sampling)
    expert_labelled = set()
    for k, label, weight, self_label in picked:
        data.add(trace[k].obs, label, weight, i, trace[k].t, self_label)
        if not self_label:
            expert_labelled.add(k)
    queries = sum(1 for k, s in enumerate(trace)
                  if s.expert_action is not None and (s.actor == EXPERT or k in expert_labelled))
    setup.learner.observe_episode(trace)
    t0 = time.perf_counter()
    stats = setup.learner.fit(data, i, rng)
    if setup.after_fit:
        setup.after_fit()
    out = {"queries": int(queries), "labels": len(picked), "self_labels": int(sum(r[3] for r in picked)),
           "dataset": len(data), "seconds_fit": round(time.perf_counter() - t0, 3)}
    cost = getattr(setup.aggregation, "last_cost_to_go", None)
    if cost is not None:
        out["cost_to_go"] = float(cost)
    out.update({k: v for k, v in stats.items() if k not in out})
    return out
