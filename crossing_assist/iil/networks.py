"""The thesis's learner network (Figure 4.3): a small ResNet with one residual block and a
late, explicit-mask MC dropout layer.

Input: float ``N x 3 x H x W`` in [0, 1] (any H, W >= 16). The trunk (stem conv, one residual
block, pooling that keeps 8 columns of the horizontal axis, a dense layer) runs once; the
``samples`` dropout masks are folded into the batch after it, so T samples cost one trunk
pass. Masks are ``u >= p`` scaled by ``1 / (1 - p)``, drawn from the learner's own generator
(:func:`crossing_assist.models.mc.mc_dropout`, the policy heads' layer; never ``nn.Dropout``,
which export and graph optimisers remove). Output: ``samples x N x out`` (logits, or raw values for
a continuous action).
"""

from __future__ import annotations

import torch
from torch import nn

from ..models.mc import mc_dropout


class ResidualBlock(nn.Module):
    """Two 3x3 convolutions with batch norm and an identity skip: ``relu(x + f(x))``."""

    def __init__(self, channels: int):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(channels, channels, 3, padding=1, bias=False), nn.BatchNorm2d(channels), nn.ReLU(),
            nn.Conv2d(channels, channels, 3, padding=1, bias=False), nn.BatchNorm2d(channels),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.relu(x + self.body(x))


class SmallResNet(nn.Module):
    """Stem (5x5 conv, stride 2, max-pool) -> one residual block -> pool to 2 x 8 -> dense ->
    MC dropout -> linear head with ``n_out`` outputs."""

    def __init__(self, n_out: int, *, channels: int = 16, hidden: int = 64, p: float = 0.5):
        super().__init__()
        if not 0.0 <= p < 1.0:
            raise ValueError(f"Invalid dropout p: {p}; valid: 0 <= p < 1")
        self.p = float(p)
        self.trunk = nn.Sequential(
            nn.Conv2d(3, channels, 5, stride=2, padding=2), nn.ReLU(), nn.MaxPool2d(2),
            ResidualBlock(channels),
            nn.AdaptiveAvgPool2d((2, 8)), nn.Flatten(),
            nn.Linear(channels * 16, hidden), nn.ReLU(),
        )
        self.head = nn.Linear(hidden, n_out)

    def forward(self, x: torch.Tensor, samples: int = 1, mc: bool | None = None,
                generator: torch.Generator | None = None) -> torch.Tensor:
        """``x``: N x 3 x H x W float -> ``samples x N x n_out``; ``mc=None`` means training mode."""
        h = self.trunk(x)
        mc = self.training if mc is None else mc
        h = mc_dropout(h.unsqueeze(0).expand(samples, *h.shape), self.p, mc, generator)
        return self.head(h)
