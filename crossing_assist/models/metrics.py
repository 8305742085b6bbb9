"""Evaluation metrics for action probabilities (numpy only: used for checkpoints AND bundles).

Conventions: ``probs`` is N x A (rows sum to 1), ``labels`` are action indices 0..A-1 with
0 = unknown. The *bin error* of a frame is ``|predicted action - true action|`` in action
indices, over frames whose true and predicted actions are both known (the thesis excluded
unknown); frames with a known goal predicted ``unknown`` are counted separately.
"""

from __future__ import annotations

import math

import numpy as np

from ..actions import UNKNOWN, get_space

ECE_BINS = 15


def _mean_ci(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and normal-approximation 95% interval; nan when empty."""
    n = values.size
    if n == 0:
        return math.nan, math.nan, math.nan
    m = float(values.mean())
    half = 1.96 * float(values.std(ddof=1)) / math.sqrt(n) if n > 1 else math.nan
    return m, m - half, m + half


def bin_errors(pred: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """|pred - label| (action indices) where both are known (non-zero)."""
    keep = (pred != UNKNOWN) & (labels != UNKNOWN)
    return np.abs(pred[keep] - labels[keep]).astype(np.float64)


def expected_x(probs: np.ndarray, n_actions: int) -> np.ndarray:
    """E[x] (fraction of width) under the known-action part of ``probs``; nan if it is all 0."""
    space = get_space(n_actions)
    centres = np.array([space.action_center_x(a) for a in range(1, n_actions)])
    known = probs[:, 1:]
    mass = known.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(mass > 0, known @ centres / mass, np.nan)


def calibration_bins(probs: np.ndarray, labels: np.ndarray, n_bins: int = ECE_BINS) -> dict:
    """Reliability diagram data: per confidence bin the count, mean confidence and accuracy."""
    conf = probs.max(1)
    correct = probs.argmax(1) == labels
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    idx = np.clip(np.digitize(conf, edges[1:-1]), 0, n_bins - 1)
    count = np.bincount(idx, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_conf = np.bincount(idx, conf, n_bins) / count
        acc = np.bincount(idx, correct.astype(np.float64), n_bins) / count
    ece = float(np.nansum(count / max(1, len(labels)) * np.abs(acc - mean_conf)))
    return {"edges": edges.tolist(), "count": count.tolist(),
            "confidence": [None if np.isnan(v) else float(v) for v in mean_conf],
            "accuracy": [None if np.isnan(v) else float(v) for v in acc], "ece": ece}


def compute_metrics(probs: np.ndarray, labels: np.ndarray, n_actions: int,
                    far_x: np.ndarray | None = None, *, majority: int | None = None) -> dict:
    """All evaluation numbers for one split, as plain JSON types.

    probs: N x A probabilities; labels: (N,) actions; far_x: (N,) goal x in [0, 1] or nan;
    majority: the baseline's constant action (the most common *training* action; defaults to
    the most common action of ``labels``, which flatters the baseline).
    """
    probs = np.asarray(probs, dtype=np.float64)
    labels = np.asarray(labels, dtype=np.int64)
    if probs.ndim != 2 or probs.shape[1] != n_actions or probs.shape[0] != labels.shape[0]:
        raise ValueError(f"Invalid shapes: probs {probs.shape}, labels {labels.shape}; expected N x {n_actions} and (N,)")
    if labels.size == 0:
        raise ValueError("Invalid labels: no frames to evaluate")
    if labels.min() < 0 or labels.max() >= n_actions:
        raise ValueError(f"Invalid labels: values must be in 0..{n_actions - 1}")
    n = labels.size
    pred = probs.argmax(1)
    if majority is None:
        majority = int(np.bincount(labels, minlength=n_actions).argmax())
    base = np.full(n, majority)
    errs, base_errs = bin_errors(pred, labels), bin_errors(base, labels)
    mae, lo, hi = _mean_ci(errs)
    bmae, blo, bhi = _mean_ci(base_errs)
    present = np.unique(labels)
    recalls = [float((pred[labels == c] == c).mean()) for c in present]
    top3 = np.argsort(-probs, 1)[:, :3]
    p_true = np.clip(probs[np.arange(n), labels], 1e-12, 1.0)
    conf = np.zeros((n_actions, n_actions), dtype=np.int64)
    np.add.at(conf, (labels, pred), 1)
    out = {
        "n": int(n), "n_actions": int(n_actions), "names": list(get_space(n_actions).names),
        "accuracy": float((pred == labels).mean()),
        "bin_mae": mae, "bin_mae_ci95": [lo, hi], "bin_mae_n": int(errs.size),
        "pred_unknown_when_known": int(((pred == UNKNOWN) & (labels != UNKNOWN)).sum()),
        "majority_action": int(majority), "majority_accuracy": float((base == labels).mean()),
        "majority_bin_mae": bmae, "majority_bin_mae_ci95": [blo, bhi],
        "balanced_accuracy": float(np.mean(recalls)),
        "top3_accuracy": float((top3 == labels[:, None]).any(1).mean()),
        "nll": float(-np.log(p_true).mean()),
        "confusion": conf.tolist(),
        "label_counts": np.bincount(labels, minlength=n_actions).tolist(),
    }
    cal = calibration_bins(probs, labels)
    out["ece"] = cal.pop("ece")
    out["reliability"] = cal
    if far_x is not None:
        fx = np.asarray(far_x, dtype=np.float64)
        ex = expected_x(probs, n_actions)
        ok = ~np.isnan(fx) & ~np.isnan(ex) & (labels != UNKNOWN)
        fe, flo, fhi = _mean_ci(np.abs(ex[ok] - fx[ok]))
        out.update({"far_x_error": fe, "far_x_error_ci95": [flo, fhi], "far_x_n": int(ok.sum())})
    return out
