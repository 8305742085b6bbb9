"""Checkpoints: a dict of plain types and tensors, saved atomically, loaded with weights_only.

Layout: ``{"format": "crossing_assist.policy", "version": 1, "state_dict": {...},
"config": {...PolicyConfig.to_dict(), plain JSON...}, "metrics": {...}, "epoch": int, ...extra}``. No pickled
objects, so ``torch.load(weights_only=True)`` reads it and a checkpoint cannot run code.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from crossing_assist.errors import UserError

from ..fileio import atomic_path
from .policy import Policy, PolicyConfig

FORMAT = "crossing_assist.policy"
VERSION = 1


class CheckpointError(UserError):
    """A checkpoint that is missing, corrupt or not ours (one line naming the file)."""


def _plain(value: Any, where: str) -> Any:
    """Check that ``value`` survives JSON (the config and metrics must be plain types)."""
    try:
        json.dumps(value, allow_nan=True)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"Invalid {where}: not plain JSON types ({exc})") from None
    return value


def save_checkpoint(path: str | os.PathLike, policy: Policy, extra: dict | None = None) -> Path:
    """Write ``policy`` (state dict + config) plus ``extra`` (metrics, epoch, optimizer state...)
    to ``path`` atomically (temp file in the same folder + ``os.replace``)."""
    path = Path(path)
    extra = dict(extra or {})
    data = {"format": FORMAT, "version": VERSION,
            "state_dict": {k: v.detach().cpu().clone() for k, v in policy.state_dict().items()},
            "config": _plain(policy.config.to_dict(), "config"),
            "metrics": _plain(extra.pop("metrics", {}), "metrics"),
            "epoch": int(extra.pop("epoch", 0))}
    data.update(extra)
    with atomic_path(path, mode=0o600, fsync=True) as tmp:
        torch.save(data, tmp)
    return path


def run_checkpoint(run: str | os.PathLike) -> Path:
    """The checkpoint a ``--run`` names: a ``.pt`` file as given, a run folder's ``weights/best.pt``.
    CheckpointError when it is missing, saying so when the folder has only ``weights/last.pt``
    (a run killed or still in its first epoch) and how to use that one."""
    path = Path(run)
    if path.suffix == ".pt" or not path.is_dir():
        ckpt = path
    else:
        ckpt = path / "weights" / "best.pt"
        last = path / "weights" / "last.pt"
        if not ckpt.is_file() and last.is_file():
            raise CheckpointError(f"{ckpt}: not found; the run has only {last} (no epoch was selected yet: "
                                  f"resume the training, or pass --run {last} to use the latest weights)")
    if not ckpt.is_file():
        raise CheckpointError(f"{ckpt}: checkpoint not found (expected a run folder with weights/best.pt "
                              "or a .pt file)")
    return ckpt


def load_checkpoint(path: str | os.PathLike) -> dict:
    """The raw checkpoint dict; CheckpointError when missing, corrupt or of another format."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint not found")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated zip, garbage bytes, pickled objects, ...
        raise CheckpointError(f"{path}: corrupt or unreadable checkpoint ({type(exc).__name__});"
                              " delete it and retrain, or pick another file") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a crossing_assist policy checkpoint")
    if data.get("version") != VERSION:
        raise CheckpointError(f"{path}: checkpoint version {data.get('version')} unsupported; expected {VERSION}")
    for key in ("state_dict", "config"):
        if not isinstance(data.get(key), dict):
            raise CheckpointError(f"{path}: checkpoint has no {key}")
    return data


def load_policy(path: str | os.PathLike) -> Policy:
    """Rebuild the policy saved at ``path`` (eval mode). CheckpointError when it cannot."""
    data = load_checkpoint(path)
    try:
        config = PolicyConfig.from_dict(data["config"])
        policy = Policy.from_config(config)
        policy.load_state_dict(data["state_dict"])
        if config.weights_source:  # the weights are those the run started from
            policy.backbone.facts = replace(policy.backbone.facts, weights_source=config.weights_source)
    except (KeyError, ValueError, RuntimeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CheckpointError(f"{path}: checkpoint does not fit its config: {first}") from None
    return policy.eval()
