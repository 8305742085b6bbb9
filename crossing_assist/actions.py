"""The action vocabulary: 12 image strips, ``unknown``, and the thesis's 4/8/13 action spaces.

Everything in the package speaks this vocabulary, so it is small, pure (numpy only) and
exhaustively tested.

Bins
    The camera frame is cut into ``N_BINS = 12`` vertical strips of equal width, numbered
    1 (far left) .. 12 (far right). Bin 0 is ``unknown`` (no crossing goal visible / cannot
    tell). A continuous goal position ``x`` (fraction of the frame width, 0 = left edge,
    1 = right edge) falls into bin ``floor(12 x) + 1``, clipped to 1..12.

Action spaces
    Index 0 is ``unknown`` in every space.

    * 4 actions: unknown, left {1-4}, straight {5-8}, right {9-12}
    * 8 actions: unknown, {1}, {2,3}, {4,5}, {6,7}, {8,9}, {10,11}, {12}
    * 13 actions: unknown and each bin

Mirroring (a horizontally flipped frame) maps bin ``k`` to ``13 - k`` and keeps unknown;
each space's grouping is symmetric, so mirroring commutes with grouping.

Headings
    The heading of a position ``x`` is its azimuth under a pinhole camera with horizontal
    field of view ``fov_deg`` (90 degrees by default, the thesis's region in front of the
    user): ``atan((2x - 1) tan(fov/2))``, in degrees, negative = left. The heading of an
    action is the heading of the centre of the strips it covers. Pinhole (not linear) so
    that headings agree exactly with the yaw augmentation and the gyroscope input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Iterable

import numpy as np

N_BINS = 12
UNKNOWN = 0
UNKNOWN_NAME = "unknown"
DEFAULT_FOV_DEG = 90.0
VALID_SPACES = (4, 8, 13)


def _check_bin(b: int, *, allow_unknown: bool = True) -> int:
    if isinstance(b, bool) or not isinstance(b, (int, np.integer)):
        raise TypeError(f"Invalid bin: {b!r}; expected an int")
    lo = 0 if allow_unknown else 1
    if not lo <= int(b) <= N_BINS:
        what = "0 (unknown) or 1..12" if allow_unknown else "1..12"
        raise ValueError(f"Invalid bin: {b}; valid: {what}")
    return int(b)


def _check_fov(fov_deg: float) -> float:
    if not 0.0 < float(fov_deg) < 180.0:
        raise ValueError(f"Invalid field of view: {fov_deg} degrees; valid: 0 < fov < 180")
    return float(fov_deg)


def mirror_bin(b: int) -> int:
    """Bin seen in the horizontally flipped frame: ``k -> 13 - k``; unknown stays unknown."""
    b = _check_bin(b)
    return UNKNOWN if b == UNKNOWN else N_BINS + 1 - b


def mirror_x(x: float) -> float:
    """Goal position in the flipped frame: ``x -> 1 - x``."""
    return 1.0 - _check_x(x)


def _check_x(x: float) -> float:
    x = float(x)
    if not (0.0 <= x <= 1.0) or math.isnan(x):
        raise ValueError(f"Invalid goal position x: {x}; valid: 0 <= x <= 1 (fraction of width)")
    return x


def x_to_bin(x: float) -> int:
    """Strip holding the goal at fraction ``x`` of the frame width: ``floor(12 x) + 1`` in 1..12."""
    return min(N_BINS, int(math.floor(N_BINS * _check_x(x))) + 1)


def bin_center_x(b: int) -> float:
    """Centre of strip ``b`` (1..12) as a fraction of the frame width."""
    b = _check_bin(b, allow_unknown=False)
    return (b - 0.5) / N_BINS


def x_to_heading(x: float, fov_deg: float = DEFAULT_FOV_DEG) -> float:
    """Azimuth in degrees (negative = left) of image position ``x`` under a pinhole camera."""
    x = _check_x(x)
    half = math.radians(_check_fov(fov_deg)) / 2
    return math.degrees(math.atan((2 * x - 1) * math.tan(half)))


def heading_to_x(heading_deg: float, fov_deg: float = DEFAULT_FOV_DEG) -> float:
    """Inverse of :func:`x_to_heading`; positions outside the frame give x < 0 or x > 1."""
    half = math.radians(_check_fov(fov_deg)) / 2
    h = float(heading_deg)
    if not -90.0 < h < 90.0:
        raise ValueError(f"Invalid heading: {h} degrees; valid: -90 < heading < 90")
    return 0.5 + math.tan(math.radians(h)) / (2 * math.tan(half))


def heading_to_pan(heading_deg: float, full_scale_deg: float = DEFAULT_FOV_DEG / 2) -> float:
    """Stereo pan in [-1, 1] (-1 = hard left) for a heading; saturates at ``±full_scale_deg``.

    The default full scale is half the default field of view, so the frame's edges are
    heard hard left / hard right and straight ahead is centred.
    """
    if not float(full_scale_deg) > 0:
        raise ValueError(f"Invalid full_scale_deg: {full_scale_deg}; valid: > 0")
    h = float(heading_deg)
    if math.isnan(h):
        raise ValueError("Invalid heading: nan")
    return max(-1.0, min(1.0, h / float(full_scale_deg)))


def parse_label(value: str | int) -> int:
    """``"unknown"`` / ``"0"`` / ``0`` -> 0, ``"7"`` / ``7`` -> 7; anything else raises ValueError."""
    if isinstance(value, str):
        s = value.strip().lower()
        if s in (UNKNOWN_NAME, "0"):
            return UNKNOWN
        if not s.isdigit():
            raise ValueError(f"Invalid label: {value!r}; valid: 1..12 or 'unknown'")
        value = int(s)
    try:
        return _check_bin(value)
    except (TypeError, ValueError):
        raise ValueError(f"Invalid label: {value!r}; valid: 1..12 or 'unknown'") from None


def format_label(b: int) -> str:
    """Inverse of :func:`parse_label`: 0 -> ``"unknown"``, 7 -> ``"7"``."""
    b = _check_bin(b)
    return UNKNOWN_NAME if b == UNKNOWN else str(b)


@dataclass(frozen=True)
class ActionSpace:
    """One of the thesis's action spaces. ``groups[a]`` are the bins action ``a`` covers."""

    groups: tuple[tuple[int, ...], ...]

    @property
    def n(self) -> int:
        return len(self.groups)

    @property
    def names(self) -> tuple[str, ...]:
        names = [UNKNOWN_NAME]
        for g in self.groups[1:]:
            names.append(str(g[0]) if len(g) == 1 else f"{g[0]}-{g[-1]}")
        if self.n == 4:
            names[1:] = ["left", "straight", "right"]
        return tuple(names)

    def _check_action(self, a: int) -> int:
        if isinstance(a, bool) or not isinstance(a, (int, np.integer)):
            raise TypeError(f"Invalid action: {a!r}; expected an int")
        if not 0 <= int(a) < self.n:
            raise ValueError(f"Invalid action: {a} for the {self.n}-action space; valid: 0..{self.n - 1}")
        return int(a)

    def bin_to_action(self, b: int) -> int:
        """Action (index) whose strips include bin ``b``; unknown -> 0."""
        return int(self.lookup[_check_bin(b)])

    @cached_property
    def lookup(self) -> np.ndarray:
        """``lookup[b]`` is the action of bin ``b`` (0..12), as an int64 array of length 13."""
        table = np.zeros(N_BINS + 1, dtype=np.int64)
        for a, g in enumerate(self.groups):
            table[list(g)] = a
        table.setflags(write=False)
        return table

    def bins_to_actions(self, bins: Iterable[int] | np.ndarray) -> np.ndarray:
        """Vectorised :meth:`bin_to_action` for an array of bins in 0..12."""
        arr = np.asarray(bins)
        if arr.size and (arr.min() < 0 or arr.max() > N_BINS or not np.issubdtype(arr.dtype, np.integer)):
            raise ValueError(f"Invalid bins: values must be integers in 0..12, got {arr.min()}..{arr.max()}")
        return self.lookup[arr.astype(np.int64)]

    def action_bins(self, a: int) -> tuple[int, ...]:
        """Bins covered by action ``a``; ``()`` for unknown."""
        return self.groups[self._check_action(a)]

    def mirror_action(self, a: int) -> int:
        """Action of the mirrored frame (bins k -> 13 - k)."""
        bins = self.action_bins(a)
        return UNKNOWN if not bins else self.bin_to_action(mirror_bin(bins[0]))

    def action_center_x(self, a: int) -> float:
        """Centre of the strips covered by ``a`` as a fraction of the width; ValueError for unknown."""
        bins = self.action_bins(a)
        if not bins:
            raise ValueError("The unknown action has no position; check for action 0 first")
        return (bins[0] - 1 + bins[-1]) / (2 * N_BINS)

    def action_heading(self, a: int, fov_deg: float = DEFAULT_FOV_DEG) -> float:
        """Heading (degrees, negative = left) of the centre of action ``a``'s strips."""
        return x_to_heading(self.action_center_x(a), fov_deg)

    def bin_probs_to_action_probs(self, probs: np.ndarray) -> np.ndarray:
        """Sum 13-way probabilities (unknown + bins, last axis) into this space's actions."""
        probs = np.asarray(probs, dtype=np.float64)
        if probs.shape[-1] != N_BINS + 1:
            raise ValueError(f"Invalid probs: last axis has {probs.shape[-1]} entries; expected 13")
        out = np.zeros(probs.shape[:-1] + (self.n,))
        for a, g in enumerate(self.groups):
            out[..., a] = probs[..., [UNKNOWN] if a == 0 else list(g)].sum(-1)
        return out


def _space(groups: list[tuple[int, ...]]) -> ActionSpace:
    return ActionSpace(groups=((),) + tuple(tuple(g) for g in groups))


SPACES: dict[int, ActionSpace] = {
    4: _space([(1, 2, 3, 4), (5, 6, 7, 8), (9, 10, 11, 12)]),
    8: _space([(1,), (2, 3), (4, 5), (6, 7), (8, 9), (10, 11), (12,)]),
    13: _space([(b,) for b in range(1, N_BINS + 1)]),
}


def get_space(n: int) -> ActionSpace:
    """The ``n``-action space (4, 8 or 13)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer, str)):
        raise TypeError(f"Invalid action space: {n!r}; expected an int")
    try:
        return SPACES[int(n)]
    except (KeyError, ValueError):
        raise ValueError(f"Unknown action space: {n}; valid: 4, 8, 13") from None
