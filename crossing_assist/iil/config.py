"""Learner hyper-parameters (torch-free, so the CLI can build its parser cheaply)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LearnerConfig:
    """Hyper-parameters of every learner (defaults: the thesis's)."""

    lr: float = 1e-3
    epochs: int = 3
    batch_size: int = 32
    mc_samples: int = 8
    dropout: float = 0.5
    channels: int = 16
    hidden: int = 64
    ensemble: int = 5
    max_samples: int = 4096  # most recent samples used per fit (bounds time on long runs)
