"""The one loop: the thesis's Algorithm 4.1 (generalised interactive imitation learning).

For episode ``i = 1..N``:

1. **mix** - at each step the mixing strategy says who should act (expert / learner), from
   the episode index and both agents' uncertainties;
2. **sample** - the sampling strategy turns that into who really acts (the explorer for
   AggreVaTe's switch step or UPMS's exploration policy ``E'``) and rolls out ``horizon`` steps;
3. **aggregate** - the aggregation strategy picks the labels the episode adds to ``D``;
4. **learn** - the learner is refit on ``D`` (online batch learning after the episode).

The environment's ``done`` (out of bounds or a collision before the horizon) does not end the
episode: the event is counted, its reward (the simulator's -1000) is left out, the environment
is reset to the next pre-computed start point, and the episode goes on until ``horizon`` steps
were taken. This matches the thesis's Table 3, where the expert-only run (Supervised) has 2
out-of-bounds events and still 5120 = 10 x 512 queries.

Randomness comes in separate streams (:class:`Streams`), all derived from the run's one seed
(the thesis: one seed per iteration, the same for every algorithm): start points (a reset seed
per episode and reset, pre-computed, so every algorithm starts from the same poses), mixing,
sampling, exploration and training draws. The expert's demonstration (episode 1) is therefore
the same trace for every algorithm of an iteration.

Counts per episode: **interventions** are the steps the expert acted (in control; the thesis's
"queries"); **expert labels** are the steps whose expert action went into ``D`` (DAgger's
expert labels every step, while acting only when ``beta`` picks it).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .aggregation import Aggregation
from .data import Aggregate, EpisodeContext, Step
from .mixing import EXPERT, EXPLORER, LEARNER, Mixing, StepView
from .protocols import Expert, Learner, iil_env
from .sampling import Sampling


@dataclass
class Setup:
    """One algorithm instance: its registered ``name``, the three strategies and a learner.
    Strategies that need more of the learner compose it (ThriftyDAgger's gate reads its
    critic); values that one strategy passes to another travel in the episode's
    :class:`~crossing_assist.iil.data.EpisodeContext`."""

    name: str
    mixing: Mixing
    sampling: Sampling
    aggregation: Aggregation
    learner: Learner

    def describe(self) -> dict:
        return {"algorithm": self.name, "mixing": self.mixing.describe(), "sampling": self.sampling.describe(),
                "aggregation": self.aggregation.describe(), "learner": type(self.learner).__name__}


@dataclass
class EpisodeResult:
    """Per-episode metrics (see :func:`run_episode`), the trace of steps and the episode's
    context (what the strategies shared; the aggregation reads and writes it too)."""

    metrics: dict
    trace: list[Step] = field(repr=False)
    context: EpisodeContext


def explore(space, rng: np.random.Generator):
    """A uniformly random action of a Discrete or Box space, drawn from ``rng``."""
    if hasattr(space, "n"):
        return int(rng.integers(0, int(space.n)))
    return rng.uniform(space.low, space.high).astype(np.float32)


STREAMS = ("mixing", "sampling", "explore", "train")


def start_seed(seed: int, episode: int, k: int) -> int:
    """The pre-computed start point of reset ``k`` (0: the episode's start) of ``episode`` in
    the iteration with ``seed``: a reset seed that depends on nothing else."""
    return int(np.random.SeedSequence([int(seed), int(episode), int(k)]).generate_state(1)[0] & 0x7FFFFFFF)


@dataclass
class Streams:
    """The run's random streams, one per concern (see the module docstring)."""

    seed: int
    mixing: np.random.Generator
    sampling: np.random.Generator
    explore: np.random.Generator
    train: np.random.Generator

    @classmethod
    def from_seed(cls, seed: int) -> "Streams":
        kids = np.random.SeedSequence(int(seed)).spawn(len(STREAMS))
        return cls(int(seed), *(np.random.default_rng(k) for k in kids))

    def state(self) -> dict:
        return {name: getattr(self, name).bit_generator.state for name in STREAMS}

    def set_state(self, state: dict) -> None:
        for name in STREAMS:
            getattr(self, name).bit_generator.state = state[name]


def run_episode(env, expert: Expert, setup: Setup, i: int, horizon: int, streams: Streams,
                progress: Callable[[int], None] | None = None) -> EpisodeResult:
    """Roll out episode ``i`` (1-based) for ``horizon`` steps and return its metrics and trace.

    Metrics: ``reward`` (sum, out-of-bounds steps excluded) = ``training_reward`` (sum of the
    positive step rewards) - ``penalties`` (sum of the negative step rewards' magnitudes),
    ``out_of_bounds`` (events), ``interventions`` (steps the expert acted), ``learner_steps``,
    ``explorer_steps``, mean uncertainties, and the sums of ``info["reward_terms"]``.
    """
    inner = iil_env(env)
    ctx = EpisodeContext(i=i, horizon=horizon)
    setup.mixing.begin_episode(ctx)
    setup.sampling.begin_episode(ctx, streams.sampling)
    resets = 0
    obs, _ = env.reset(seed=start_seed(streams.seed, i, resets))
    trace, terms = [], {}
    t0 = time.perf_counter()
    for t in range(horizon):
        a_exp, u_exp = expert.act(obs)
        u_exp = math.inf if a_exp is None else float(u_exp)
        a_lrn, u_lrn = setup.learner.act(obs, t, streams.mixing)  # SMILe draws its policy here
        view = StepView(i=i, t=t, u_expert=u_exp, u_learner=float(u_lrn), expert_action=a_exp,
                        learner_action=a_lrn, novelty=float(u_lrn), obs=obs)
        chosen, p_choice = setup.mixing.choose(view, streams.mixing)
        actor = setup.sampling.control(view, chosen, p_choice, streams.sampling)
        if actor == LEARNER and a_lrn is None:
            actor = EXPERT  # an untrained learner (Forward Training's future blocks) cannot act
        if actor == EXPERT:
            action = a_exp if a_exp is not None else inner.safe_action()
        elif actor == LEARNER:
            action = a_lrn
        else:
            action = explore(env.action_space, streams.explore)
        nxt, reward, terminated, truncated, info = env.step(action)
        oob = bool(info.get("out_of_bounds", False))
        for k, v in info.get("reward_terms", {}).items():
            terms[k] = terms.get(k, 0.0) + float(v)
        trace.append(Step(t, obs, a_exp, u_exp, a_lrn, float(u_lrn), actor, action,
                          0.0 if oob else float(reward), oob, actor == EXPERT))
        if terminated or truncated:
            resets += 1
            obs, _ = env.reset(seed=start_seed(streams.seed, i, resets))
        else:
            obs = nxt
        if progress:
            progress(1)
    return EpisodeResult(_metrics(trace, terms, time.perf_counter() - t0), trace, ctx)


def _metrics(trace: list[Step], terms: dict, seconds: float) -> dict:
    ok = [s for s in trace if not s.out_of_bounds]
    u_l = [s.u_learner for s in trace if math.isfinite(s.u_learner)]
    u_e = [s.u_expert for s in trace if math.isfinite(s.u_expert)]
    return {
        "steps": len(trace),
        "reward": float(sum(s.reward for s in ok)),
        "training_reward": float(sum(s.reward for s in ok if s.reward > 0)),
        "penalties": float(-sum(s.reward for s in ok if s.reward < 0)),
        "penalty_steps": int(sum(1 for s in ok if s.reward < 0)),
        "out_of_bounds": int(sum(s.out_of_bounds for s in trace)),
        "interventions": int(sum(s.actor == EXPERT for s in trace)),
        "learner_steps": int(sum(s.actor == LEARNER for s in trace)),
        "explorer_steps": int(sum(s.actor == EXPLORER for s in trace)),
        "mean_u_learner": float(np.mean(u_l)) if u_l else math.nan,
        "mean_u_expert": float(np.mean(u_e)) if u_e else math.nan,
        "seconds_rollout": round(seconds, 3),
        **{f"term_{k}": float(v) for k, v in sorted(terms.items())},
    }


def aggregate_and_learn(result: EpisodeResult, setup: Setup, data: Aggregate, rng: np.random.Generator) -> dict:
    """Steps 3-4: add the labels of episode ``result.context.i`` to ``data``, refit the learner
    (``rng``: the training stream). Returns metrics to merge into the episode's: ``expert_labels`` (steps whose expert
    action went into ``D``), ``labels`` (all samples added), ``self_labels``, ``dataset``,
    ``loss``, ``seconds_fit`` (and the learner's extra fit statistics)."""
    trace, ctx = result.trace, result.context
    i = ctx.i
    picked = setup.aggregation.select(trace, ctx)
    expert_labelled = set()
    for lab in picked:
        data.add(trace[lab.index].obs, lab.action, lab.weight, i, trace[lab.index].t, lab.self_labelled)
        if not lab.self_labelled:
            expert_labelled.add(lab.index)
    setup.learner.observe_episode(trace)
    t0 = time.perf_counter()
    stats = setup.learner.fit(data, i, rng)
    out = {"expert_labels": len(expert_labelled), "labels": len(picked),
           "self_labels": sum(lab.self_labelled for lab in picked),
           "dataset": len(data), "seconds_fit": round(time.perf_counter() - t0, 3)}
    if ctx.cost_to_go is not None:
        out["cost_to_go"] = float(ctx.cost_to_go)
    out.update({k: v for k, v in stats.items() if k not in out})
    return out
