"""Frozen-backbone feature cache: compute once, train the head (and any unfrozen blocks) on it.

A cache entry is a folder ``<cache_dir>/<key>/`` holding ``feats.npy`` (float16,
M x C x h x w, the output of the backbone's frozen blocks), ``labels.npy`` (int64 bins 0..12),
``far_x.npy`` (float64, nan when unknown), ``window.npy`` (float32 M x 2, the frame's extent
on the canvas), ``row.npy`` (index of the dataset row each sample
came from), ``variant.npy`` (index into the variant list) and ``meta.json``. The key hashes
everything that changes the features: backbone name, weights source *and* file fingerprint,
number of frozen blocks, input size, mean/std, the variants (mirroring, yaw angles, field views, their seed and recipe, FOV), the fit and
the dataset rows (image paths, labels, flags, file sizes and mtimes). ``meta.json`` is written last
(atomically), so a half-written entry is never used. Processes sharing a cache take turns on
an entry (:func:`entry_lock`): the first computes it, the others wait and read it; a run first
builds the entries no other process is building (``wait=False``), then waits for the rest.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from ..data_tools.augment import field_recipe
from ..data_tools.manifest import Dataset
from ..fileio import sweep_orphans
from .backbones import Backbone
from .data import Variant, load_variants, normalise


@dataclass(frozen=True)
class FeatureSet:
    """Cached samples: ``feats`` M x C x h x w (float16, memory-mapped), ``labels`` (M,) bins,
    ``far_x`` (M,) in [0, 1] or nan, ``window`` (M, 2) content window, ``row`` (M,) dataset row index, ``variant`` (M,)."""

    feats: np.ndarray
    labels: np.ndarray
    far_x: np.ndarray
    window: np.ndarray
    row: np.ndarray
    variant: np.ndarray
    path: Path

    def __len__(self) -> int:
        return int(self.labels.shape[0])


def _dataset_fingerprint(ds: Dataset) -> str:
    h = hashlib.sha256()
    for r in ds.rows:
        p = ds.image_path(r)
        st = os.stat(p)
        # flags change the pixels (aspect=4:3 unsquashes) and field views' goals (far_y)
        h.update(f"{r.image}|{r.label}|{r.far_x}|{' '.join(r.flags)}|{st.st_size}|{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def cache_key(backbone: Backbone, frozen_blocks: int, size: tuple[int, int],
              variants: tuple[Variant, ...], fov_deg: float, ds: Dataset, fit: str = "stretch",
              seed: int = 0) -> str:
    """A hex digest naming the cache entry (see the module docstring for what it covers)."""
    f = backbone.facts
    spec = {
        "backbone": f.name, "weights": f.weights_source, "frozen_blocks": frozen_blocks,
        "weights_fingerprint": _weights_fingerprint(backbone, frozen_blocks),
        "size": list(size), "mean": list(f.mean), "std": list(f.std),
        "variants": [[v.mirrored, v.yaw_deg] for v in variants], "fov_deg": fov_deg,
        "data": _dataset_fingerprint(ds), "version": 1,
    }
    if fit != "stretch" or any(v.field >= 0 for v in variants):   # keys of older entries unchanged
        spec.update(fit=fit, fields=[v.field for v in variants], seed=seed, version=2)
    if fit == "letterbox":   # frames shown through the view crop since 2026-12-04: older entries did not
        spec["view_crop"] = True
    views = [v for v in variants if v.field >= 0]
    if views:
        spec["field_recipe"] = field_recipe(views[0].without, views[0].zoom)
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:24]


def _weights_fingerprint(backbone: Backbone, frozen_blocks: int) -> str:
    h = hashlib.sha256()
    for block in backbone.blocks[:frozen_blocks]:
        for t in block.state_dict().values():
            h.update(t.detach().cpu().numpy().tobytes()[:4096])
    return h.hexdigest()[:16]


def _open(path: Path) -> FeatureSet:
    load = lambda n, **kw: np.load(path / n, **kw)  # noqa: E731
    labels = load("labels.npy")
    window = (load("window.npy") if (path / "window.npy").is_file()
              else np.tile(np.asarray([[0.0, 1.0]], np.float32), (len(labels), 1)))
    return FeatureSet(load("feats.npy", mmap_mode="r"), labels, load("far_x.npy"), window,
                      load("row.npy"), load("variant.npy"), path)


@torch.no_grad()
def compute_features(backbone: Backbone, frozen_blocks: int, ds: Dataset, size: tuple[int, int],
                     variants: tuple[Variant, ...], fov_deg: float, cache_dir: Path,
                     batch_size: int = 32, progress: bool = True, desc: str = "features",
                     fit: str = "stretch", seed: int = 0, wait: bool = True) -> FeatureSet | None:
    """Features of blocks ``[0, frozen_blocks)`` for every row x variant, cached on disk.
    ``wait=False``: None at once, computing nothing, while another process computes the entry."""
    key = cache_key(backbone, frozen_blocks, size, variants, fov_deg, ds, fit, seed)
    path = Path(cache_dir) / key
    if (path / "meta.json").is_file():
        return _open(path)
    with entry_lock(cache_dir, key, wait=wait) as held:
        if not held:
            return None
        if (path / "meta.json").is_file():   # another process built it while this one waited
            return _open(path)
        sweep_orphans(cache_dir, prefix="")  # half-written entries of killed runs (<key>.tmp<pid>)
        tmp = Path(cache_dir) / f"{key}.tmp{os.getpid()}"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        try:
            return _compute(backbone, frozen_blocks, ds, size, variants, fov_deg, Path(cache_dir), batch_size,
                            progress, desc, key, tmp, path, fit, seed)
        finally:  # an error or Ctrl-C: no half-written entry stays behind (a finished one was moved)
            shutil.rmtree(tmp, ignore_errors=True)


@contextmanager
def entry_lock(cache_dir: str | os.PathLike, key: str, wait: bool = True):
    """Held while one process computes the entry ``key``: another process that needs the same
    entry (folds or runs started side by side on one cache) waits for it and then reads it,
    instead of computing it again. An advisory ``flock`` on ``<cache_dir>/<key>.lock``, released
    by the system if the holder dies, and removed by it once done (the cache holds only entries
    between runs: a process that opens a removed lock re-checks for the entry before computing).
    Yields whether it is held: ``wait=False`` yields False at once when another process holds it.
    Where ``fcntl`` is missing (Windows) nothing is locked."""
    try:
        import fcntl
    except ImportError:   # pragma: no cover - not POSIX
        yield True
        return
    Path(cache_dir).mkdir(parents=True, exist_ok=True)
    lock = Path(cache_dir) / f"{key}.lock"
    with open(lock, "a") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        try:
            yield True
        finally:
            lock.unlink(missing_ok=True)
            fcntl.flock(f, fcntl.LOCK_UN)


def _compute(backbone: Backbone, frozen_blocks: int, ds: Dataset, size: tuple[int, int],
             variants: tuple[Variant, ...], fov_deg: float, cache_dir: Path, batch_size: int, progress: bool,
             desc: str, key: str, tmp: Path, path: Path, fit: str, seed: int) -> FeatureSet:
    backbone.eval()
    n = len(ds.rows) * len(variants)
    probe = backbone.forward_until(torch.zeros(1, 3, *size), frozen_blocks)
    feats = np.lib.format.open_memmap(tmp / "feats.npy", mode="w+", dtype=np.float16,
                                      shape=(n, *probe.shape[1:]))
    base = _shallower(backbone, frozen_blocks, size, variants, fov_deg, ds, Path(cache_dir), fit, seed)
    if base is not None:  # run only blocks [k, frozen) on an existing shallower entry
        k, src = base
        for i in tqdm(range(0, n, batch_size), desc=f"{desc} (from block {k})", disable=not progress):
            x = torch.from_numpy(np.array(src.feats[i:i + batch_size])).float()
            feats[i:i + batch_size] = backbone.forward_from_to(x, k, frozen_blocks).numpy().astype(np.float16)
        for name in ("labels", "far_x", "window", "row", "variant"):
            np.save(tmp / f"{name}.npy", getattr(src, name))
        return _finish(feats, tmp, path, key, n, backbone, frozen_blocks, size, variants, ds)
    labels, far_x, windows, rows, vids = [], [], [], [], []
    buf: list[np.ndarray] = []
    done = 0

    def flush() -> None:
        nonlocal done
        x = torch.from_numpy(normalise(np.stack(buf), backbone.facts.mean, backbone.facts.std))
        out = backbone.forward_until(x, frozen_blocks)
        feats[done:done + len(buf)] = out.numpy().astype(np.float16)
        done += len(buf)
        buf.clear()

    for i, row in enumerate(tqdm(ds.rows, desc=desc, disable=not progress, unit="img")):
        for j, (img, fx, lab, win) in enumerate(load_variants(ds, row, size, variants, fov_deg, fit, seed)):
            buf.append(img)
            labels.append(lab)
            far_x.append(fx)
            windows.append(win)
            rows.append(i)
            vids.append(j)
            if len(buf) >= batch_size:
                flush()
    if buf:
        flush()
    np.save(tmp / "labels.npy", np.asarray(labels, np.int64))
    np.save(tmp / "far_x.npy", np.asarray(far_x, np.float64))
    np.save(tmp / "window.npy", np.asarray(windows, np.float32).reshape(-1, 2))
    np.save(tmp / "row.npy", np.asarray(rows, np.int64))
    np.save(tmp / "variant.npy", np.asarray(vids, np.int64))
    return _finish(feats, tmp, path, key, n, backbone, frozen_blocks, size, variants, ds)


def _shallower(backbone: Backbone, frozen_blocks: int, size: tuple[int, int], variants: tuple[Variant, ...],
               fov_deg: float, ds: Dataset, cache_dir: Path, fit: str = "stretch",
               seed: int = 0) -> tuple[int, FeatureSet] | None:
    """The deepest complete entry for the same frames and weights with fewer frozen blocks."""
    for k in range(frozen_blocks - 1, 0, -1):
        p = cache_dir / cache_key(backbone, k, size, variants, fov_deg, ds, fit, seed)
        if (p / "meta.json").is_file():
            return k, _open(p)
    return None


def _finish(feats: np.ndarray, tmp: Path, path: Path, key: str, n: int, backbone: Backbone,
            frozen_blocks: int, size: tuple[int, int], variants: tuple[Variant, ...], ds: Dataset) -> FeatureSet:
    """Flush the features, write meta.json last, move the entry into place atomically."""
    feats.flush()
    del feats
    meta = {"key": key, "n": n, "backbone": backbone.facts.name, "frozen_blocks": frozen_blocks,
            "size": list(size), "variants": [v.tag for v in variants], "root": str(ds.root)}
    (tmp / "meta.json").write_text(json.dumps(meta, indent=1))
    try:
        os.replace(tmp, path)
    except OSError:  # another process finished the same entry first
        shutil.rmtree(tmp, ignore_errors=True)
    return _open(path)
