"""The IIL run's typed configuration (torch-free, so the CLI builds its parser from it cheaply):
learner hyper-parameters, strategy hyper-parameters, one run, and the algorithm catalogue.

Defaults live here once: the CLI's defaults are read from these classes (a test checks it).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path

from .protocols import iil_env

THESIS_HORIZON = 512        # steps per episode in the thesis's Table 3 (10 episodes x 512 steps)
THESIS_BINARY_RISK = 0.5    # the thesis's 0/inf expert wants to act above this risk
CONFIGS = ("thesis", "code")

# Every algorithm, in the order of the registry, ``crossing-iil list`` and the report's table;
# ``crossing_assist.iil.algorithms`` registers one builder for each name (a test checks both ways).
ALGORITHMS = ("supervised", "forward", "smile", "dagger", "aggrevate", "dropout-dagger", "upms", "upms-ne",
              "upms-sl", "upms-ne-sl", "ensemble-dagger", "hg-dagger", "thrifty-dagger")
THESIS_ALGORITHMS = ("supervised", "dagger", "aggrevate", "dropout-dagger", "upms", "upms-ne", "upms-sl",
                     "upms-ne-sl")


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


@dataclass(frozen=True)
class AlgoParams:
    """Hyper-parameters of the strategies. Uncertainty thresholds are in each agent's own
    units (the value where UPMS's coefficient is 1/2, ``code`` configuration); ``None`` means
    the environment's default (``env.unwrapped.iil_defaults``, an
    :class:`~crossing_assist.iil.protocols.IILDefaults`). ``config`` picks the configuration
    (see :mod:`crossing_assist.iil.algorithms`); ``uncertainty_scale`` and ``dropout_threshold``
    are the thesis's (used by ``thesis`` only)."""

    config: str = "thesis"
    uncertainty_scale: float = 30.0
    dropout_threshold: float = 0.1
    dagger_p: float = 0.5
    smile_alpha: float = 0.3
    expert_threshold: float | None = None
    learner_threshold: float | None = None
    ensemble_threshold: float | None = None
    max_discrepancy: float | None = None
    hg_threshold: float | None = None
    thrifty_rate: float = 0.1
    forward_block: int | None = None

    def resolved(self, env) -> AlgoParams:
        """Fill ``None`` fields from the environment's defaults."""
        defaults = iil_env(env).iil_defaults
        return AlgoParams(**{f.name: (getattr(self, f.name) if getattr(self, f.name) is not None
                                      else getattr(defaults, f.name, None)) for f in fields(self)})


@dataclass(frozen=True)
class RunConfig:
    """One run: (environment, algorithm, seed) with its sizes and hyper-parameters."""

    env: str
    algo: str
    seed: int
    episodes: int = 10
    horizon: int = THESIS_HORIZON
    learner: LearnerConfig = field(default_factory=LearnerConfig)
    params: AlgoParams = field(default_factory=AlgoParams)
    expert_scale: float = 1.0
    expert_binary_risk: float | None = None  # r0: the 0/inf expert; None: thesis config 0.5, code config continuous
    frame_size: tuple[int, int] | None = None  # (W, H) of Duckietown's frames; None: the env's (160 x 120)
    expert: str = "oracle"  # "oracle" (scripted) or "human" (keyboard/gamepad window)

    def folder(self, out: Path) -> Path:
        return Path(out) / self.env / self.params.config / self.algo / f"seed{self.seed}"

    def binary_risk(self) -> float | None:
        """The 0/inf expert's risk threshold, or None for the continuous confidence."""
        if self.expert_binary_risk is not None:
            return self.expert_binary_risk
        return THESIS_BINARY_RISK if self.params.config == "thesis" else None
