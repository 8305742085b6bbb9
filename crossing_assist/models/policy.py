"""The policy: backbone + head + action space, rebuilt from a plain-JSON config.

``forward(x, samples, mc)``: x is N x 3 x H x W, already resized to ``config["input_size"]``
and normalised with ``config["mean"] / config["std"]``; returns logits (samples, N, A).
The backbone runs once; the head folds the MC samples into the batch after its trunk.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from ..actions import DEFAULT_FOV_DEG, get_space
from .backbones import Backbone, create_backbone
from .heads import Head, create_head

CONFIG_KEYS = ("backbone", "head", "n_actions", "p", "input_size", "mean", "std", "fov_deg")


def policy_config(backbone: Backbone, head_kind: str, n_actions: int, *, p: float = 0.5,
                  input_size: tuple[int, int] | None = None, fov_deg: float = DEFAULT_FOV_DEG,
                  **extra: Any) -> dict:
    """The plain-JSON config of a policy (what checkpoints and bundles carry)."""
    f = backbone.facts
    cfg = {
        "backbone": f.name, "weights_source": f.weights_source, "licence": f.licence,
        "head": head_kind, "n_actions": int(n_actions), "names": list(get_space(n_actions).names),
        "p": float(p), "input_size": list(input_size or f.input_size),
        "mean": list(f.mean), "std": list(f.std), "fov_deg": float(fov_deg),
    }
    cfg.update(extra)
    return cfg


class Policy(nn.Module):
    """Backbone + head. ``frozen_blocks``: how many leading backbone blocks stay frozen."""

    def __init__(self, backbone: Backbone, head: Head, config: dict):
        super().__init__()
        missing = [k for k in CONFIG_KEYS if k not in config]
        if missing:
            raise ValueError(f"Invalid policy config: missing {', '.join(missing)}")
        get_space(int(config["n_actions"]))
        self.backbone = backbone
        self.head = head
        self.config = dict(config)
        self.n_actions = int(config["n_actions"])

    @classmethod
    def from_config(cls, config: dict, *, weights: str = "none") -> "Policy":
        """A policy with the architecture of ``config`` (weights random unless ``weights``)."""
        backbone = create_backbone(config["backbone"], weights=weights)
        head = create_head(config["head"], backbone.num_features, int(config["n_actions"]), p=float(config["p"]))
        return cls(backbone, head, config)

    def forward(self, x: torch.Tensor, samples: int = 1, mc: bool | None = None,
                window: torch.Tensor | None = None) -> torch.Tensor:
        """``window`` [N, 2]: the frame's extent on the canvas (fractions of its width; None =
        the whole canvas), where the head reads the 12 strips."""
        return self.head(self.backbone.forward_features(x), samples=samples, mc=mc, window=window)

    def forward_from(self, cached: torch.Tensor, start: int, samples: int = 1,
                     mc: bool | None = None, window: torch.Tensor | None = None) -> torch.Tensor:
        """Logits from cached output of backbone blocks ``[0, start)``."""
        return self.head(self.backbone.forward_from(cached, start), samples=samples, mc=mc, window=window)
