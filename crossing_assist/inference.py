"""Running a bundle's graph: one torch-free module for the runtime, the export and evaluation.

numpy + onnxruntime only. :func:`open_session` reads and validates a bundle and opens its graph
(checked against the json by :func:`~crossing_assist.bundle.check_session`);
:func:`session_from_bytes` opens graph bytes in memory (the export measures the graph it is
about to write without writing it first); :func:`predict` runs frames of any sizes in batches;
:func:`check_frame` is the one frame rule (H x W x 3 uint8 RGB) the engine and the batch path share.
Every ``run`` draws fresh MC-dropout masks (docs/export.md, "Randomness under onnxruntime").
"""

from __future__ import annotations

import os
from typing import Any, Iterable, Sequence

import numpy as np

from crossing_assist.bundle import INPUT_NAME, OUTPUT_NAMES, Bundle, BundleError, check_session, read_bundle


def session_options(threads: int = 0, *, inter_threads: int = 0, quiet: bool = False) -> Any:
    """onnxruntime's default session options, with ``threads`` > 0 intra-op threads,
    ``inter_threads`` > 0 inter-op threads and, ``quiet``, warnings off."""
    import onnxruntime as ort

    opts = ort.SessionOptions()
    if threads > 0:
        opts.intra_op_num_threads = int(threads)
    if inter_threads > 0:
        opts.inter_op_num_threads = int(inter_threads)
    if quiet:
        opts.log_severity_level = 3
    return opts


def session_from_bytes(model: bytes, threads: int = 0, seed: int | None = None) -> Any:
    """An onnxruntime session (CPU) on serialised graph bytes, default options but ``threads``;
    ``seed`` as in :func:`open_session`."""
    import onnxruntime as ort

    if seed is not None:
        ort.set_seed(check_seed(seed))
    return ort.InferenceSession(model, sess_options=session_options(threads), providers=["CPUExecutionProvider"])


def open_session(bundle_dir: str | os.PathLike | Bundle, *, threads: int = 0, inter_threads: int = 0,
                 quiet: bool = False, seed: int | None = None) -> tuple[Bundle, Any]:
    """Read and validate a bundle and open its graph (CPU, :func:`session_options`). Raises
    BundleError (one line) when the bundle or its graph cannot be used or they disagree.
    ``seed``: seeds onnxruntime's random ops first (``onnxruntime.set_seed``, process-wide), so
    the session draws the same MC-dropout masks, run after run, as any session opened with that
    seed; None leaves the per-process seed (two processes then differ)."""
    import onnxruntime as ort

    bundle = bundle_dir if isinstance(bundle_dir, Bundle) else read_bundle(bundle_dir)
    if seed is not None:
        ort.set_seed(check_seed(seed))
    try:
        sess = ort.InferenceSession(str(bundle.model_path), providers=["CPUExecutionProvider"],
                                    sess_options=session_options(threads, inter_threads=inter_threads, quiet=quiet))
    except Exception as exc:  # onnxruntime raises its own exception types
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise BundleError(f"bundle: onnxruntime cannot open {bundle.model_path.name}: {first[:200]}; "
                          "re-export the bundle") from None
    check_session(bundle, sess)
    return bundle, sess


#: The seeds onnxruntime's ``set_seed`` takes.
SEED_RANGE = "an integer 0 .. 2**63 - 1"


def is_seed(seed: Any) -> bool:
    """Whether ``seed`` is in :data:`SEED_RANGE`."""
    return not isinstance(seed, bool) and isinstance(seed, (int, np.integer)) and 0 <= int(seed) < 2 ** 63


def check_seed(seed: Any) -> int:
    """``seed`` as an int in :data:`SEED_RANGE`, else ValueError."""
    if not is_seed(seed):
        raise ValueError(f"Invalid seed {seed!r}; valid: {SEED_RANGE}")
    return int(seed)


def check_frame(frame: Any, where: str = "frame") -> np.ndarray:
    """``frame`` as an H x W x 3 uint8 RGB array (C-contiguous), else ValueError naming ``where``."""
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"Invalid {where}: {type(frame).__name__}; expected a numpy array")
    if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3 or min(frame.shape[:2]) < 2:
        raise ValueError(f"Invalid {where}: shape {frame.shape} dtype {frame.dtype}; expected H x W x 3 uint8 RGB")
    return np.ascontiguousarray(frame)


def run(session: Any, frames: np.ndarray) -> dict[str, np.ndarray]:
    """One ``session.run`` on a batch N x H x W x 3 uint8: the graph's outputs by name."""
    return dict(zip(OUTPUT_NAMES, session.run(list(OUTPUT_NAMES), {INPUT_NAME: np.ascontiguousarray(frames)})))


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


def predict(session: Any, n_actions: int, images: Sequence[np.ndarray] | np.ndarray, *, batch: int = 16,
            progress: bool = False) -> dict[str, np.ndarray]:
    """Run ``images`` (H x W x 3 uint8 RGB arrays, any sizes, or one N x H x W x 3 array) through
    ``session``, a graph with ``n_actions`` actions.

    Returns float32 arrays in input order: ``probs`` [N, A], ``entropy`` [N], ``mutual_info`` [N],
    ``variance`` [N, A], ``votes`` [N, A] (docs/contracts.md section 3). Each call draws fresh
    dropout masks, so repeated calls differ by the MC noise.
    """
    from tqdm import tqdm

    n = len(images)
    if isinstance(images, np.ndarray) and images.ndim == 4:
        if images.dtype != np.uint8 or images.shape[-1] != 3:
            raise ValueError(f"images: expected N×H×W×3 uint8 RGB, got {images.dtype} {images.shape}")
    else:
        for i, img in enumerate(images):
            check_frame(np.asarray(img), f"image {i}")
    out = {k: np.zeros((n, n_actions) if k in ("probs", "variance", "votes") else (n,), np.float32)
           for k in OUTPUT_NAMES}
    with tqdm(total=n, disable=not progress, desc="bundle", unit="frame") as bar:
        for idx, frames in _batches(images, batch):
            for k, v in run(session, frames).items():
                out[k][idx] = v
            bar.update(len(idx))
    return out


def predict_bundle(bundle_dir: str | os.PathLike | Bundle, images: Sequence[np.ndarray] | np.ndarray, *,
                   batch: int = 16, progress: bool = False) -> dict[str, np.ndarray]:
    """:func:`predict` on a bundle folder (opened and checked with :func:`open_session`)."""
    bundle, sess = open_session(bundle_dir)
    return predict(sess, bundle.actions.n, images, batch=batch, progress=progress)
