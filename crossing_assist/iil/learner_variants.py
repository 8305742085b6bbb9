"""Learners built from :class:`NetLearner`: Forward Training's per-time-block policies,
SMILe's geometric mixture of per-episode policies, and ThriftyDAgger's ensemble + risk critic."""

from __future__ import annotations

import math

import numpy as np
import torch

from .data import Aggregate, Step
from .learners import EnsembleLearner, LearnerConfig, NetLearner, to_tensor
from .networks import SmallResNet


class ForwardLearner:
    """Forward Training: one policy per time block of ``block`` steps (``block = 1`` is the
    textbook one policy per time step). Episode ``i`` trains the policy of block ``i - 1``
    on the expert labels of that block only; ``act`` uses the policy of ``t``'s block."""

    def __init__(self, space, cfg: LearnerConfig, seed: int, block: int):
        self.space, self.cfg, self.seed, self.block = space, cfg, seed, int(block)
        self.policies: dict[int, NetLearner] = {}

    @property
    def trained(self) -> bool:
        return bool(self.policies)

    def act(self, obs, t, rng):
        pol = self.policies.get(t // self.block)
        if pol is None:
            return None, math.inf
        return pol.act(obs, t, rng)

    def fit(self, data: Aggregate, episode: int, rng, only_episode=None):
        b = episode - 1
        sub = Aggregate()
        for k, (e, s) in enumerate(zip(data.episodes, data.steps)):
            if e == episode and s // self.block == b:
                sub.add(data.obs[k], data.labels[k], data.weights[k], e, s, data.self_labelled[k])
        if not len(sub):
            return {"loss": math.nan, "samples": 0}
        pol = NetLearner(self.space, self.cfg, self.seed + 104729 * (b + 1))
        self.policies[b] = pol
        return pol.fit(sub, episode, rng)

    def observe_episode(self, trace):
        pass

    def state_dict(self):
        return {"policies": {str(k): p.state_dict() for k, p in self.policies.items()}}

    def load_state_dict(self, state):
        for k, s in state["policies"].items():
            pol = NetLearner(self.space, self.cfg, self.seed + 104729 * (int(k) + 1))
            pol.load_state_dict(s)
            self.policies[int(k)] = pol


class SmileLearner:
    """SMILe: after episode ``i`` a new policy is trained on that episode's expert labels; the
    learner acts as the mixture of the trained policies with weights ``(1 - alpha) ** (j - 1)``
    (policy ``j`` trained after episode ``j``), one policy drawn per step with ``rng``."""

    def __init__(self, space, cfg: LearnerConfig, seed: int, alpha: float):
        self.space, self.cfg, self.seed, self.alpha = space, cfg, seed, float(alpha)
        self.policies: list[NetLearner] = []

    @property
    def trained(self) -> bool:
        return bool(self.policies)

    def weights(self) -> np.ndarray:
        """Mixture weights of the trained policies (sum to 1)."""
        w = (1.0 - self.alpha) ** np.arange(len(self.policies))
        return w / w.sum()

    def act(self, obs, t, rng):
        if not self.policies:
            return None, math.inf
        j = int(rng.choice(len(self.policies), p=self.weights()))
        return self.policies[j].act(obs, t, rng)

    def fit(self, data, episode, rng, only_episode=None):
        pol = NetLearner(self.space, self.cfg, self.seed + 15485863 * episode)
        stats = pol.fit(data, episode, rng, only_episode=episode)
        if stats["samples"]:
            self.policies.append(pol)
        return stats

    def observe_episode(self, trace):
        pass

    def state_dict(self):
        return {"policies": [p.state_dict() for p in self.policies]}

    def load_state_dict(self, state):
        self.policies = []
        for k, s in enumerate(state["policies"]):
            pol = NetLearner(self.space, self.cfg, self.seed)
            pol.load_state_dict(s)
            self.policies.append(pol)


class ThriftyLearner(EnsembleLearner):
    """ThriftyDAgger's learner: an ensemble (novelty = its disagreement) plus a risk critic
    predicting the chance of going out of bounds within ``risk_horizon`` steps of a visited
    state (trained on every visited state, not only labelled ones). After each fit the gate's
    thresholds are refit: novelty at the ``1 - target_rate`` quantile of the ensemble
    disagreement on the aggregated data, risk at the same quantile over visited states."""

    def __init__(self, space, cfg: LearnerConfig, seed: int, risk_horizon: int = 10,
                 target_rate: float = 0.1, max_visited: int = 4096):
        super().__init__(space, cfg, seed)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed + 3)
            self.critic = SmallResNet(1, channels=cfg.channels, hidden=cfg.hidden, p=0.0)
        self.critic_opt = torch.optim.Adagrad(self.critic.parameters(), lr=cfg.lr * 10)
        self.risk_horizon, self.target_rate, self.max_visited = int(risk_horizon), float(target_rate), max_visited
        self.visited: list[np.ndarray] = []
        self.failed: list[float] = []
        self.novelty_threshold = math.inf
        self.risk_threshold = math.inf

    def risk(self, obs) -> float:
        """Estimated probability (0..1) of going out of bounds soon from ``obs``."""
        self.critic.eval()
        with torch.no_grad():
            return float(torch.sigmoid(self.critic(to_tensor(obs), mc=False)[0, 0, 0]))

    def observe_episode(self, trace: list[Step]) -> None:
        oob = np.array([s.out_of_bounds for s in trace], dtype=bool)
        for k, s in enumerate(trace):
            self.visited.append(s.obs)
            self.failed.append(float(oob[k:k + self.risk_horizon].any()))
        self.visited, self.failed = self.visited[-self.max_visited:], self.failed[-self.max_visited:]

    def fit(self, data, episode, rng, only_episode=None):
        stats = super().fit(data, episode, rng)
        q = 1.0 - self.target_rate
        x, y = np.stack(self.visited) if self.visited else None, torch.tensor(self.failed)
        if x is not None:
            self.critic.train()
            for s in range(0, len(x), self.cfg.batch_size):
                b = rng.permutation(len(x))[: self.cfg.batch_size]
                logit = self.critic(to_tensor(x[b]), mc=False)[0, :, 0]
                loss = torch.nn.functional.binary_cross_entropy_with_logits(logit, y[b])
                self.critic_opt.zero_grad()
                loss.backward()
                self.critic_opt.step()
            sub = rng.permutation(len(x))[:256]
            self.risk_threshold = float(np.quantile([self.risk(x[k]) for k in sub], q))
        if len(data):
            sub = rng.permutation(len(data))[:256]
            self.novelty_threshold = float(np.quantile([self.act(data.obs[k], 0, rng)[1] for k in sub], q))
        return {**stats, "novelty_threshold": self.novelty_threshold, "risk_threshold": self.risk_threshold}

    def state_dict(self):
        return {**super().state_dict(), "critic": self.critic.state_dict(),
                "critic_opt": self.critic_opt.state_dict(), "visited": torch.as_tensor(np.stack(self.visited)) if self.visited else None,
                "failed": list(self.failed), "thresholds": [self.novelty_threshold, self.risk_threshold]}

    def load_state_dict(self, state):
        super().load_state_dict(state)
        self.critic.load_state_dict(state["critic"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.visited = list(state["visited"].numpy()) if state["visited"] is not None else []
        self.failed = list(state["failed"])
        self.novelty_threshold, self.risk_threshold = state["thresholds"]
