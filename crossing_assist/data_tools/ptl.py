"""Import a folder in the PTL layout (``labels.csv`` + images) as a dataset.

PTL layout (as in ``../shared/data/ptl``): ``labels.csv`` with at least the columns
``image`` (path relative to the PTL folder), ``split``, ``photographer``, ``far_x`` and
``bin12``; ``blocked`` and ``light`` are optional and become flags. The label is the file's
``bin12`` (checked against ``far_x``); the source is ``ptl:<photographer>``; PTL's own split
is kept. A photo whose EXIF gives its camera's 35 mm-equivalent focal length (phones write it)
gets its horizontal FOV as an ``fov=DEG`` flag (:func:`crossing_assist.data_tools.exif.photo_fov`),
which evaluation plays it at; PTL's own copies carry no EXIF.

Images are either copied into ``<out>/images/`` (``mode="copy"``: a hard link where the file
system allows, else a byte copy; the dataset is self-contained and may be moved) or
referenced in place (``mode="reference"``: the manifest stores paths relative to the
dataset folder, e.g. ``../ptl/images/x.jpg``; nothing is copied, and reading the manifest
fails with a clear error naming the line if the dataset or the PTL folder is moved).
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath

from tqdm import tqdm

from crossing_assist.actions import parse_label
from crossing_assist.data_tools.exif import photo_fov
from crossing_assist.data_tools.images import inspect_image_file
from crossing_assist.data_tools.manifest import SPLITS, Row, check_row, is_file, reading_csv, write_manifest
from crossing_assist.errors import UserError
from crossing_assist.fileio import link_or_copy

REQUIRED = ("image", "split", "photographer", "far_x", "bin12")
IMAGE_MODES = ("copy", "reference")
#: What a square image file is: PTL's squashed 4:3 copy (``squashed``, default) or a photo taken square.
SQUARE_MODES = ("squashed", "square")
#: PTL's files are 224x224 copies of 4:3 photos squashed without a crop: ``aspect=4:3`` on a
#: square file tells readers (:func:`crossing_assist.data_tools.images.load_frame`) to undo the
#: squash. A file that is not square (a photo as the phone saved it, portrait or landscape)
#: already has its camera's aspect and gets no flag: stretching a portrait photo to 4:3 would
#: show the model a frame no camera took.
PTL_ASPECT = "4:3"
LIGHTS = {"0": "red", "1": "green", "2": "countdown_green", "3": "countdown_blank", "4": "none"}


class PTLError(UserError):
    """A PTL folder that cannot be imported; names the labels.csv line."""


@dataclass(frozen=True)
class PTLImportConfig:
    ptl_dir: Path
    out_dir: Path
    images: str = "copy"          # "copy" or "reference"
    progress: bool = True
    square: str = "squashed"      # a square file: PTL's 4:3 photo squashed ("squashed") or taken square
    exif_fov: bool = True         # a photo's camera FOV from its EXIF focal length (flag fov=DEG)


def _row_from_record(rec: dict[str, str]) -> tuple[Row, str]:
    """(manifest row with the PTL-relative image path, that path); ValueError on bad fields."""
    image = (rec["image"] or "").strip()
    if not image or PurePosixPath(image).is_absolute() or ".." in PurePosixPath(image).parts:
        raise ValueError(f"image {image!r} invalid; expected a path inside the PTL folder")
    split = (rec["split"] or "").strip()
    if split not in SPLITS:
        raise ValueError(f"split {split!r} invalid; valid: {', '.join(SPLITS)}")
    who = (rec["photographer"] or "").strip().replace(" ", "_") or "unnamed"
    try:
        far_x = float(rec["far_x"]) if (rec["far_x"] or "").strip() else None
    except ValueError:
        raise ValueError(f"far_x {rec['far_x']!r} invalid; expected a number in 0..1") from None
    try:
        label = parse_label(rec["bin12"] or "")
    except ValueError:
        raise ValueError(f"bin12 {rec['bin12']!r} invalid; valid: 1..12 or unknown") from None
    flags = []
    far_y = (rec.get("far_y") or "").strip()
    if far_y:
        try:
            flags.append(f"far_y={min(max(float(far_y), 0.0), 1.0):.4f}")
        except ValueError:
            raise ValueError(f"far_y {rec['far_y']!r} invalid; expected a number in 0..1") from None
    if (rec.get("blocked") or "").strip() == "1":
        flags.append("blocked")
    light = (rec.get("light") or "").strip()
    if light:
        flags.append(f"light={LIGHTS.get(light, light)}")
    row = Row(image, label, far_x, f"ptl:{who}", split, {}, tuple(flags))
    check_row(row)
    return row, image


def read_ptl_labels(ptl_dir: Path, square: str = "squashed", exif_fov: bool = True) -> list[Row]:
    """Rows of ``ptl_dir/labels.csv`` with image paths relative to ``ptl_dir`` (checked to exist
    and whole); a square file gets ``aspect=4:3`` unless ``square`` is ``"square"``; with
    ``exif_fov`` a photo whose EXIF gives its camera's FOV gets ``fov=DEG``."""
    if square not in SQUARE_MODES:
        raise PTLError(f"Unknown square mode: {square!r}; valid: {', '.join(SQUARE_MODES)}")
    path = Path(ptl_dir) / "labels.csv"
    if not path.is_file():
        raise PTLError(f"{path}: not found; a PTL folder holds labels.csv and the images")
    rows: list[Row] = []
    with reading_csv(path, PTLError) as state, open(path, newline="", encoding="utf-8") as fh:
        reader = state["reader"] = csv.DictReader(fh)
        missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
        if missing:
            raise PTLError(f"{path} line 1: header lacks column(s) {', '.join(missing)}")
        seen: dict[str, int] = {}
        for rec in reader:
            line = reader.line_num
            if None in rec or any(rec[c] is None for c in REQUIRED):
                raise PTLError(f"{path} line {line}: wrong number of fields")
            try:
                row, image = _row_from_record(rec)
            except ValueError as exc:
                raise PTLError(f"{path} line {line}: {exc}") from None
            if image in seen:
                raise PTLError(f"{path} line {line}: duplicate image {image!r} (first at line {seen[image]})")
            seen[image] = line
            if not is_file(Path(ptl_dir) / image):
                raise PTLError(f"{path} line {line}: image {image!r} not found in {ptl_dir}")
            bad, size = inspect_image_file(Path(ptl_dir) / image)
            if bad:
                raise PTLError(f"{path} line {line}: image {image!r} {bad}; replace or remove it")
            squashed = square == "squashed" and size[0] == size[1]
            if squashed:
                row = replace(row, flags=(f"aspect={PTL_ASPECT}", *row.flags))
            fov = photo_fov(Path(ptl_dir) / image, size, 4 / 3 if squashed else None) if exif_fov else None
            if fov is not None:
                row = replace(row, flags=(*row.flags, f"fov={fov:.1f}"))
            rows.append(row)
    if not rows:
        raise PTLError(f"{path}: no rows")
    return rows




def import_ptl(cfg: PTLImportConfig) -> Path:
    """Import ``cfg.ptl_dir`` into the dataset folder ``cfg.out_dir``; returns the manifest path."""
    if cfg.images not in IMAGE_MODES:
        raise PTLError(f"Unknown images mode: {cfg.images!r}; valid: {', '.join(IMAGE_MODES)}")
    ptl = Path(cfg.ptl_dir).resolve()
    out = Path(cfg.out_dir).resolve()
    if out == ptl:
        raise PTLError(f"--out {cfg.out_dir} is the PTL folder itself; choose another folder")
    rows = read_ptl_labels(ptl, cfg.square, cfg.exif_fov)
    out.mkdir(parents=True, exist_ok=True)
    placed: list[Row] = []
    for row in tqdm(rows, desc="import-ptl", unit="img", disable=not cfg.progress):
        src = ptl / row.image
        if cfg.images == "copy":
            rel = PurePosixPath(row.image)
            rel = rel if rel.parts[0] == "images" else PurePosixPath("images", rel)
            link_or_copy(src, out / rel)
        else:
            rel = PurePosixPath(Path(os.path.relpath(src, out)).as_posix())
        placed.append(Row(str(rel), row.label, row.far_x, row.source, row.split, row.votes, row.flags))
    return write_manifest(out, placed)
