"""Epoch time with cached frozen-backbone features vs recomputing them, same data, one run.

    .venv/bin/python benchmarks/train_cache.py [--data DIR] [--images 64] [--backbone efficientnet_lite0]

DIR is a dataset folder (manifest.csv); without it (or when it is missing) synthetic frames
are used. Both epochs run the same head training steps (spatial head, batch 16, mirrored
frames); the recomputing epoch also decodes, resizes, normalises and runs the frozen
backbone for every sample, as training without the cache would. Prints both times and the
ratio (the cached epoch must be >= 10x faster).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from crossing_assist.actions import DEFAULT_FOV_DEG
from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import Dataset, Row, read_manifest, write_manifest
from crossing_assist.models.backbones import create_backbone
from crossing_assist.models.cache import compute_features
from crossing_assist.models.data import load_variants, make_variants, normalise
from crossing_assist.models.heads import create_head


def synthetic(root: Path, n: int, rng: np.random.Generator) -> Dataset:
    rows = []
    for i in range(n):
        save_rgb(root / f"{i}.jpg", rng.integers(0, 255, (224, 224, 3), dtype=np.uint8))
        rows.append(Row(f"{i}.jpg", int(rng.integers(1, 13)), None, "synth", "train"))
    write_manifest(root, rows)
    return read_manifest(root)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="runs/data/ptl")
    ap.add_argument("--images", type=int, default=64)
    ap.add_argument("--backbone", default="efficientnet_lite0")
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    tmp = Path(tempfile.mkdtemp(prefix="train_cache_"))
    rng = np.random.default_rng(0)
    if (Path(a.data) / "manifest.csv").is_file():
        full = read_manifest(a.data).split("train")
        ds = Dataset(full.root, full.rows[: a.images])
        what = f"{len(ds)} frames of {a.data}"
    else:
        ds = synthetic(tmp / "data", a.images, rng)
        what = f"{len(ds)} synthetic frames"
    bb = create_backbone(a.backbone, weights="none" if a.backbone != "efficientnet_lite0" else "imagenet").eval()
    bb.requires_grad_(False)
    size, variants, nb = bb.facts.input_size, make_variants(True), len(bb.blocks)
    head = create_head("spatial", bb.num_features, 13)
    opt = torch.optim.RMSprop(head.parameters(), lr=2e-4, alpha=0.9, eps=1e-8)

    def step(feats: torch.Tensor, y: torch.Tensor) -> None:
        loss = F.cross_entropy(head(feats, mc=True)[0], y)
        opt.zero_grad()
        loss.backward()
        opt.step()

    t0 = time.perf_counter()
    fs = compute_features(bb, nb, ds, size, variants, DEFAULT_FOV_DEG, tmp / "cache", progress=False)
    t_build = time.perf_counter() - t0
    feats, labels = torch.from_numpy(np.array(fs.feats)), torch.from_numpy(fs.labels)
    order = rng.permutation(len(labels))
    batches = [order[i:i + 16] for i in range(0, len(order), 16)]

    def cached_epoch() -> None:
        for idx in batches:
            step(feats[idx].float(), labels[idx])

    def recompute_epoch() -> None:
        for idx in batches:
            imgs, ys = [], []
            for k in idx:
                img, _, lab, _ = load_variants(ds, ds.rows[fs.row[k]], size, (variants[fs.variant[k]],), DEFAULT_FOV_DEG)[0]
                imgs.append(img)
                ys.append(lab)
            with torch.no_grad():
                f = bb.forward_features(torch.from_numpy(normalise(np.stack(imgs), bb.facts.mean, bb.facts.std)))
            step(f, torch.tensor(ys))

    cached_epoch()                      # warm-up (allocator, kernels), not timed
    t0 = time.perf_counter()
    cached_epoch()
    t_cached = time.perf_counter() - t0
    t0 = time.perf_counter()
    recompute_epoch()
    t_recompute = time.perf_counter() - t0

    print(f"{what} x {len(variants)} variants = {len(labels)} samples, {a.backbone}, {a.threads} threads")
    print(f"building the cache once: {t_build:.2f} s")
    print(f"epoch with cached features: {t_cached:.3f} s")
    print(f"epoch recomputing features: {t_recompute:.3f} s")
    print(f"ratio: {t_recompute / t_cached:.1f}x faster with the cache")
    return 0


if __name__ == "__main__":
    sys.exit(main())
