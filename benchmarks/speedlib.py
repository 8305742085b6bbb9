"""Shared by the speed benchmarks (``int8_speed.py``, ``peer_speed.py``): one-thread sessions,
interleaved timing on the calling thread's CPU clock, onnxruntime's profiler by op type, and
the PTL frames split the way ``crossing-export --int8`` splits them.

Timing rule (the machine is shared): every model gets the same session options (1 intra-op
thread, 1 inter-op thread, sequential, full graph optimisation); each round runs every model
for a block of calls and measures ``time.thread_time`` (CPU time of this thread, which the
other load on the machine does not inflate the way it inflates wall time); the ratios are
medians of per-round ratios, so models compared share each round's conditions.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import onnxruntime as ort


def session(model: str | bytes, *, profile_prefix: str | None = None) -> ort.InferenceSession:
    """A CPU session with one thread (the options every model in a comparison gets)."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = 3
    if profile_prefix:
        so.enable_profiling = True
        so.profile_file_prefix = profile_prefix
    return ort.InferenceSession(model, so, providers=["CPUExecutionProvider"])


@dataclass
class Timed:
    name: str
    ms: list[float]          # per round: median CPU ms per call of the block


def interleaved(models: dict[str, tuple[ort.InferenceSession, dict[str, np.ndarray]]], *,
                rounds: int, block: int, warmup: int = 2) -> dict[str, Timed]:
    """Thread CPU time per call, rounds interleaved: model A block, model B block, ... per round."""
    for sess, feed in models.values():
        for _ in range(warmup):
            sess.run(None, feed)
    out = {name: Timed(name, []) for name in models}
    for _ in range(rounds):
        for name, (sess, feed) in models.items():
            calls = []
            for _ in range(block):
                t0 = time.thread_time()
                sess.run(None, feed)
                calls.append(time.thread_time() - t0)
            out[name].ms.append(float(np.median(calls)) * 1000)
    return out


def ratio(slow: Timed, fast: Timed) -> float:
    """Median over rounds of slow/fast (> 1: ``fast`` is faster)."""
    return float(np.median(np.asarray(slow.ms) / np.asarray(fast.ms)))


def profile_by_op(model: str | bytes, feed: dict[str, np.ndarray], runs: int = 20) -> tuple[dict[str, float], float]:
    """onnxruntime's profiler (``SessionOptions.enable_profiling``): kernel time per op type,
    ms per call (mean over ``runs``), and the total. The profiler times kernels by WALL clock,
    so on a loaded machine its absolute figures run well above the thread-CPU timings: read
    them as shares."""
    with tempfile.TemporaryDirectory(prefix="ort-profile-") as tmp:
        sess = session(model, profile_prefix=os.path.join(tmp, "p"))
        sess.run(None, feed)  # first call: allocations, not counted
        for _ in range(runs):
            sess.run(None, feed)
        events = json.loads(Path(sess.end_profiling()).read_text())
    runs_seen = 0
    by: dict[str, float] = collections.defaultdict(float)
    for e in events:
        if e.get("cat") == "Session" and e.get("name") == "model_run":
            runs_seen += 1
    # The first model_run (the warm-up) is dropped: keep the kernels after its end.
    first_end = min((e["ts"] + e["dur"] for e in events if e.get("name") == "model_run"), default=0)
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time") and e["ts"] >= first_end:
            by[e["args"].get("op_name", "?")] += e["dur"]
    n = max(runs_seen - 1, 1)
    per = {k: v / n / 1000 for k, v in sorted(by.items(), key=lambda kv: -kv[1])}
    return per, sum(per.values())


def print_profiles(profiles: dict[str, tuple[dict[str, float], float]], top: int = 14) -> None:
    """Side by side: op type -> ms per call and share, for each profiled model."""
    names = list(profiles)
    ops: list[str] = []
    for name in names:
        for op in profiles[name][0]:
            if op not in ops:
                ops.append(op)
    ops.sort(key=lambda op: -max(profiles[n][0].get(op, 0.0) for n in names))
    head = f"{'op type':<22}" + "".join(f"{n:>22}" for n in names)
    print(head)
    rest = {n: 0.0 for n in names}
    for i, op in enumerate(ops):
        if i >= top:
            for n in names:
                rest[n] += profiles[n][0].get(op, 0.0)
            continue
        cells = []
        for n in names:
            ms, total = profiles[n][0].get(op, 0.0), profiles[n][1]
            cells.append(f"{ms:8.2f} ms {100 * ms / total:4.0f} %    " if ms else f"{'-':>18}    ")
        print(f"{op:<22}" + "".join(f"{c:>22}" for c in cells))
    if len(ops) > top:
        print(f"{'(other ops)':<22}" + "".join(f"{rest[n]:8.2f} ms{'':>12}" for n in names))
    print(f"{'total kernel time':<22}" + "".join(f"{profiles[n][1]:8.2f} ms{'':>12}" for n in names))


def synthetic_frames(n: int, h: int, w: int, seed: int = 0) -> list[np.ndarray]:
    """Smooth random uint8 RGB frames (for timing; int8 ranges need a realistic spread)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        coarse = rng.integers(0, 256, (h // 16 + 1, w // 16 + 1, 3)).astype(np.float32)
        img = np.kron(coarse, np.ones((16, 16, 1)))[:h, :w] + rng.normal(0, 12, (h, w, 3))
        out.append(np.clip(img, 0, 255).astype(np.uint8))
    return out


@dataclass
class Frames:
    images: list[np.ndarray]
    labels: np.ndarray      # action index per frame
    sources: np.ndarray     # e.g. "ptl:john"


def load_split(data_dir: str, split: str, n_actions: int) -> Frames:
    """A dataset split (``manifest.csv``): raw RGB frames, action labels, sources (no torch)."""
    from crossing_assist.actions import get_space
    from crossing_assist.data_tools.images import load_frame
    from crossing_assist.data_tools.manifest import read_manifest

    try:
        ds = read_manifest(data_dir).split(split)
        if len(ds.rows) < 2:
            raise ValueError(f"{data_dir}: split {split!r} has {len(ds.rows)} frames; need >= 2")
        images = [load_frame(ds.image_path(r), r.flags) for r in ds.rows]
    except (OSError, ValueError) as exc:  # ManifestError is a ValueError
        raise SystemExit(f"error: {exc}") from None
    labels = get_space(n_actions).bins_to_actions(ds.labels())
    return Frames(images, np.asarray(labels), np.asarray([r.source for r in ds.rows]))


def int8_split(n: int, calib_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(calibration, unseen) indices, as ``crossing-export --int8`` picks them."""
    perm = np.random.default_rng(0).permutation(n)
    k = min(calib_frames, n // 2)
    return np.sort(perm[:k]), np.sort(perm[k:])


def predict(sess: ort.InferenceSession, images: Sequence[np.ndarray]) -> dict[str, np.ndarray]:
    """The bundle graph's outputs for each frame (one frame a call, any sizes)."""
    names = [o.name for o in sess.get_outputs()]
    rows = [sess.run(None, {"frames": np.ascontiguousarray(im[None])}) for im in images]
    return {k: np.concatenate([r[i] for r in rows]) for i, k in enumerate(names)}


def describe(sess: Any) -> str:
    return ", ".join(f"{i.name} {i.type} {i.shape}" for i in sess.get_inputs())


def parse_size(text: str) -> tuple[int, int]:
    """``640x480`` -> (640, 480) for ``--frame`` options (argparse type)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}; expected WIDTHxHEIGHT, e.g. 640x480") from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"{text!r}; each side 16..4096")
    return w, h
