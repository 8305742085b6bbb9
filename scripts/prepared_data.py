"""The probe scripts' photos: a crossing-data manifest folder and a seeded draw from its rows.

``scripts/prepare_default_data.sh`` writes PTL's manifest to ``runs/data/ptl``, every script's
default ``--data``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from crossing_assist.data_tools.manifest import Dataset, read_manifest


def open_manifest(data: Path) -> Dataset | None:
    """``data``'s manifest; None, after one ``error:`` line on stderr, when there is none."""
    if not (Path(data) / "manifest.csv").is_file():
        print(f"error: no manifest at {Path(data) / 'manifest.csv'} (scripts/prepare_default_data.sh writes "
              "runs/data/ptl)", file=sys.stderr)
        return None
    return read_manifest(data)


def draw(rows: list, n: int, rng: np.random.Generator) -> list:
    """``n`` of ``rows`` (all when fewer) drawn without replacement by ``rng``, in their order."""
    return [rows[i] for i in sorted(rng.choice(len(rows), min(n, len(rows)), replace=False))]
