"""Xception (Chollet 2017), compact: depthwise-separable convolutions with residual blocks.

torchvision has none, so it is written here. Entry flow (stride 8 -> 16 with 728 channels),
``middle_repeats`` middle blocks (8 in the paper), exit flow to 2048 channels at stride 32.
The network has no dropout of its own (the paper's dropout sits in the classifier, which the
head replaces). No ImageNet weights ship; bring a state dict of this class with ``--weights``.
"""

from __future__ import annotations

import torch
from torch import nn


class SeparableConv(nn.Sequential):
    """3x3 depthwise conv then 1x1 pointwise conv, followed by batch norm."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__(
            nn.Conv2d(c_in, c_in, 3, padding=1, groups=c_in, bias=False),
            nn.Conv2d(c_in, c_out, 1, bias=False),
            nn.BatchNorm2d(c_out),
        )


class XBlock(nn.Module):
    """``reps`` x (ReLU, separable conv), optional stride-2 max-pool, plus a (1x1) skip."""

    def __init__(self, c_in: int, c_out: int, reps: int, stride: int, relu_first: bool = True,
                 grow_first: bool = True):
        super().__init__()
        layers: list[nn.Module] = []
        c = c_in
        widths = [c_out] * reps if grow_first else [c_in] * (reps - 1) + [c_out]
        for i, w in enumerate(widths):
            if i > 0 or relu_first:
                layers.append(nn.ReLU())
            layers.append(SeparableConv(c, w))
            c = w
        if stride != 1:
            layers.append(nn.MaxPool2d(3, stride, padding=1))
        self.body = nn.Sequential(*layers)
        self.skip = (
            nn.Sequential(nn.Conv2d(c_in, c_out, 1, stride=stride, bias=False), nn.BatchNorm2d(c_out))
            if stride != 1 or c_in != c_out else nn.Identity()
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x) + self.skip(x)


class Xception(nn.Module):
    """Xception classifier; ``feature_blocks()`` lists its trunk for :class:`Backbone`."""

    num_features = 2048

    def __init__(self, num_classes: int = 1000, middle_repeats: int = 8):
        super().__init__()
        self.stem = nn.Sequential(
            nn.Conv2d(3, 32, 3, stride=2, bias=False), nn.BatchNorm2d(32), nn.ReLU(),
            nn.Conv2d(32, 64, 3, bias=False), nn.BatchNorm2d(64), nn.ReLU(),
        )
        self.entry = nn.Sequential(
            XBlock(64, 128, 2, 2, relu_first=False),
            XBlock(128, 256, 2, 2),
            XBlock(256, 728, 2, 2),
        )
        self.middle = nn.Sequential(*[XBlock(728, 728, 3, 1) for _ in range(middle_repeats)])
        self.exit = nn.Sequential(
            XBlock(728, 1024, 2, 2, grow_first=False),
            SeparableConv(1024, 1536), nn.ReLU(),
            SeparableConv(1536, 2048), nn.ReLU(),
        )
        self.fc = nn.Linear(2048, num_classes)

    def feature_blocks(self) -> list[nn.Module]:
        return [self.stem, *self.entry, *self.middle, self.exit]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for block in self.feature_blocks():
            x = block(x)
        return self.fc(x.mean((2, 3)))
