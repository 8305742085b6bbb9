"""Run a bundle through onnxruntime (no torch) and report its conformal sets.

``predict_bundle`` is what ``crossing-eval --bundle`` calls: the same bundle, session options
and graph a user ships, so the metrics describe what runs on the device.
"""

from __future__ import annotations

import os
from typing import Any, Iterable, Sequence

import numpy as np
from tqdm import tqdm

from crossing_assist.bundle import OUTPUT_NAMES, Bundle, BundleError, check_session, read_bundle


def open_session(bundle_dir: str | os.PathLike | Bundle, *, threads: int = 0) -> tuple[Bundle, Any]:
    """Read and validate a bundle and open its model with onnxruntime's DEFAULT session options
    (``threads`` > 0 only sets the intra-op thread count). Raises BundleError on any mismatch."""
    import onnxruntime as ort

    bundle = bundle_dir if isinstance(bundle_dir, Bundle) else read_bundle(bundle_dir)
    opts = ort.SessionOptions()
    if threads > 0:
        opts.intra_op_num_threads = threads
    try:
        sess = ort.InferenceSession(str(bundle.model_path), sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own exception types
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise BundleError(f"bundle: onnxruntime cannot open {bundle.model_path.name}: {first[:200]}") from None
    check_session(bundle, sess)
    return bundle, sess


def _batches(images: Sequence[np.ndarray] | np.ndarray, batch: int) -> Iterable[tuple[np.ndarray, np.ndarray]]:
    """(indices, stacked frames) batches; frames of one batch share one shape."""
    if isinstance(images, np.ndarray) and images.ndim == 4:
        for i in range(0, len(images), batch):
            yield np.arange(i, min(i + batch, len(images))), images[i:i + batch]
        return
    by_shape: dict[tuple, list[int]] = {}
    for i, img in enumerate(images):
        by_shape.setdefault(np.shape(img), []).append(i)
    for idx in by_shape.values():
        for i in range(0, len(idx), batch):
            part = idx[i:i + batch]
            yield np.asarray(part), np.stack([images[j] for j in part])


def _check_frame(img: Any, i: int) -> None:
    a = np.asarray(img)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"image {i}: expected an H×W×3 uint8 RGB array, got {a.dtype} {a.shape}")


def predict_bundle(bundle_dir: str | os.PathLike | Bundle, images: Sequence[np.ndarray] | np.ndarray, *,
                   batch: int = 16, progress: bool = False, session: Any = None) -> dict[str, np.ndarray]:
    """Run ``images`` (H×W×3 uint8 RGB arrays, any sizes, or one N×H×W×3 array) through the bundle.

    Returns float32 arrays in input order: ``probs`` [N, A], ``entropy`` [N], ``mutual_info`` [N],
    ``variance`` [N, A], ``votes`` [N, A] (see docs/contracts.md section 3). Each call draws
    fresh dropout masks, so repeated calls differ by the MC noise. ``session`` reuses an
    ``open_session`` result's session.
    """
    bundle, sess = (bundle_dir, session) if session is not None else open_session(bundle_dir)
    n = len(images)
    if isinstance(images, np.ndarray) and images.ndim == 4:
        if images.dtype != np.uint8 or images.shape[-1] != 3:
            raise ValueError(f"images: expected N×H×W×3 uint8 RGB, got {images.dtype} {images.shape}")
    else:
        for i, img in enumerate(images):
            _check_frame(img, i)
    a = bundle.actions.n
    out = {k: np.zeros((n, a) if k in ("probs", "variance", "votes") else (n,), np.float32) for k in OUTPUT_NAMES}
    with tqdm(total=n, disable=not progress, desc="bundle", unit="frame") as bar:
        for idx, frames in _batches(images, batch):
            res = sess.run(list(OUTPUT_NAMES), {"frames": np.ascontiguousarray(frames)})
            for k, v in zip(OUTPUT_NAMES, res):
                out[k][idx] = v
            bar.update(len(idx))
    return out


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


def format_conformal_report(rep: dict[str, Any], target: float | None = None) -> str:
    """One line: coverage (vs target), mean set size, empty sets."""
    tgt = f" (target {target:.1%})" if target is not None else ""
    return (f"conformal sets (threshold {rep['threshold']:.4f}, n={rep['n']}): coverage {rep['coverage']:.1%}{tgt}, "
            f"mean size {rep['mean_size']:.2f}, median {rep['median_size']:.0f}, empty {rep['empty']:.1%}")


def bundle_conformal_report(bundle_dir: str | os.PathLike | Bundle, probs: np.ndarray,
                            labels: np.ndarray) -> dict[str, Any]:
    """:func:`conformal_report` at the bundle's own threshold, with its target ``coverage`` and
    the calibration's size, for ``crossing-eval --bundle`` (``labels``: action indices [N])."""
    bundle = bundle_dir if isinstance(bundle_dir, Bundle) else read_bundle(bundle_dir, verify_hash=False)
    conf = bundle.calibration.conformal
    rep = conformal_report(probs, labels, conf.threshold)
    rep.update({"target_coverage": conf.coverage, "calibration_frames": conf.n_frames})
    return rep
