"""Split-conformal action sets as a bundle defines them, and how well they cover labelled frames.

The set of a frame is ``{a : probs[a] >= calibration.conformal.threshold}`` (docs/contracts.md
section 3); :func:`conformal_report` measures coverage and set sizes on labelled frames, the
way ``crossing-eval --bundle`` and the export report them. numpy only.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from crossing_assist.bundle import Bundle, read_bundle


def conformal_sets(probs: np.ndarray, threshold: float) -> np.ndarray:
    """Boolean [N, A]: action ``a`` is in frame ``i``'s set when ``probs[i, a] >= threshold``."""
    return np.asarray(probs) >= threshold


def conformal_report(probs: np.ndarray, labels: np.ndarray, threshold: float) -> dict[str, Any]:
    """Empirical coverage and set sizes of the conformal sets on labelled frames.

    ``labels`` are action indices [N]. Returns ``coverage`` (fraction of frames whose set holds
    the true action), ``mean_size``, ``median_size``, ``empty`` (fraction of empty sets),
    ``size_hist`` (list: number of frames with set size 0..A) and ``n``.
    """
    sets = conformal_sets(probs, threshold)
    labels = np.asarray(labels, dtype=np.int64)
    if len(labels) != len(sets):
        raise ValueError(f"labels: {len(labels)} entries but probs has {len(sets)} rows")
    if len(labels) == 0:
        raise ValueError("conformal_report needs at least one labelled frame")
    sizes = sets.sum(1)
    return {
        "n": int(len(labels)),
        "threshold": float(threshold),
        "coverage": float(sets[np.arange(len(labels)), labels].mean()),
        "mean_size": float(sizes.mean()),
        "median_size": float(np.median(sizes)),
        "empty": float((sizes == 0).mean()),
        "size_hist": np.bincount(sizes, minlength=sets.shape[1] + 1).tolist(),
    }


def bundle_conformal_report(bundle_dir: str | os.PathLike | Bundle, probs: np.ndarray,
                            labels: np.ndarray) -> dict[str, Any]:
    """:func:`conformal_report` at the bundle's own threshold, with its target ``coverage`` and
    the calibration's size, for ``crossing-eval --bundle`` (``labels``: action indices [N])."""
    bundle = bundle_dir if isinstance(bundle_dir, Bundle) else read_bundle(bundle_dir, verify_hash=False)
    conf = bundle.calibration.conformal
    rep = conformal_report(probs, labels, conf.threshold)
    rep.update({"target_coverage": conf.coverage, "calibration_frames": conf.n_frames})
    return rep
