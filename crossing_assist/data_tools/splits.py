"""Splits without leakage: whole sources (video / place / photographer) go to one split.

:func:`assign_splits` shuffles the sources with a seeded generator and gives each, in turn,
to the split whose frame count is furthest below its target, so every split gets whole
sources and the fractions are met as closely as source sizes allow.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from crossing_assist.data_tools.manifest import SPLITS, Row
from crossing_assist.errors import UserError


class SplitError(UserError):
    """Split fractions that cannot be met."""


@dataclass(frozen=True)
class SplitConfig:
    val: float = 0.2
    test: float = 0.0
    seed: int = 0


def assign_splits(rows: list[Row] | tuple[Row, ...], cfg: SplitConfig) -> list[Row]:
    """Rows with ``split`` reassigned by source (rows keep their order)."""
    if not (0 <= cfg.val < 1 and 0 <= cfg.test < 1 and cfg.val + cfg.test < 1):
        raise SplitError(f"val={cfg.val} test={cfg.test} invalid; each in 0..1 and val + test < 1")
    sizes: dict[str, int] = {}
    for r in rows:
        sizes[r.source] = sizes.get(r.source, 0) + 1
    wanted = {"train": 1 - cfg.val - cfg.test, "val": cfg.val, "test": cfg.test}
    wanted = {k: v for k, v in wanted.items() if v > 0}
    if len(sizes) < len(wanted):
        raise SplitError(f"{len(sizes)} source(s) cannot fill {len(wanted)} splits "
                         f"({', '.join(wanted)}) without putting one source in two splits")
    order = list(sizes)
    perm = np.random.default_rng(cfg.seed).permutation(len(order))
    total = sum(sizes.values())
    filled = {k: 0 for k in wanted}
    where: dict[str, str] = {}
    # smaller splits first, so each gets at least one source
    empty = sorted(wanted, key=lambda k: wanted[k])
    for i in perm:
        src = order[i]
        target = empty.pop(0) if empty else max(wanted, key=lambda k: wanted[k] * total - filled[k])
        where[src] = target
        filled[target] += sizes[src]
    return [replace(r, split=where[r.source]) for r in rows]


def shared_sources(rows: list[Row] | tuple[Row, ...]) -> dict[str, tuple[str, ...]]:
    """Sources that appear in more than one split, with those splits (empty = no leakage)."""
    seen: dict[str, set[str]] = {}
    for r in rows:
        seen.setdefault(r.source, set()).add(r.split)
    return {s: tuple(k for k in SPLITS if k in sp) for s, sp in seen.items() if len(sp) > 1}
