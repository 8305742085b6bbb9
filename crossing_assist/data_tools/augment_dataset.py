"""``crossing-data augment``: a new dataset with mirrored and yawed copies of a dataset's frames.

The new folder holds every original row (images hard-linked, else copied, into
``images/``) plus, for the chosen splits (train by default), one mirrored copy and one copy
per yaw angle, with exact labels from :mod:`augment`. Augmented rows keep the original's
source and split (no leakage) and get the flags ``mirrored`` / ``yaw=+10.0``; pixels a yaw
could not see are black. Training can do the same on the fly with :func:`augment.mirror`
and :func:`augment.yaw`; this command is for inspecting them or for tools that cannot.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath

from tqdm import tqdm

from crossing_assist.actions import DEFAULT_FOV_DEG
from crossing_assist.data_tools.augment import OUT_OF_FRAME_MODES, mirror, yaw
from crossing_assist.data_tools.images import load_rgb, save_rgb
from crossing_assist.data_tools.manifest import (
    SPLITS,
    ManifestError,
    Row,
    read_manifest,
    write_manifest,
)
from crossing_assist.fileio import link_or_copy


@dataclass(frozen=True)
class AugmentConfig:
    dataset: Path
    out_dir: Path
    mirror: bool = True
    yaw_deg: tuple[float, ...] = ()
    fov_deg: float = DEFAULT_FOV_DEG
    out_of_frame: str = "unknown"
    splits: tuple[str, ...] = ("train",)
    drop_unknown_yaw: bool = False
    progress: bool = True




def _out_name(row: Row, index: int, tag: str) -> str:
    stem = PurePosixPath(row.image).stem
    return f"images/{index:06d}_{stem}{tag}.jpg" if tag else f"images/{index:06d}_{PurePosixPath(row.image).name}"


def augment_dataset(cfg: AugmentConfig) -> Path:
    """Write the augmented dataset to ``cfg.out_dir``; returns its manifest path."""
    if cfg.out_of_frame not in OUT_OF_FRAME_MODES:
        raise ManifestError(f"Unknown out_of_frame: {cfg.out_of_frame!r}; valid: {', '.join(OUT_OF_FRAME_MODES)}")
    bad = [s for s in cfg.splits if s not in SPLITS]
    if bad:
        raise ManifestError(f"Unknown split(s): {', '.join(bad)}; valid: {', '.join(SPLITS)}")
    if not cfg.mirror and not cfg.yaw_deg:
        raise ManifestError("nothing to do: give --yaw angles and/or leave mirroring on")
    src, out = Path(cfg.dataset).resolve(), Path(cfg.out_dir).resolve()
    if src == out:
        raise ManifestError(f"--out {cfg.out_dir} is the input dataset; choose a new folder")
    ds = read_manifest(src)
    rows: list[Row] = []
    for i, row in enumerate(tqdm(ds.rows, desc="augment", unit="img", disable=not cfg.progress)):
        orig = _out_name(row, i, "")
        link_or_copy(ds.image_path(row), out / orig)
        rows.append(replace(row, image=orig))
        if row.split not in cfg.splits:
            continue
        image = load_rgb(ds.image_path(row))
        if cfg.mirror:
            img, x, b = mirror(image, row.far_x, row.label)
            name = _out_name(row, i, "_m")
            save_rgb(out / name, img)
            rows.append(replace(row, image=name, label=b, far_x=x, votes={}, flags=row.flags + ("mirrored",)))
        for psi in cfg.yaw_deg:
            img, x, b, _valid = yaw(image, row.far_x, row.label, psi, cfg.fov_deg, cfg.out_of_frame)
            if b == 0 and row.label != 0 and cfg.drop_unknown_yaw:
                continue
            name = _out_name(row, i, f"_y{psi:+.1f}")
            save_rgb(out / name, img)
            rows.append(replace(row, image=name, label=b, far_x=x, votes={}, flags=row.flags + (f"yaw={psi:+.1f}",)))
    return write_manifest(out, rows)
