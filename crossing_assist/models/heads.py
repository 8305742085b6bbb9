"""Policy heads with export-safe MC dropout.

Every head splits into a deterministic ``trunk`` (run once per frame) and a stochastic
``tail``: the T Monte-Carlo samples are folded into the batch *after* the trunk, so T samples
cost almost nothing over one. Dropout masks are explicit (``torch.rand_like(x) >= p``, scaled
by ``1 / (1 - p)``), which exports to ONNX as ``RandomUniformLike`` and is never removed by
export or graph optimisation (``nn.Dropout`` is; docs/export.md, "Randomness under onnxruntime").

Kinds
    ``spatial`` (default): features pooled over *rows only* (mean and max; the horizontal axis
    is the task), 1x1 conv + ReLU, a 3-column context conv + ReLU (trunk), then dropout and a
    score per column, resampled to the 12 strips (+ a learned per-strip prior); ``unknown``
    from the column-pooled features; multi-strip actions take the log-sum-exp of their strips.
    ``spatial_fine``: ``spatial`` with the columns upsampled x2 (linear) between the 1x1 conv
    and a 5-column context conv, so a strip *between* two feature columns can score highest.
    ``spatial``'s strip scores are linear between column centres, so its argmax always sits at
    a column: 7 columns on a 224-wide canvas, ~4 across a 3:4 portrait window letterboxed onto
    it, and on PTL val portrait windows it never chose strip 2, 5, 8 or 11.
    ``spatial_strips``: ``spatial`` with the reduced features resampled to the window's 12
    strips *before* the context conv (over strips) and its ReLU, so any strip can peak.
    ``spatial_mlp``: rows-only pooling, 1x1 conv + ReLU, columns resampled to 12, then
    dropout -> linear -> ReLU -> dropout -> linear (not translation equivariant).
    ``thesis``: the thesis's head, 3x3x32 conv (ReLU) -> dropout -> 1x1x|A| conv -> ReLU ->
    global mean; the softmax is applied to these pooled scores by the loss / the consumer.
    ``thesis_fc``: the thesis's ResNet-50 head, global mean -> dropout -> fully connected.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from crossing_assist.errors import UserError
from crossing_assist.registry import Registry

from ..actions import N_BINS


class HeadError(UserError):
    """Invalid head kind or argument."""


HEADS: Registry[type] = Registry("head", error=HeadError)   # kind -> Head subclass (bottom of the file)


from .mc import mc_dropout  # explicit-mask dropout, the one copy (shared with the IIL)


def pool_rows(features: torch.Tensor) -> torch.Tensor:
    """N x C x h x w -> N x 2C x w: mean and max over the rows, the columns kept."""
    return torch.cat([features.mean(2), features.amax(2)], 1)


def strip_weights(w: int, window: torch.Tensor | None, like: torch.Tensor) -> torch.Tensor:
    """Linear-interpolation weights (N|1) x 12 x ``w`` from ``w`` feature columns to the centres
    of the 12 strips of the content ``window`` [N, 2] (fractions of the canvas width; None = the
    whole canvas, where this is a bilinear resize of the columns to 12)."""
    centres = (torch.arange(N_BINS, dtype=like.dtype, device=like.device) + 0.5) / N_BINS
    if window is None:
        pos = centres.unsqueeze(0)                                        # 1 x 12
    else:
        window = window.to(like.dtype)
        pos = window[:, :1] + (window[:, 1:] - window[:, :1]) * centres   # N x 12
    src = (pos * w - 0.5).clamp(0.0, w - 1.0)                             # column coordinate
    j = torch.arange(w, dtype=like.dtype, device=like.device)
    return F.relu(1.0 - (src.unsqueeze(-1) - j).abs())


class Head(nn.Module):
    """Base class. ``forward(features N x C x h x w, samples, mc) -> logits (samples, N, A)``.

    ``mc=None`` means ``mc = self.training``; with ``mc`` False every sample is identical.
    ``p`` (dropout probability, 0 <= p < 1) is a plain settable attribute.
    """

    kind = "base"

    def __init__(self, in_channels: int, n_actions: int, p: float):
        super().__init__()
        if not 0.0 <= float(p) < 1.0:
            raise HeadError(f"Invalid dropout p: {p}; valid: 0 <= p < 1")
        self.in_channels = int(in_channels)
        self.n_actions = int(n_actions)
        self.p = float(p)

    def trunk(self, features: torch.Tensor) -> torch.Tensor:  # deterministic, once per frame
        raise NotImplementedError

    def tail(self, z: torch.Tensor, mc: bool, window: torch.Tensor | None = None) -> torch.Tensor:
        """Stochastic, per sample. ``window`` [N, 2]: the frame's extent on the canvas (heads
        that localise read their strips there; the others ignore it)."""
        raise NotImplementedError

    def forward(self, features: torch.Tensor, samples: int = 1, mc: bool | None = None,
                window: torch.Tensor | None = None) -> torch.Tensor:
        mc = self.training if mc is None else bool(mc)
        z = self.trunk(features)
        n = z.shape[0]
        if not mc:  # every sample is the same: compute one, repeat it (exactly identical)
            return self.tail(z, False, window).unsqueeze(0).expand(samples, n, self.n_actions)
        if samples > 1:
            z = z.unsqueeze(0).expand(samples, *z.shape).reshape(samples * n, *z.shape[1:])
            if window is not None:
                window = window.unsqueeze(0).expand(samples, n, 2).reshape(samples * n, 2)
        logits = self.tail(z, True, window)
        return logits.reshape(samples, n, self.n_actions)


class SpatialMLPHead(Head):
    """Keeps the horizontal axis: per-column features (resampled to 12 columns) feed an MLP."""

    kind = "spatial_mlp"

    def __init__(self, in_channels: int, n_actions: int, p: float = 0.5, width: int = 128,
                 hidden: int = 256, columns: int = N_BINS):
        super().__init__(in_channels, n_actions, p)
        self.columns = int(columns)
        self.reduce = nn.Conv1d(2 * in_channels, width, 1)
        self.fc1 = nn.Linear(width * self.columns, hidden)
        self.fc2 = nn.Linear(hidden, n_actions)

    def trunk(self, features: torch.Tensor) -> torch.Tensor:
        z = F.relu(self.reduce(pool_rows(features)))                      # N x W x w
        # linear resampling of the w columns to 12 as one constant matrix (w x 12): the same numbers
        # as interpolating each row, and an ONNX Resize on a batch of frames (whose size the traced
        # graph would hard-code) is avoided
        eye = torch.eye(z.shape[-1], dtype=z.dtype, device=z.device).unsqueeze(0)
        resample = F.interpolate(eye, size=self.columns, mode="linear", align_corners=False)[0]
        return (z @ resample).flatten(1)                                  # N x (width * 12)

    def tail(self, z: torch.Tensor, mc: bool, window: torch.Tensor | None = None) -> torch.Tensor:
        z = F.relu(self.fc1(mc_dropout(z, self.p, mc)))
        return self.fc2(mc_dropout(z, self.p, mc))

    def column_maps(self, features: torch.Tensor, window: torch.Tensor | None = None) -> torch.Tensor:
        """Class activation along the width: N x A x 12 (each column's share of the logit)."""
        z = self.trunk(features).reshape(features.shape[0], -1, self.columns)   # N x W x 12
        h = F.relu(self.fc1(z.flatten(1)))                                        # N x hidden
        # Gradient-free attribution: occlude one column at a time and record the logit drop.
        base = self.fc2(h)
        drops = []
        for c in range(self.columns):
            zc = z.clone()
            zc[:, :, c] = 0
            drops.append(base - self.fc2(F.relu(self.fc1(zc.flatten(1)))))
        return torch.stack(drops, -1)


class SpatialHead(Head):
    """Translation-equivariant localiser: a score per feature column (with +-1 column of
    context), resampled to the 12 strips; ``unknown`` scored from pooled features; an action
    covering several strips gets the log-sum-exp of their scores."""

    kind = "spatial"

    def __init__(self, in_channels: int, n_actions: int, p: float = 0.5, width: int = 128):
        super().__init__(in_channels, n_actions, p)
        from ..actions import get_space

        self.reduce = nn.Conv1d(2 * in_channels, width, 1)
        self.context = nn.Conv1d(width, width, 3, padding=1)
        self.score = nn.Conv1d(width, 1, 1)
        self.bias = nn.Parameter(torch.zeros(N_BINS))          # per-strip prior
        self.unknown = nn.Linear(width, 1)
        groups = torch.zeros(n_actions - 1, N_BINS)
        for a in range(1, n_actions):
            for b in get_space(n_actions).action_bins(a):
                groups[a - 1, b - 1] = 1.0
        self.register_buffer("groups_mask", torch.log(groups.clamp_min(1e-30)), persistent=False)

    def trunk(self, features: torch.Tensor) -> torch.Tensor:
        z = F.relu(self.reduce(pool_rows(features)))                      # N x W x w
        return F.relu(self.context(z))                                    # N x W x w

    def strip_scores(self, z: torch.Tensor, window: torch.Tensor | None = None) -> torch.Tensor:
        """Trunk output N x W x w -> a score per strip, N x 12: the column scores linearly
        interpolated at the centres of the 12 strips of the content ``window`` [N, 2] (fractions
        of the canvas width; None = the whole canvas, where this equals a bilinear resize of the
        columns to 12)."""
        cols = self.score(z)[:, 0]                                        # N x w
        weight = strip_weights(cols.shape[-1], window, cols)             # (N|1) x 12 x w
        return (weight * cols.unsqueeze(1)).sum(-1) + self.bias

    def column_maps(self, features: torch.Tensor, window: torch.Tensor | None = None) -> torch.Tensor:
        """Where the head sees the goal: the strip scores, N x A x 12 (the same for every action)."""
        bins = self.strip_scores(self.trunk(features), window)
        return bins.unsqueeze(1).expand(bins.shape[0], self.n_actions, N_BINS)

    def tail(self, z: torch.Tensor, mc: bool, window: torch.Tensor | None = None) -> torch.Tensor:
        z = mc_dropout(z, self.p, mc)
        bins = self.strip_scores(z, window)                               # N x 12
        known = torch.logsumexp(bins.unsqueeze(1) + self.groups_mask, -1)  # N x (A - 1)
        unknown = self.unknown(z.mean(2))                                 # N x 1
        return torch.cat([unknown, known], 1)


class FineSpatialHead(SpatialHead):
    """:class:`SpatialHead` at twice the column resolution: the reduced columns are upsampled
    x2 (linear) before the context conv (5 fine columns = the plain head's 3 coarse ones of
    context) and its ReLU, which lets the column scores peak between two feature columns."""

    kind = "spatial_fine"
    UPSAMPLE = 2

    def __init__(self, in_channels: int, n_actions: int, p: float = 0.5, width: int = 128):
        super().__init__(in_channels, n_actions, p, width)
        self.context = nn.Conv1d(width, width, 5, padding=2)

    def trunk(self, features: torch.Tensor) -> torch.Tensor:
        z = F.relu(self.reduce(pool_rows(features)))                      # N x W x w
        z = F.interpolate(z, scale_factor=float(self.UPSAMPLE), mode="linear", align_corners=False)
        return F.relu(self.context(z))                                    # N x W x 2w


class StripSpatialHead(SpatialHead):
    """:class:`SpatialHead` that resamples the reduced *features* (not the scores) to the 12
    strips of the content window, then runs its context conv (+-1 strip), ReLU, dropout and
    score per strip: the non-linearity comes after the resampling, so any strip can score
    highest however few feature columns the window covers (~4 for a 3:4 portrait window)."""

    kind = "spatial_strips"

    def trunk(self, features: torch.Tensor) -> torch.Tensor:
        return F.relu(self.reduce(pool_rows(features)))                   # N x W x w

    def strip_features(self, z: torch.Tensor, window: torch.Tensor | None = None) -> torch.Tensor:
        """N x W x w -> N x W x 12: the features at the strips' centres, with context."""
        weight = strip_weights(z.shape[-1], window, z)                    # (N|1) x 12 x w
        return F.relu(self.context(torch.einsum("ncw,nsw->ncs", z, weight.expand(z.shape[0], -1, -1))))

    def column_maps(self, features: torch.Tensor, window: torch.Tensor | None = None) -> torch.Tensor:
        bins = self.score(self.strip_features(self.trunk(features), window))[:, 0] + self.bias
        return bins.unsqueeze(1).expand(bins.shape[0], self.n_actions, N_BINS)

    def tail(self, z: torch.Tensor, mc: bool, window: torch.Tensor | None = None) -> torch.Tensor:
        s = mc_dropout(self.strip_features(z, window), self.p, mc)        # N x W x 12
        bins = self.score(s)[:, 0] + self.bias                            # N x 12
        known = torch.logsumexp(bins.unsqueeze(1) + self.groups_mask, -1)  # N x (A - 1)
        return torch.cat([self.unknown(s.mean(2)), known], 1)


class ThesisHead(Head):
    """3x3x32 conv (ReLU) -> dropout -> 1x1x|A| conv -> ReLU -> global mean."""

    kind = "thesis"

    def __init__(self, in_channels: int, n_actions: int, p: float = 0.5):
        super().__init__(in_channels, n_actions, p)
        self.conv = nn.Conv2d(in_channels, 32, 3, padding=1)
        self.score = nn.Conv2d(32, n_actions, 1)

    def trunk(self, features: torch.Tensor) -> torch.Tensor:
        return F.relu(self.conv(features))

    def tail(self, z: torch.Tensor, mc: bool, window: torch.Tensor | None = None) -> torch.Tensor:
        return F.relu(self.score(mc_dropout(z, self.p, mc))).mean((2, 3))

    def score_maps(self, features: torch.Tensor) -> torch.Tensor:
        """Class activation maps N x A x h x w (the scores before pooling)."""
        return F.relu(self.score(self.trunk(features)))


class ThesisFCHead(Head):
    """The thesis's ResNet-50 head: global mean -> dropout -> fully connected."""

    kind = "thesis_fc"

    def __init__(self, in_channels: int, n_actions: int, p: float = 0.5):
        super().__init__(in_channels, n_actions, p)
        self.fc = nn.Linear(in_channels, n_actions)

    def trunk(self, features: torch.Tensor) -> torch.Tensor:
        return features.mean((2, 3))

    def tail(self, z: torch.Tensor, mc: bool, window: torch.Tensor | None = None) -> torch.Tensor:
        return self.fc(mc_dropout(z, self.p, mc))

    def score_maps(self, features: torch.Tensor) -> torch.Tensor:
        """Classic CAM: N x A x h x w, the FC weights applied at every position."""
        return torch.einsum("nchw,ac->nahw", features, self.fc.weight)


for _cls in (SpatialHead, FineSpatialHead, StripSpatialHead, SpatialMLPHead, ThesisHead, ThesisFCHead):
    HEADS.register(_cls.kind, _cls)
del _cls
HEAD_KINDS = HEADS.names()   # ("spatial", "spatial_fine", "spatial_strips", "spatial_mlp", "thesis", "thesis_fc")


def create_head(kind: str, in_channels: int, n_actions: int, *, p: float = 0.5) -> Head:
    """Build head ``kind`` (one of :data:`HEAD_KINDS`) on C = ``in_channels``."""
    return HEADS.get(kind)(in_channels, n_actions, p=p)
