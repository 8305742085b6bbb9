"""Leave-one-source-out cross-validation (``crossing-train --cv source``).

A user is always an unseen photographer in an unseen city, so the honest figure is measured
on sources the model never trained on: one run per train source ``s`` (``OUT/fold-<s>``), each
trained on the other sources with ``s`` held out (``--holdout s --select-on last``), scored on
``s``'s frames (identity variant only). The frozen-feature cache is shared by all folds (one
source is a mask, never a new cache). ``OUT/cv.json`` and ``OUT/cv.csv`` hold each fold and the
mean +- sd; a fold that already finished is read back, not retrained, so a killed CV resumes.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..data_tools.manifest import atomic_write_text, read_manifest
from .checkpoint import load_checkpoint
from .config import ConfigError, TrainConfig

CV_METRICS = ("accuracy", "bin_mae", "far_x_error", "majority_accuracy", "top3_accuracy", "nll")


def _fold_dir(out: Path, source: str) -> Path:
    return out / ("fold-" + re.sub(r"[^A-Za-z0-9_.-]+", "_", source))


def _fold_metrics(fold: Path, epochs: int) -> dict | None:
    """The held-out metrics of a finished fold (its last epoch), else None."""
    last = fold / "weights" / "last.pt"
    if not last.is_file():
        return None
    state = load_checkpoint(last)
    if int(state.get("epoch", 0)) < epochs:
        return None
    return dict(state["metrics"]["selection"])


def fold_stats(folds: list[dict], keys) -> dict:
    """Per metric in ``keys``: ``{"mean", "sd"}`` over the folds that have it (None where none do;
    sd needs two)."""
    out = {}
    for k in keys:
        vals = np.asarray([f[k] for f in folds if f.get(k) is not None and not math.isnan(f[k])], float)
        out[k] = {"mean": float(vals.mean()) if len(vals) else None,
                  "sd": float(vals.std(ddof=1)) if len(vals) > 1 else None}
    return out


def _train_fold(fcfg: TrainConfig, resume: bool) -> None:
    """One fold in a worker process (``jobs`` > 1); at module level so that it pickles."""
    from .train import train

    train(fcfg, resume=resume)


def _train_side_by_side(todo: list[tuple[TrainConfig, bool]], jobs: int) -> None:
    """The unfinished folds in up to ``jobs`` processes at once (each with the config's
    threads; they share the feature cache, whose entries are built once: cache.entry_lock).
    A fold's error cancels the folds not yet started and is raised (those running finish);
    finished folds are kept for a rerun."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    pool = ProcessPoolExecutor(max_workers=min(jobs, len(todo)), mp_context=mp.get_context("spawn"))
    try:
        futures = {pool.submit(_train_fold, replace(fcfg, progress=False), again): fcfg.holdout[0]
                   for fcfg, again in todo}
        for fut in as_completed(futures):
            fut.result()
            print(f"fold holding out {futures[fut]}: done", flush=True)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


def cross_validate(cfg: TrainConfig, *, resume: bool = False, jobs: int = 1) -> dict:
    """Run (or finish) every fold of ``cfg`` and return the summary written to ``cv.json``;
    ``jobs`` > 1 trains that many folds side by side, in processes of their own."""
    from .train import train

    out = Path(cfg.out)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"Invalid --cv-jobs {jobs!r}; valid: >= 1 (folds trained side by side)")
    sources = read_manifest(cfg.data).split("train").sources()
    if len(sources) < 2:
        raise ConfigError(f"Invalid --cv source: {cfg.data} has {len(sources)} train source(s); need >= 2")
    if cfg.holdout:
        raise ConfigError("Invalid --cv source with --holdout: each fold holds out its own source")
    todo = []   # (what to say, the fold's config, whether it resumes) of each unfinished fold
    for i, source in enumerate(sources, 1):
        fold = _fold_dir(out, source)
        if _fold_metrics(fold, cfg.epochs) is None:
            todo.append((f"fold {i}/{len(sources)}: holding out {source}",
                         replace(cfg, out=str(fold), holdout=(source,), select_on="last"),
                         (fold / "weights" / "last.pt").is_file()))
    if jobs > 1 and len(todo) > 1:
        for line, _, _ in todo:
            print(line, flush=True)
        _train_side_by_side([(fcfg, again) for _, fcfg, again in todo], jobs)
    else:   # one process: each fold announced as it starts
        for line, fcfg, again in todo:
            print(line, flush=True)
            train(fcfg, resume=again)
    folds = []
    for source in sources:
        m = _fold_metrics(_fold_dir(out, source), cfg.epochs)
        folds.append({"source": source, **{k: m.get(k) for k in ("n",) + CV_METRICS}})
    summary = {"cv": "source", "folds": folds, "config": cfg.to_dict(), **fold_stats(folds, CV_METRICS)}
    out.mkdir(parents=True, exist_ok=True)
    clean = lambda v: None if isinstance(v, float) and math.isnan(v) else v  # noqa: E731  (strict JSON: null, not NaN)
    summary["folds"] = [{k: clean(v) for k, v in f.items()} for f in folds]
    atomic_write_text(out / "cv.json", json.dumps(summary, indent=1))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=["source", "n", *CV_METRICS])
    w.writeheader()
    w.writerows(folds)
    atomic_write_text(out / "cv.csv", buf.getvalue())
    return summary


def format_cv(summary: dict) -> str:
    """Lines a person reads: one per fold, then mean +- sd (``n/a`` where a figure is undefined,
    e.g. bin MAE when every fold's is NaN)."""
    def num(v, spec: str, width: int = 0) -> str:
        return format("n/a" if v is None else format(v, spec), f">{width}")

    lines = [f"{'held out':<16} {'n':>5} {'accuracy':>9} {'bin MAE':>8} {'far-x err':>9} {'majority':>9}"]
    for f in summary["folds"]:
        lines.append(f"{f['source']:<16} {f['n']:>5} {num(f['accuracy'], '.3f', 9)} {num(f['bin_mae'], '.3f', 8)} "
                     f"{num(f['far_x_error'], '.4f', 9)} {num(f['majority_accuracy'], '.3f', 9)}")
    ms = lambda k, p=".3f": f"{num(summary[k]['mean'], p)} +- {num(summary[k]['sd'] or 0, p)}"  # noqa: E731
    lines.append(f"leave-one-source-out over {len(summary['folds'])} folds: accuracy {ms('accuracy')}, "
                 f"bin MAE {ms('bin_mae')}, far-x error {ms('far_x_error', '.4f')}")
    return "\n".join(lines)
