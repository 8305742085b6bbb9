"""Dataset statistics: counts per bin, action space and split; majority-class baselines;
sources shared between splits (leakage); a histogram plot."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crossing_assist.actions import N_BINS, VALID_SPACES, format_label, get_space
from crossing_assist.data_tools.manifest import SPLITS, Dataset


@dataclass(frozen=True)
class DatasetStats:
    """Counts and baselines of a dataset.

    ``bins[split]``: int64 (13,) counts of bins 0..12; ``actions[n][split]``: counts per action
    of the n-action space; ``baseline[n]``: (majority action name, accuracy) of always
    predicting the train split's most common action, measured on val (on train when there is
    no val); ``shared_sources``: sources appearing in more than one split.
    """

    n_rows: int
    bins: dict[str, np.ndarray]
    actions: dict[int, dict[str, np.ndarray]]
    baseline: dict[int, tuple[str, float, str]]
    sources: dict[str, int]
    shared_sources: tuple[str, ...]
    flags: dict[str, int]


def compute_stats(ds: Dataset) -> DatasetStats:
    """Stats of ``ds`` over the splits it has (``all`` is included)."""
    present = [s for s in SPLITS if any(r.split == s for r in ds.rows)]
    bins = {s: np.bincount(ds.split(s).labels(), minlength=N_BINS + 1) for s in present}
    bins["all"] = np.bincount(ds.labels(), minlength=N_BINS + 1)
    actions: dict[int, dict[str, np.ndarray]] = {}
    baseline: dict[int, tuple[str, float, str]] = {}
    fit = "train" if "train" in bins else "all"
    judge = "val" if "val" in bins else fit
    for n in VALID_SPACES:
        space = get_space(n)
        actions[n] = {s: np.bincount(space.lookup, weights=c, minlength=n).astype(np.int64)
                      for s, c in bins.items()}
        major = int(np.argmax(actions[n][fit]))
        total = actions[n][judge].sum()
        acc = float(actions[n][judge][major] / total) if total else float("nan")
        baseline[n] = (space.names[major], acc, judge)
    by_split: dict[str, set[str]] = {}
    for r in ds.rows:
        by_split.setdefault(r.source, set()).add(r.split)
    shared = tuple(sorted(s for s, sp in by_split.items() if len(sp) > 1))
    sources = dict(Counter(r.source for r in ds.rows).most_common())
    flags = dict(Counter(f.split("=")[0] for r in ds.rows for f in r.flags).most_common())
    return DatasetStats(len(ds), bins, actions, baseline, sources, shared, flags)


def format_stats(st: DatasetStats) -> str:
    """Human-readable report of :func:`compute_stats`."""
    splits = list(st.bins)
    out = [f"rows: {st.n_rows}  (" + ", ".join(f"{s} {int(st.bins[s].sum())}" for s in splits if s != "all") + ")"]
    out.append("bin counts:")
    out.append("  " + "split".ljust(8) + "".join(format_label(b).rjust(8) for b in range(N_BINS + 1)))
    for s in splits:
        out.append("  " + s.ljust(8) + "".join(str(int(c)).rjust(8) for c in st.bins[s]))
    for n in (4, 8):
        names = get_space(n).names
        out.append(f"{n}-action counts:")
        out.append("  " + "split".ljust(8) + "".join(nm.rjust(10) for nm in names))
        for s in splits:
            out.append("  " + s.ljust(8) + "".join(str(int(c)).rjust(10) for c in st.actions[n][s]))
    out.append("majority-class baseline (most common train action, accuracy measured on "
               f"{next(iter(st.baseline.values()))[2]}):")
    for n, (name, acc, _) in st.baseline.items():
        out.append(f"  {n:>2} actions: always '{name}' -> accuracy {acc:.3f}")
    out.append(f"sources: {len(st.sources)} (" + ", ".join(f"{k} {v}" for k, v in list(st.sources.items())[:8])
               + (", ..." if len(st.sources) > 8 else "") + ")")
    if st.shared_sources:
        out.append(f"WARNING: {len(st.shared_sources)} source(s) appear in more than one split "
                   f"(frames of one place/video on both sides leak): {', '.join(st.shared_sources[:8])}")
    else:
        out.append("splits are disjoint by source (no leakage)")
    if st.flags:
        out.append("flags: " + ", ".join(f"{k} {v}" for k, v in st.flags.items()))
    return "\n".join(out)


def plot_histogram(st: DatasetStats, path: Path) -> Path:
    """Bar chart of bin counts per split as a PNG (matplotlib, imported here only)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from crossing_assist.data_tools.manifest import atomic_write_bytes
    import io

    splits = [s for s in st.bins if s != "all"] or ["all"]
    fig, ax = plt.subplots(figsize=(8, 3.5), dpi=100)
    width = 0.8 / len(splits)
    x = np.arange(N_BINS + 1)
    for i, s in enumerate(splits):
        ax.bar(x + (i - (len(splits) - 1) / 2) * width, st.bins[s], width, label=f"{s} ({int(st.bins[s].sum())})")
    ax.set_xticks(x, [format_label(b) for b in x])
    ax.set_xlabel("bin (1 = far left strip, 12 = far right)")
    ax.set_ylabel("frames")
    ax.set_title(f"label histogram, {st.n_rows} frames")
    ax.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buf.getvalue())
    return path
