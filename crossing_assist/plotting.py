"""Figures for every package: matplotlib on its Agg backend, imported only when a figure is made
(it is not a runtime dependency), and written atomically (temp file + ``os.replace``)."""

from __future__ import annotations

from pathlib import Path

from crossing_assist.fileio import atomic_path


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (ImportError without matplotlib)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | Path, dpi: int = 100) -> Path:
    """Write ``fig`` to ``path`` atomically and close it."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    pyplot().close(fig)
    return path
