"""Negatives from labelled photos: views with no crossing in them, labelled ``unknown``.

PTL has no ``unknown`` frame, so a model trained on it alone has barely seen a scene without a
crossing. A photo whose far kerb is known (``far_y`` flag) yields a real street view with no
crossing: the part *above* the far kerb (buildings, sky, traffic lights, the far pavement), as
a phone tilted up would see it. Each crop keeps its photo's source and split (so held-out
figures stay leakage-free), is cut at a phone aspect (4:3 or 3:4) and written as its own image.
Label rules (docs/data.md): no crossing in view, or cannot tell -> ``unknown``.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from crossing_assist.actions import UNKNOWN
from crossing_assist.data_tools.images import flag_value, load_frame, save_rgb
from crossing_assist.data_tools.manifest import ManifestError, Row, read_manifest, write_manifest

MARGIN = 0.06        # crop this far (fraction of height) above the far kerb
MIN_HEIGHT = 0.25    # skip photos whose sky-side part is shorter than this


@dataclass(frozen=True)
class NegativesConfig:
    dataset: Path
    out: Path
    seed: int = 0
    progress: bool = True


def top_crop(image: np.ndarray, far_y: float, rng: np.random.Generator) -> np.ndarray | None:
    """A 4:3 or 3:4 window above the far kerb (``far_y - MARGIN``), or None if too short."""
    h, w = image.shape[:2]
    bottom = int((far_y - MARGIN) * h)
    if bottom < MIN_HEIGHT * h or bottom < 16:
        return None
    aspect = 4 / 3 if rng.random() < 0.5 else 3 / 4
    cw = min(w, int(round(bottom * aspect)))
    ch = min(bottom, int(round(cw / aspect)))
    x0 = int(rng.integers(0, w - cw + 1))
    return np.ascontiguousarray(image[bottom - ch:bottom, x0:x0 + cw])


def make_negatives(cfg: NegativesConfig) -> Path:
    """Write ``cfg.out`` (images + manifest.csv) with one unknown view per usable photo."""
    ds = read_manifest(cfg.dataset)
    out = Path(cfg.out)
    if out.resolve() == Path(cfg.dataset).resolve():
        raise ManifestError(f"--out {out} is the source dataset itself; choose another folder")
    if not any(flag_value(r.flags, "far_y") is not None and r.label != UNKNOWN for r in ds.rows):
        raise ManifestError(f"{cfg.dataset}: no row has a far_y flag and a known goal; nothing to crop "
                            "(import PTL with crossing-data import-ptl to get far_y)")
    rows: list[Row] = []
    for r in tqdm(ds.rows, desc="negatives", unit="img", disable=not cfg.progress):
        far_y = flag_value(r.flags, "far_y")
        if far_y is None or r.label == UNKNOWN:
            continue
        rng = np.random.default_rng([cfg.seed, zlib.crc32(r.image.encode())])
        crop = top_crop(load_frame(ds.image_path(r), r.flags), float(far_y), rng)
        if crop is None:
            continue
        stem = "_".join(p for p in Path(r.image).with_suffix("").parts if p not in ("..", ".", "/"))[-120:]
        name = Path("images") / f"{stem}_{zlib.crc32(r.image.encode()):08x}_top.jpg"
        save_rgb(out / name, crop)
        rows.append(Row(name.as_posix(), UNKNOWN, None, r.source, r.split, {}, ("negative=top",)))
    if not rows:
        raise ManifestError(f"{cfg.dataset}: no row has a far_y flag and a known goal; nothing to crop "
                            "(import PTL with crossing-data import-ptl to get far_y)")
    return write_manifest(out, rows)
