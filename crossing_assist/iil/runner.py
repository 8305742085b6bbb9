"""Runs: one (environment, algorithm, seed) per folder, resumable after every episode.

Folder ``OUT/<env>/<algo>/seed<k>/``:

* ``config.json`` - the resolved :class:`RunConfig`, the strategies, environment facts
  (frame source) and package versions;
* ``episodes.csv`` - one row an episode (see :func:`crossing_assist.iil.loop.run_episode`);
* ``data/ep<i>.npz`` - the samples episode ``i`` aggregated;
* ``state.pt`` - learner weights, optimiser and the run's random streams after the last episode.

Everything is written atomically; a run whose folder already holds ``k`` finished episodes
with the same configuration continues at episode ``k + 1`` and gives the same numbers as an
uninterrupted run (same random streams).

The expert: the ``thesis`` configuration uses the thesis's 0/inf expert (``U = 0`` while it
wants to act, i.e. above risk ``expert_binary_risk``, default 0.5; ``inf`` otherwise); the
``code`` configuration a continuous confidence unless ``expert_binary_risk`` is set.
"""

from __future__ import annotations

import json
import platform
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ..fileio import atomic_path
from .algorithms import create
from .config import THESIS_BINARY_RISK, AlgoParams, LearnerConfig, RunConfig  # noqa: F401 (re-exported)
from .data import Aggregate
from .envs import make_env
from .experts import OracleExpert
from .files import RunError, _atomic_write, _write_csv, read_episodes  # noqa: F401 (re-exported)
from .loop import Setup, Streams, aggregate_and_learn, run_episode


def make_run_env(cfg: RunConfig):
    """The run's environment (frame size applied where the environment takes one)."""
    if cfg.frame_size is None:
        return make_env(cfg.env)
    if cfg.env != "duckietown":
        raise RunError(f"--frame-size applies to duckietown only (not {cfg.env})")
    return make_env(cfg.env, obs_size=tuple(int(v) for v in cfg.frame_size))


def versions() -> dict:
    out = {"python": platform.python_version(), "numpy": np.__version__, "torch": torch.__version__}
    for mod in ("gymnasium", "gym_duckietown", "pyglet", "crossing_assist"):
        m = sys.modules.get(mod)
        if m is None:
            try:
                m = __import__(mod)
            except Exception:  # noqa: BLE001 - optional packages
                continue
        out[mod] = getattr(m, "__version__", "?")
    return out


def _config_json(cfg: RunConfig) -> dict:
    return json.loads(json.dumps(asdict(cfg)))


def run(cfg: RunConfig, out: Path, *, progress: Callable[[int], None] | None = None,
        on_episode: Callable[[dict], None] | None = None, env=None, expert=None) -> Path:
    """Run (or continue) ``cfg`` under ``out``; returns the run folder. ``expert``: an expert
    object (the human's); default the environment's oracle as :meth:`RunConfig.binary_risk` says."""
    folder = cfg.folder(out)
    env = env or make_run_env(cfg)
    setup = create(cfg.algo, env, horizon=cfg.horizon, episodes=cfg.episodes, seed=cfg.seed,
                   params=cfg.params, cfg=cfg.learner)
    (folder / "data").mkdir(parents=True, exist_ok=True)
    want = _config_json(cfg)
    meta_path = folder / "config.json"
    if meta_path.exists():
        have = json.loads(meta_path.read_text())["run"]
        diff = [k for k in want if k != "episodes" and want[k] != have.get(k)]
        if diff:
            raise RunError(f"{folder}: holds a run with a different {diff[0]} ({have.get(diff[0])!r} vs "
                           f"{want[diff[0]]!r}); use another --out or delete the folder")
    meta = {"run": want, "params_resolved": asdict(cfg.params.resolved(env)), "strategies": setup.describe(),
            "expert": {"kind": cfg.expert, "binary_risk": cfg.binary_risk(), "scale": cfg.expert_scale},
            "versions": versions(),
            "env": {"name": cfg.env, "source": getattr(env.unwrapped, "source", cfg.env)},
            "command": " ".join(sys.argv)}
    _atomic_write(meta_path, json.dumps(meta, indent=2, default=str))
    streams = Streams.from_seed(cfg.seed)
    data, rows = Aggregate(), []
    done = _resume(folder, setup, data, streams, rows)
    if expert is None:
        if cfg.expert != "oracle":
            raise RunError(f"expert {cfg.expert!r} needs an expert object (the CLI opens the window)")
        expert = OracleExpert(env, cfg.expert_scale, cfg.binary_risk())
    for i in range(done + 1, cfg.episodes + 1):
        res = run_episode(env, expert, setup, i, cfg.horizon, streams, progress)
        row = {"episode": i, **res.metrics, **aggregate_and_learn(res, setup, data, streams.train)}
        data.save_episode(folder / "data" / f"ep{i}.npz", i)
        rows.append(row)
        _save_state(folder / "state.pt", setup, streams, i)
        _write_csv(folder / "episodes.csv", rows)
        if on_episode:
            on_episode(row)
    return folder


def _save_state(path: Path, setup: Setup, streams: Streams, episode: int) -> None:
    with atomic_path(path) as tmp:
        torch.save({"episode": episode, "learner": setup.learner.state_dict(),
                    "streams": json.dumps(streams.state())}, tmp)


def _resume(folder: Path, setup: Setup, data: Aggregate, streams: Streams, rows: list[dict]) -> int:
    state_path, csv_path = folder / "state.pt", folder / "episodes.csv"
    if not (state_path.exists() and csv_path.exists()):
        return 0
    try:
        state = torch.load(state_path, weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable checkpoint
        raise RunError(f"{state_path}: unreadable run state ({exc}); delete the folder to start again") from None
    done = int(state["episode"])
    rows.extend(r for r in read_episodes(csv_path) if r["episode"] <= done)
    for i in range(1, done + 1):
        data.load_episode(folder / "data" / f"ep{i}.npz")
    setup.learner.load_state_dict(state["learner"])
    if "streams" not in state:
        raise RunError(f"{state_path}: a run from before the per-concern random streams; delete the folder to start again")
    streams.set_state(json.loads(state["streams"]))
    return done
