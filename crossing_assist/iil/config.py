"""Learner hyper-parameters (torch-free, so the CLI can build its parser cheaply)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LearnerConfig:
    """Hyper-parameters of every learner (defaults: the thesis's)."""

    lr: float = 1e-3
    epochs: int = 3
    batch_size: int = 32
    mc_samples: int = 16  # the thesis's T = 16, p = 0.5
    dropout: float = 0.5
    channels: int = 16
    hidden: int = 64
    ensemble: int = 5
    max_samples: int | None = None  # None: train on all of D (the thesis); k: the k most recent only
