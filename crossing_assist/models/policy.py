"""The policy: backbone + head + action space, rebuilt from a :class:`PolicyConfig`.

``forward(x, samples, mc)``: x is N x 3 x H x W, already resized to ``config.input_size``
and normalised with ``config.mean / config.std``; returns logits (samples, N, A).
The backbone runs once; the head folds the MC samples into the batch after its trunk.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import torch
from torch import nn

from ..actions import DEFAULT_FOV_DEG, get_space
from ..geometry import FITS, PAD_RGB
from .backbones import Backbone, create_backbone
from .heads import Head, create_head

CONFIG_KEYS = ("backbone", "head", "n_actions", "p", "input_size", "mean", "std", "fov_deg")


def _bad(name: str, want: str, value: Any) -> ValueError:
    return ValueError(f"Invalid policy config: {name} must be {want}, got {value!r}")


def _int(name: str, v: Any, optional: bool = False) -> int | None:
    if v is None and optional:
        return None
    if isinstance(v, bool) or not isinstance(v, numbers.Integral):
        raise _bad(name, "an int" + (" or None" if optional else ""), v)
    return int(v)


def _real(name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise _bad(name, "a number", v)
    return float(v)


def _str(name: str, v: Any, optional: bool = False) -> str | None:
    if v is None and optional:
        return None
    if not isinstance(v, str):
        raise _bad(name, "a string" + (" or None" if optional else ""), v)
    return v


def _seq(name: str, v: Any, n: int | None, item, want: str) -> tuple:
    if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)) or (n is not None and len(v) != n):
        raise _bad(name, f"a list of {'' if n is None else f'{n} '}{want}", v)
    return tuple(item(f"{name}[{i}]", x) for i, x in enumerate(v))


@dataclass(frozen=True, kw_only=True)
class PolicyConfig:
    """What rebuilds a policy and what its checkpoint and bundle say about it (plain JSON on
    disk via :meth:`to_dict` / :meth:`from_dict`; the field order is the on-disk key order).

    Required: the architecture and the input contract (:data:`CONFIG_KEYS`). The rest has the
    defaults a checkpoint written before the field existed was trained with (no ``fit``:
    ``stretch``; no ``pad_rgb``: :data:`crossing_assist.geometry.PAD_RGB`). Keys this class
    does not know are kept, not refused, in ``extra`` and written back by :meth:`to_dict`, so a
    checkpoint round-trips unchanged. Values are validated and normalised in ``__post_init__``
    (sequences become tuples); a wrong type or value is one ``ValueError`` line.
    """

    backbone: str                                   # a name in models.backbones.list_backbones()
    weights_source: str | None = None               # where the starting weights came from
    licence: str | None = None                      # their licence
    head: str                                       # a kind in models.heads.HEAD_KINDS
    n_actions: int                                  # 4, 8 or 13
    names: tuple[str, ...] | None = None            # action names; None: the n-action space's
    p: float                                        # MC dropout probability of the head
    input_size: tuple[int, int]                     # (H, W) canvas, pixels
    mean: tuple[float, ...]                         # per-channel normalisation (RGB, 0..1 scale)
    std: tuple[float, ...]
    fov_deg: float                                  # horizontal FOV of the training photos, degrees
    frozen_blocks: int | None = None                # leading backbone blocks frozen; None: all
    feature_stride: int | None = None               # None: the backbone's own; 16: its stride-16 skip kept
    data: str | None = None                         # the training dataset folder
    fit: str = "stretch"                            # how a frame met the canvas (geometry.FITS)
    pad_rgb: tuple[int, int, int] = PAD_RGB         # letterbox padding colour, uint8 RGB
    counts: dict[str, int] = field(default_factory=dict)  # training set sizes (train.py)
    majority_action: int | None = None              # training majority direction (0: unknown)
    extra: dict[str, Any] = field(default_factory=dict)   # keys of other versions, kept as read

    def __post_init__(self) -> None:
        put = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen: normalising once)
        put("backbone", _str("backbone", self.backbone))
        put("head", _str("head", self.head))
        for k in ("weights_source", "licence", "data"):
            put(k, _str(k, getattr(self, k), optional=True))
        put("n_actions", _int("n_actions", self.n_actions))
        space = get_space(self.n_actions)  # ValueError: Unknown action space
        names = space.names if self.names is None else self.names
        put("names", _seq("names", names, self.n_actions, _str, "strings"))
        put("p", _real("p", self.p))
        if not 0 <= self.p < 1:
            raise _bad("p", "in [0, 1)", self.p)
        put("input_size", _seq("input_size", self.input_size, 2, _int, "ints (H, W)"))
        put("mean", _seq("mean", self.mean, 3, _real, "numbers (RGB)"))
        put("std", _seq("std", self.std, 3, _real, "numbers (RGB)"))
        put("fov_deg", _real("fov_deg", self.fov_deg))
        put("frozen_blocks", _int("frozen_blocks", self.frozen_blocks, optional=True))
        put("feature_stride", _int("feature_stride", self.feature_stride, optional=True))
        put("majority_action", _int("majority_action", self.majority_action, optional=True))
        if _str("fit", self.fit) not in FITS:
            raise _bad("fit", f"one of {', '.join(FITS)}", self.fit)
        put("pad_rgb", _seq("pad_rgb", self.pad_rgb, 3, _int, "ints (RGB)"))
        if not isinstance(self.counts, Mapping) or not all(isinstance(k, str) for k in self.counts):
            raise _bad("counts", "a mapping of names to ints", self.counts)
        put("counts", {k: _int(f"counts[{k!r}]", v) for k, v in self.counts.items()})
        if not isinstance(self.extra, Mapping) or not all(isinstance(k, str) for k in self.extra):
            raise _bad("extra", "a mapping with string keys", self.extra)
        clash = sorted(set(self.extra) & set(_FIELDS))
        if clash:
            raise _bad("extra", "free of field names", clash)
        put("extra", dict(self.extra))

    def to_dict(self) -> dict:
        """Plain JSON (tuples as lists; ``extra`` keys at the top level): what checkpoints store."""
        d = {}
        for name in _FIELDS:
            v = getattr(self, name)
            d[name] = list(v) if isinstance(v, tuple) else dict(v) if isinstance(v, dict) else v
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "PolicyConfig":
        """A config from :meth:`to_dict`'s output or an older checkpoint's dict (missing optional
        keys take their defaults, unknown keys go to ``extra``). ValueError names a missing key."""
        if not isinstance(d, Mapping):
            raise ValueError(f"Invalid policy config: expected a mapping, got {type(d).__name__}")
        missing = [k for k in CONFIG_KEYS if k not in d]
        if missing:
            raise ValueError(f"Invalid policy config: missing {', '.join(missing)}")
        known = {k: v for k, v in d.items() if k in _FIELDS}
        return cls(**known, extra={k: v for k, v in d.items() if k not in _FIELDS})


_FIELDS = tuple(f.name for f in fields(PolicyConfig) if f.name != "extra")  # the typed keys, on-disk order


def policy_config(backbone: Backbone, head_kind: str, n_actions: int, *, p: float = 0.5,
                  input_size: tuple[int, int] | None = None, fov_deg: float = DEFAULT_FOV_DEG,
                  **more: Any) -> PolicyConfig:
    """The config of a policy built on ``backbone`` (its facts fill the input contract);
    ``more``: further :class:`PolicyConfig` fields (fit, frozen_blocks, data, ...)."""
    f = backbone.facts
    return PolicyConfig(backbone=f.name, weights_source=f.weights_source, licence=f.licence,
                        head=head_kind, n_actions=n_actions, p=p, input_size=tuple(input_size or f.input_size),
                        mean=tuple(f.mean), std=tuple(f.std), fov_deg=fov_deg, **more)


def as_policy_config(config: PolicyConfig | Mapping[str, Any]) -> PolicyConfig:
    """``config`` itself, or :meth:`PolicyConfig.from_dict` of a plain dict (ValueError if invalid)."""
    return config if isinstance(config, PolicyConfig) else PolicyConfig.from_dict(config)


class Policy(nn.Module):
    """Backbone + head; ``config`` (a :class:`PolicyConfig`, or its dict) describes both."""

    def __init__(self, backbone: Backbone, head: Head, config: PolicyConfig | Mapping[str, Any]):
        super().__init__()
        self.backbone = backbone
        self.head = head
        self.config: PolicyConfig = as_policy_config(config)
        self.n_actions = self.config.n_actions

    @classmethod
    def from_config(cls, config: PolicyConfig | Mapping[str, Any], *, weights: str = "none") -> "Policy":
        """A policy with the architecture of ``config`` (weights random unless ``weights``)."""
        config = as_policy_config(config)
        backbone = create_backbone(config.backbone, weights=weights, feature_stride=config.feature_stride)
        head = create_head(config.head, backbone.num_features, config.n_actions, p=config.p)
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
