"""Environments for interactive imitation learning (gymnasium API), by name.

Each implements :class:`crossing_assist.iil.protocols.IILEnv` beyond ``reset``/``step``:
``oracle() -> (action, risk in [0, 1])`` for the scripted expert, ``safe_action()`` (what the
expert does when it must act but gave nothing), ``iil_defaults``
(:class:`~crossing_assist.iil.protocols.IILDefaults`: uncertainty thresholds in this
environment's units), and reports ``info["out_of_bounds"]`` and ``info["reward_terms"]``.
Environments know no horizon: the loop takes ``horizon`` steps and resets them as often as needed.
"""

from __future__ import annotations

from typing import Any, Callable

from crossing_assist.registry import Registry


def _toy(**kwargs):
    from .toy import ToyLaneEnv  # noqa: PLC0415 - each environment's imports only when made
    return ToyLaneEnv(**kwargs)


def _crossing(synthetic: bool) -> Callable[..., Any]:
    def make(**kwargs):
        from .crossing import CrossingConfig, CrossingEnv  # noqa: PLC0415
        photos = None if synthetic else kwargs.pop("ptl_dir", "auto")
        return CrossingEnv(CrossingConfig(photos=photos, **kwargs))
    return make


def _duckietown(**kwargs):
    from .duckietown import DuckietownLaneEnv  # noqa: PLC0415
    return DuckietownLaneEnv(**kwargs)


# name -> factory(**kwargs); the one list of environments (CLI choices, errors, docs).
ENVIRONMENTS: Registry[Callable[..., Any]] = Registry("environment")
ENVIRONMENTS.register("toy", _toy)
ENVIRONMENTS.register("crossing", _crossing(synthetic=False))
ENVIRONMENTS.register("crossing-synthetic", _crossing(synthetic=True))
ENVIRONMENTS.register("duckietown", _duckietown)
ENV_NAMES = ENVIRONMENTS.names()


def make_env(name: str, **kwargs):
    """``toy`` | ``crossing`` | ``crossing-synthetic`` | ``duckietown`` -> a gymnasium.Env;
    ``kwargs`` go to the environment (its config fields, e.g. ``obs_size`` for Duckietown)."""
    return ENVIRONMENTS.get(name)(**kwargs)
