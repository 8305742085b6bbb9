"""The registry: each algorithm is a named combination of mixing, sampling, aggregation and
learner. ``create(name, env, ...) -> Setup``; ``list_algorithms()``. The names and their order
are :data:`crossing_assist.iil.config.ALGORITHMS`; each builder is registered under its name
once and ``create`` puts that name on the :class:`~crossing_assist.iil.loop.Setup`.

| name | who acts (mixing) | when the expert is asked (sampling) | aggregated |
|---|---|---|---|
| supervised | expert only | full horizon | expert labels |
| forward | learner for trained time blocks | full horizon | expert labels of this episode's block |
| smile | expert w.p. (1-a)^(i-1), else mixture of past policies | full horizon | this episode's labels (new policy) |
| dagger | expert w.p. p^(i-1) | full horizon | expert labels at every step |
| aggrevate | expert w.p. p^(i-1) until t_s | random switch, explore, expert | cost-to-go weighted expert labels |
| dropout-dagger | learner iff MC-dropout U_L < threshold (code: and close to the expert) | full horizon | expert labels at every step |
| upms | rational mixing | rational sampling (E' with the random explorer E) | expert labels where it acted |
| upms-ne | rational mixing | thesis: rational sampling with E = the learner; code: full horizon | expert labels where it acted |
| upms-sl | rational mixing | rational sampling | + the learner's own labels |
| upms-ne-sl | rational mixing | as upms-ne | + the learner's own labels |
| ensemble-dagger | learner iff ensemble variance < threshold and close to the expert | full horizon | expert labels at every step |
| hg-dagger | expert gates by its rule (U_T < threshold) | full horizon | expert labels where it acted |
| thrifty-dagger | novelty/risk gate, thresholds refit per episode | full horizon | expert labels where it acted |

Two configurations (``AlgoParams.config``) of the thesis's algorithms:

* ``thesis`` - as chapter 4 writes them: UPMS's coefficient ``1 - tanh(30 U)`` for both agents
  (``uncertainty_scale``), rational sampling by Eq. 19-21 (:class:`RationalSampling` ``"thesis"``),
  UPMS-NE as ``E = pi_hat`` inside ``E'``, DropoutDAgger gated by ``sigma^2 < 0.1`` alone
  (``dropout_threshold``); the runner pairs it with the 0/inf expert;
* ``code`` - this project's earlier variant (after the author's public code): ``c =
  atanh(1/2) / threshold`` per agent (thresholds from the environment's defaults), sampling that
  keeps the mixing choice with its own probability, UPMS-NE without sampling, DropoutDAgger with
  the extra action-distance gate ``max_discrepancy`` where the environment sets one; the runner
  pairs it with the continuous expert confidence.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

from crossing_assist.registry import Registry

from .aggregation import Aggregation, CostToGo, ExpertLabels, SelfLabelling
from .config import ALGORITHMS, CONFIGS, THESIS_ALGORITHMS, AlgoParams, LearnerConfig  # noqa: F401 (re-exported)
from .learner_variants import ForwardLearner, SmileLearner, ThriftyLearner
from .learners import EnsembleLearner, NetLearner
from .loop import Setup
from .mixing import EXPLORER, LEARNER
from .mixing import (BetaDecay, ExpertGate, ExpertOnly, GeometricMixture, LearnerThreshold, Mixing, PerStepSchedule,
                     RationalMixing, ThriftyGate)
from .protocols import Learner
from .sampling import FullHorizon, RandomSwitch, RationalSampling, Sampling


class Parts(NamedTuple):
    """What a builder returns: the algorithm's strategies and learner (``create`` names them)."""

    mixing: Mixing
    sampling: Sampling
    aggregation: Aggregation
    learner: Learner


Builder = Callable[..., Parts]
BUILDERS: Registry[Builder] = Registry("algorithm", catalogue=ALGORITHMS,
                                       catalogue_name="crossing_assist.iil.config.ALGORITHMS")


def register(name: str) -> Callable[[Builder], Builder]:
    """Register a builder ``fn(env, horizon, episodes, seed, p, cfg) -> Parts`` under ``name``,
    which must be listed in :data:`~crossing_assist.iil.config.ALGORITHMS`."""
    return BUILDERS.register(name)


def list_algorithms() -> list[str]:
    """The registered algorithms, in the order of :data:`~crossing_assist.iil.config.ALGORITHMS`."""
    return list(BUILDERS.names())


def create(name: str, env, *, horizon: int, episodes: int, seed: int,
           params: AlgoParams = AlgoParams(), cfg: LearnerConfig = LearnerConfig()) -> Setup:
    """Build algorithm ``name`` for ``env`` (its action space and defaults)."""
    builder = BUILDERS.get(name)
    if params.config not in CONFIGS:
        raise ValueError(f"Unknown configuration: {params.config!r}; valid: {', '.join(CONFIGS)}")
    p = params.resolved(env)
    parts = builder(env=env, horizon=horizon, episodes=episodes, seed=seed, p=p, cfg=cfg)
    return Setup(name, *parts)


def _net(env, cfg, seed):
    return NetLearner(env.action_space, cfg, seed)


@register("supervised")
def _supervised(env, horizon, episodes, seed, p, cfg):
    return Parts(ExpertOnly(), FullHorizon(), ExpertLabels("all"), _net(env, cfg, seed))


@register("forward")
def _forward(env, horizon, episodes, seed, p, cfg):
    block = p.forward_block or max(1, -(-horizon // episodes))
    return Parts(PerStepSchedule(block), FullHorizon(), ExpertLabels("block", block),
                 ForwardLearner(env.action_space, cfg, seed, block))


@register("smile")
def _smile(env, horizon, episodes, seed, p, cfg):
    return Parts(GeometricMixture(p.smile_alpha), FullHorizon(), ExpertLabels("all"),
                 SmileLearner(env.action_space, cfg, seed, p.smile_alpha))


@register("dagger")
def _dagger(env, horizon, episodes, seed, p, cfg):
    return Parts(BetaDecay(p.dagger_p), FullHorizon(), ExpertLabels("all"), _net(env, cfg, seed))


@register("aggrevate")
def _aggrevate(env, horizon, episodes, seed, p, cfg):
    return Parts(BetaDecay(p.dagger_p), RandomSwitch(), CostToGo(), _net(env, cfg, seed))


@register("dropout-dagger")
def _dropout_dagger(env, horizon, episodes, seed, p, cfg):
    gate = (LearnerThreshold(p.dropout_threshold) if p.config == "thesis"
            else LearnerThreshold(p.learner_threshold, p.max_discrepancy))
    return Parts(gate, FullHorizon(), ExpertLabels("all"), _net(env, cfg, seed))


def _upms(env, seed, p, cfg, explore: bool, self_label: bool) -> Parts:
    agg = SelfLabelling(ExpertLabels("acting")) if self_label else ExpertLabels("acting")
    if p.config == "thesis":  # Eq. 19-21; UPMS-NE: E = the learner inside E'
        sampling = RationalSampling("thesis", scale=p.uncertainty_scale, explorer=EXPLORER if explore else LEARNER)
        mixing = RationalMixing(scale=p.uncertainty_scale)
    else:
        sampling = RationalSampling("code", expert_threshold=p.expert_threshold) if explore else FullHorizon()
        mixing = RationalMixing(p.expert_threshold, p.learner_threshold)
    return Parts(mixing, sampling, agg, _net(env, cfg, seed))


@register("upms")
def _upms_full(env, horizon, episodes, seed, p, cfg):
    return _upms(env, seed, p, cfg, explore=True, self_label=False)


@register("upms-ne")
def _upms_ne(env, horizon, episodes, seed, p, cfg):
    return _upms(env, seed, p, cfg, explore=False, self_label=False)


@register("upms-sl")
def _upms_sl(env, horizon, episodes, seed, p, cfg):
    return _upms(env, seed, p, cfg, explore=True, self_label=True)


@register("upms-ne-sl")
def _upms_ne_sl(env, horizon, episodes, seed, p, cfg):
    return _upms(env, seed, p, cfg, explore=False, self_label=True)


@register("ensemble-dagger")
def _ensemble_dagger(env, horizon, episodes, seed, p, cfg):
    return Parts(LearnerThreshold(p.ensemble_threshold, p.max_discrepancy), FullHorizon(),
                 ExpertLabels("all"), EnsembleLearner(env.action_space, cfg, seed))


@register("hg-dagger")
def _hg_dagger(env, horizon, episodes, seed, p, cfg):
    return Parts(ExpertGate(p.hg_threshold), FullHorizon(), ExpertLabels("acting"), _net(env, cfg, seed))


@register("thrifty-dagger")
def _thrifty(env, horizon, episodes, seed, p, cfg):
    learner = ThriftyLearner(env.action_space, cfg, seed, target_rate=p.thrifty_rate)
    gate = ThriftyGate(handback_distance=p.max_discrepancy or 0.0, critic=learner)
    return Parts(gate, FullHorizon(), ExpertLabels("acting"), learner)
