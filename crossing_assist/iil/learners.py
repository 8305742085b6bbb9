"""Learners: the thesis's MC-dropout ResNet, ensembles (EnsembleDAgger, ThriftyDAgger with a
risk critic), Forward Training's one policy per time block and SMILe's mixture of policies.

Every learner has ``act(obs, t, rng) -> (action, uncertainty >= 0)``, ``fit(data, episode,
rng) -> dict`` (online batch learning after each episode, AdaGrad, lr 1e-3 by default),
``observe_episode(trace)`` and ``state_dict()/load_state_dict()`` for resumable runs.
Observations are H x W x 3 uint8 frames. Discrete actions are trained with cross-entropy; the MC-dropout
learner's uncertainty is the predictive entropy (nats) of its mean over samples (an untrained
net is uncertain by it, while its samples still agree), an ensemble's is the mutual
information of its members; continuous (Box)
actions are regressed in [-1, 1] with MSE and their uncertainty is the mean per-dimension
variance over samples (in normalised units), as in the thesis's code.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from ..models.mc import mc_summaries
from .config import LearnerConfig
from .data import Aggregate, Step
from .networks import SmallResNet


class ActionCodec:
    """Maps a gymnasium action space to network outputs. ``n`` discrete actions, or a Box of
    shape (d,) with finite bounds, normalised to [-1, 1]."""

    def __init__(self, space):
        if hasattr(space, "n"):
            self.discrete, self.n_out = True, int(space.n)
            self.low = self.high = None
        else:
            low, high = np.asarray(space.low, dtype=np.float32), np.asarray(space.high, dtype=np.float32)
            if low.ndim != 1 or not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
                raise ValueError(f"Invalid action space: {space}; expected Discrete or a bounded 1-D Box")
            self.discrete, self.n_out, self.low, self.high = False, int(low.shape[0]), low, high

    def encode(self, labels: np.ndarray) -> torch.Tensor:
        if self.discrete:
            return torch.as_tensor(np.asarray(labels, dtype=np.int64))
        lab = np.asarray(labels, dtype=np.float32).reshape(-1, self.n_out)
        return torch.as_tensor(2 * (lab - self.low) / (self.high - self.low) - 1)

    def decode(self, out: torch.Tensor, measure: str = "entropy"):
        """``out``: samples x 1 x n_out -> (action, uncertainty) for one observation. Discrete:
        ``measure`` is ``"entropy"`` (predictive entropy of the mean, nats: high for an
        untrained net too) or ``"mutual_info"`` (disagreement between samples/members)."""
        if self.discrete:  # the bundle graph's summaries (one copy), in float64
            probs, ent, mi, _, _ = mc_summaries(out[:, :1].double())
            u = ent if measure == "entropy" else mi
            return int(probs[0].argmax()), max(float(u[0]), 0.0)
        vals = torch.tanh(out[:, 0]).double().numpy()  # T x d
        mean = vals.mean(0)
        action = (self.low + (mean + 1) / 2 * (self.high - self.low)).astype(np.float32)
        return action, float(vals.var(0).mean()) if vals.shape[0] > 1 else 0.0

    def loss(self, out: torch.Tensor, target: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        if self.discrete:
            per = nn.functional.cross_entropy(out, target, reduction="none")
        else:
            per = ((torch.tanh(out) - target) ** 2).mean(-1)
        return (per * weights).sum() / weights.sum().clamp_min(1e-8)


def to_tensor(obs: np.ndarray) -> torch.Tensor:
    """H x W x 3 (or N x H x W x 3) uint8 -> N x 3 x H x W float in [0, 1]."""
    arr = np.asarray(obs)
    if arr.ndim == 3:
        arr = arr[None]
    return torch.as_tensor(arr).permute(0, 3, 1, 2).float().div_(255.0)


def _seeded_net(n_out: int, cfg: LearnerConfig, seed: int, p: float) -> SmallResNet:
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return SmallResNet(n_out, channels=cfg.channels, hidden=cfg.hidden, p=p)


class NetLearner:
    """One SmallResNet with MC dropout; the thesis's learner."""

    def __init__(self, space, cfg: LearnerConfig, seed: int, p: float | None = None):
        self.codec, self.cfg = ActionCodec(space), cfg
        self.net = _seeded_net(self.codec.n_out, cfg, seed, cfg.dropout if p is None else p)
        self.opt = torch.optim.Adagrad(self.net.parameters(), lr=cfg.lr)
        self.gen = torch.Generator().manual_seed(seed + 1)
        self.trained = False

    def act(self, obs: np.ndarray, t: int, rng: np.random.Generator):
        self.net.eval()
        with torch.no_grad():
            out = self.net(to_tensor(obs), samples=self.cfg.mc_samples, mc=True, generator=self.gen)
        return self.codec.decode(out)

    def fit(self, data: Aggregate, episode: int, rng: np.random.Generator, only_episode: int | None = None) -> dict:
        arrs = data.arrays(only_episode)
        if not arrs:
            return {"loss": math.nan, "samples": 0}
        n = len(arrs["labels"])
        keep = np.arange(0 if self.cfg.max_samples is None else max(0, n - self.cfg.max_samples), n)
        x_all, y_all = arrs["obs"][keep], self.codec.encode(arrs["labels"][keep])
        w_all = torch.as_tensor(arrs["weights"][keep])
        self.net.train()
        losses = []
        for _ in range(self.cfg.epochs):
            order = rng.permutation(len(keep))
            for s in range(0, len(order), self.cfg.batch_size):
                b = order[s:s + self.cfg.batch_size]
                if len(b) < 2:
                    continue
                out = self.net(to_tensor(x_all[b]), samples=1, mc=True, generator=self.gen)[0]
                loss = self.codec.loss(out, y_all[b], w_all[b])
                self.opt.zero_grad()
                loss.backward()
                self.opt.step()
                losses.append(loss.item())
        self.trained = True
        return {"loss": float(np.mean(losses)) if losses else math.nan, "samples": int(len(keep))}

    def observe_episode(self, trace: list[Step]) -> None:
        """Hook for learners that learn from every visited state (ThriftyDAgger's critic)."""

    def state_dict(self) -> dict:
        return {"net": self.net.state_dict(), "opt": self.opt.state_dict(),
                "gen": self.gen.get_state(), "trained": self.trained}

    def load_state_dict(self, state: dict) -> None:
        self.net.load_state_dict(state["net"])
        self.opt.load_state_dict(state["opt"])
        self.gen.set_state(state["gen"])
        self.trained = bool(state["trained"])


class EnsembleLearner:
    """``cfg.ensemble`` SmallResNets (no dropout) on bootstrap resamples; the action is the
    members' mean (discrete: mean probabilities), the uncertainty their disagreement (discrete:
    mutual information of the members; continuous: mean variance)."""

    def __init__(self, space, cfg: LearnerConfig, seed: int):
        self.cfg = cfg
        self.members = [NetLearner(space, cfg, seed + 7919 * k, p=0.0) for k in range(cfg.ensemble)]
        self.codec = self.members[0].codec

    @property
    def trained(self) -> bool:
        return self.members[0].trained

    def act(self, obs, t, rng):
        outs = []
        with torch.no_grad():
            for m in self.members:
                m.net.eval()
                outs.append(m.net(to_tensor(obs), samples=1, mc=False)[0])
        return self.codec.decode(torch.stack(outs), measure="mutual_info")

    def fit(self, data, episode, rng, only_episode=None):
        stats = []
        for m in self.members:
            boot = Aggregate()
            arrs_n = len(data)
            for k in rng.integers(0, arrs_n, size=arrs_n) if arrs_n else []:
                boot.add(data.obs[k], data.labels[k], data.weights[k], data.episodes[k], data.steps[k],
                         data.self_labelled[k])
            stats.append(m.fit(boot, episode, rng)["loss"])
        return {"loss": float(np.nanmean(stats)) if len(data) else math.nan, "samples": len(data)}

    def observe_episode(self, trace):
        pass

    def state_dict(self):
        return {"members": [m.state_dict() for m in self.members]}

    def load_state_dict(self, state):
        for m, s in zip(self.members, state["members"]):
            m.load_state_dict(s)
