"""The dataset folder: ``manifest.csv`` plus images, read and written with validation.

A dataset is a folder holding ``manifest.csv`` and the images (paths relative to the folder).
Columns, in this order (a header line is required; extra columns are ignored on read):

``image``   POSIX path relative to the dataset folder (may start with ``../`` to reference
            images kept elsewhere; :func:`read_manifest` then checks that they exist)
``label``   ``1``..``12`` or ``unknown``
``far_x``   goal position in [0, 1] (fraction of width); empty when unknown or not measured
``source``  leakage unit (video / place / photographer), e.g. ``ptl:john``, ``vid:corner03``
``split``   ``train``, ``val`` or ``test``
``votes``   space-separated ``label:count``, e.g. ``6:3 7:1 unknown:1``; empty when not voted
``flags``   space-separated tokens, e.g. ``synthetic mirrored yaw=+10.0``

Consistency rules checked on read and write: an ``unknown`` label has no ``far_x``; when
``far_x`` is given the label is its strip ``floor(12 far_x) + 1`` (a tolerance of 1e-5 of
the width absorbs rounding at strip boundaries); image paths are unique.
"""

from __future__ import annotations

import csv
import io
import math
import os
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Iterable, Iterator

import numpy as np

from crossing_assist.actions import N_BINS, UNKNOWN, format_label, parse_label, x_to_bin
from crossing_assist.errors import UserError
from crossing_assist.fileio import atomic_write_bytes, atomic_write_text  # noqa: F401 (re-exported)

MANIFEST_NAME = "manifest.csv"
COLUMNS = ("image", "label", "far_x", "source", "split", "votes", "flags")
SPLITS = ("train", "val", "test")
BIN_TOLERANCE = 1e-5


MAX_PATH = 1024  # longest image path accepted (file systems stop at 4096, a name at 255)


def is_file(path: Path) -> bool:
    """``path.is_file()``, False (not an exception) for a name too long or otherwise unusable."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _bad_utf8_where(path: Path) -> str:
    """``PATH line N`` of the first byte that is not UTF-8 (the csv reader decodes in chunks)."""
    try:
        Path(path).read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1
        return f"{path} line {line}"
    except OSError:
        pass
    return str(path)


@contextmanager
def reading_csv(path: Path, error: type[Exception]) -> Iterator[dict]:
    """Turn what the csv module and the UTF-8 decoder raise inside the block into ``error``
    naming the file and line. The block sets ``state["reader"]`` to its csv reader."""
    state: dict = {}
    where = lambda: f"{path} line {state['reader'].line_num + 1}" if "reader" in state else str(path)  # noqa: E731
    try:
        yield state
    except UnicodeDecodeError as exc:
        raise error(f"{_bad_utf8_where(path)}: not UTF-8 text ({exc.reason}); save the file as UTF-8") from None
    except csv.Error as exc:
        raise error(f"{where()}: not a readable CSV ({exc})") from None


class ManifestError(UserError):
    """A manifest that cannot be trusted; the message names the file line or the row."""


@dataclass(frozen=True)
class Row:
    """One frame of a dataset.

    ``label`` is a bin 0..12 (0 = unknown); ``far_x`` a fraction of the width in [0, 1] or
    None; ``votes`` maps bins 0..12 to vote counts (empty when not voted); ``flags`` are
    whitespace-free tokens.
    """

    image: str
    label: int
    far_x: float | None
    source: str
    split: str
    votes: dict[int, int] = field(default_factory=dict)
    flags: tuple[str, ...] = ()


@dataclass(frozen=True)
class Dataset:
    """A dataset folder: ``root`` and its rows in manifest order."""

    root: Path
    rows: tuple[Row, ...]

    def __len__(self) -> int:
        return len(self.rows)

    def split(self, name: str) -> "Dataset":
        """The rows of one split (``train``, ``val`` or ``test``), same root."""
        if name not in SPLITS:
            raise ManifestError(f"Unknown split: {name!r}; valid: {', '.join(SPLITS)}")
        return Dataset(self.root, tuple(r for r in self.rows if r.split == name))

    def image_path(self, row: Row) -> Path:
        """Absolute-or-root-relative path of ``row``'s image file."""
        return self.root / row.image

    def labels(self) -> np.ndarray:
        """Bins of all rows, int64 array of shape (N,), values 0..12 (0 = unknown)."""
        return np.array([r.label for r in self.rows], dtype=np.int64)

    def far_x(self) -> np.ndarray:
        """Goal positions, float64 array of shape (N,), nan where not known."""
        return np.array([np.nan if r.far_x is None else r.far_x for r in self.rows], dtype=np.float64)

    def sources(self) -> tuple[str, ...]:
        """Distinct sources in order of first appearance."""
        return tuple(dict.fromkeys(r.source for r in self.rows))


# ---------------------------------------------------------------- field codecs


def parse_votes(text: str) -> dict[int, int]:
    """``"6:3 7:1 unknown:1"`` -> ``{6: 3, 7: 1, 0: 1}``; ValueError on bad tokens."""
    votes: dict[int, int] = {}
    for token in text.split():
        name, sep, count = token.rpartition(":")
        if not sep or not count.isdigit() or int(count) < 1:
            raise ValueError(f"vote {token!r} invalid; expected label:count, e.g. 6:3")
        b = parse_label(name)
        if b in votes:
            raise ValueError(f"vote for {format_label(b)!r} given twice")
        votes[b] = int(count)
    return votes


def format_votes(votes: dict[int, int]) -> str:
    """Inverse of :func:`parse_votes`, bins ascending with unknown last."""
    order = sorted(votes, key=lambda b: (b == UNKNOWN, b))
    return " ".join(f"{format_label(b)}:{int(votes[b])}" for b in order)


def _format_x(x: float | None) -> str:
    return "" if x is None else repr(float(x))


def _check_bin_value(b: object, what: str) -> None:
    if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 0 <= int(b) <= N_BINS:
        raise ValueError(f"{what} {b!r} invalid; expected an int bin 0..{N_BINS} (0 = unknown)")


def check_row(row: Row) -> None:
    """Raise ValueError (one line, no location) when ``row`` breaks the format's rules."""
    img = row.image
    if not img or "\\" in img or PurePosixPath(img).is_absolute() or img != img.strip():
        raise ValueError(f"image {img!r} invalid; expected a POSIX path relative to the dataset folder")
    if any(ord(c) < 32 for c in img) or len(img) > MAX_PATH:
        raise ValueError(f"image {img[:80]!r} invalid; a path without control characters, at most {MAX_PATH} "
                         "characters")
    _check_bin_value(row.label, "label")
    if not row.source or any(c.isspace() for c in row.source):
        raise ValueError(f"source {row.source!r} invalid; expected a non-empty id such as ptl:john")
    if row.split not in SPLITS:
        raise ValueError(f"split {row.split!r} invalid; valid: {', '.join(SPLITS)}")
    if row.far_x is not None:
        x = float(row.far_x)
        if math.isnan(x) or not 0.0 <= x <= 1.0:
            raise ValueError(f"far_x {row.far_x!r} invalid; valid: 0..1 (fraction of width) or empty")
        if row.label == UNKNOWN:
            raise ValueError(f"far_x {x} given for an unknown label; leave far_x empty")
        lo, hi = x_to_bin(max(0.0, x - BIN_TOLERANCE)), x_to_bin(min(1.0, x + BIN_TOLERANCE))
        if row.label not in (lo, hi):
            raise ValueError(f"label {row.label} disagrees with far_x {x} (strip {x_to_bin(x)})")
    for b, n in row.votes.items():
        _check_bin_value(b, "vote label")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"vote count {n!r} for {format_label(b)} invalid; expected an int >= 1")
    for flag in row.flags:
        if not flag or any(c.isspace() for c in flag):
            raise ValueError(f"flag {flag!r} invalid; flags are non-empty tokens without spaces")


def _parse_line(rec: dict[str, str]) -> Row:
    far = rec["far_x"].strip()
    try:
        far_x = float(far) if far else None
    except ValueError:
        raise ValueError(f"far_x {far!r} invalid; valid: 0..1 (fraction of width) or empty") from None
    try:
        label = parse_label(rec["label"])
    except ValueError:
        raise ValueError(f"label {rec['label']!r} invalid; valid: 1..{N_BINS} or unknown") from None
    row = Row(
        image=rec["image"].strip(),
        label=label,
        far_x=far_x,
        source=rec["source"].strip(),
        split=rec["split"].strip(),
        votes=parse_votes(rec["votes"] or ""),
        flags=tuple((rec["flags"] or "").split()),
    )
    check_row(row)
    return row


# ---------------------------------------------------------------- read / write


def read_manifest(dataset_dir: str | os.PathLike, *, check_images: bool = True) -> Dataset:
    """Read and validate ``dataset_dir/manifest.csv``.

    Raises ManifestError naming the first bad line (``manifest.csv line 17: ...``): a bad
    field, a duplicate image, or (with ``check_images``) an image file that is not there.
    """
    root = Path(dataset_dir)
    path = root / MANIFEST_NAME
    if not path.is_file():
        raise ManifestError(f"{path}: no manifest here; is {root} a dataset folder?")
    with reading_csv(path, ManifestError) as state, open(path, newline="", encoding="utf-8") as fh:
        reader = state["reader"] = csv.DictReader(fh)
        missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise ManifestError(f"{path} line 1: header lacks column(s) {', '.join(missing)}; "
                                f"expected {','.join(COLUMNS)}")
        rows: list[Row] = []
        seen: dict[str, int] = {}
        for rec in reader:
            line = reader.line_num
            if None in rec or any(rec[c] is None for c in COLUMNS):
                raise ManifestError(f"{path} line {line}: wrong number of fields; expected {len(COLUMNS)}")
            try:
                row = _parse_line(rec)
            except ValueError as exc:
                raise ManifestError(f"{path} line {line}: {exc}") from None
            if row.image in seen:
                raise ManifestError(f"{path} line {line}: duplicate image {row.image!r} "
                                    f"(first at line {seen[row.image]})")
            seen[row.image] = line
            if check_images and not is_file(root / row.image):
                raise ManifestError(f"{path} line {line}: image {row.image!r} not found "
                                    f"(looked at {(root / row.image).resolve()}); was the dataset "
                                    "or the folder it references moved?")
            rows.append(row)
    return Dataset(root, tuple(rows))


def write_manifest(dataset_dir: str | os.PathLike, rows: Iterable[Row]) -> Path:
    """Validate ``rows`` and write ``dataset_dir/manifest.csv`` atomically; returns its path.

    Raises ManifestError naming the first bad row (0-based index and image).
    """
    root = Path(dataset_dir)
    rows = list(rows)
    seen: dict[str, int] = {}
    for i, row in enumerate(rows):
        try:
            check_row(row)
        except ValueError as exc:
            raise ManifestError(f"row {i} ({row.image!r}): {exc}") from None
        if row.image in seen:
            raise ManifestError(f"row {i}: duplicate image {row.image!r} (first at row {seen[row.image]})")
        seen[row.image] = i
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(COLUMNS)
    for r in rows:
        writer.writerow([r.image, format_label(r.label), _format_x(r.far_x), r.source, r.split,
                         format_votes(r.votes), " ".join(r.flags)])
    root.mkdir(parents=True, exist_ok=True)
    path = root / MANIFEST_NAME
    atomic_write_text(path, buf.getvalue())
    return path


