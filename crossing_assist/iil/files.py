"""Small atomic file helpers shared by runs and reports (no torch)."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

from ..fileio import atomic_write_text


class RunError(ValueError):
    """A run cannot start or continue (bad arguments or folder, mismatching configuration)."""


def _atomic_write(path: Path, text: str) -> None:
    atomic_write_text(path, text)


def _write_csv(path: Path, rows: list[dict]) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=keys)
    w.writeheader()
    w.writerows(rows)
    _atomic_write(path, buf.getvalue())


def read_episodes(path: Path) -> list[dict]:
    """Rows of an ``episodes.csv`` with numbers parsed (empty cells -> nan)."""
    with Path(path).open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    def num(v):
        try:
            return float(v) if v not in ("", None) else math.nan
        except ValueError:
            return v
    return [{k: num(v) for k, v in r.items()} for r in rows]
