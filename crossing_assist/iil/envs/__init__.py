"""Environments for interactive imitation learning (gymnasium API).

Each implements, beyond ``reset``/``step``: ``oracle() -> (action, risk in [0, 1])`` for the
scripted expert, ``safe_action()`` (what the expert does when it must act but gave nothing),
``iil_defaults`` (uncertainty thresholds in this environment's units), and reports
``info["out_of_bounds"]`` and ``info["reward_terms"]``.
"""

from __future__ import annotations


def make_env(name: str, *, horizon: int = 512, **kwargs):
    """``toy`` | ``crossing`` | ``crossing-synthetic`` | ``duckietown`` -> a gymnasium.Env."""
    if name == "toy":
        from .toy import ToyLaneEnv
        return ToyLaneEnv(**kwargs)
    if name in ("crossing", "crossing-synthetic"):
        from .crossing import CrossingEnv, CrossingConfig
        return CrossingEnv(CrossingConfig(photos=None if name == "crossing-synthetic" else kwargs.pop("ptl_dir", "auto"),
                                          **kwargs))
    if name == "duckietown":
        from .duckietown import DuckietownLaneEnv
        return DuckietownLaneEnv(**kwargs)
    raise ValueError(f"Unknown environment: {name!r}; valid: toy, crossing, crossing-synthetic, duckietown")


ENV_NAMES = ("toy", "crossing", "crossing-synthetic", "duckietown")
