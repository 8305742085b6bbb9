"""``crossing-data votes``: a dataset from a frames folder and people's votes.

Reads ``FRAMES_DIR/frames.csv`` (written by ``crossing-data frames``), the votes (CSV and/or
Label Studio JSON exports), takes the majority vote per frame (ties -> unknown, see
:mod:`votes`), splits by source without leakage, and writes ``FRAMES_DIR/manifest.csv`` and
``FRAMES_DIR/agreement.csv`` (``image,n_votes,label,agreement,tie``). Frames nobody voted on
are left out of the manifest and counted in the summary.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crossing_assist.actions import format_label
from crossing_assist.data_tools.frames import FRAMES_CSV
from crossing_assist.data_tools.manifest import Row, atomic_write_text, reading_csv, write_manifest
from crossing_assist.data_tools.splits import SplitConfig, assign_splits
from crossing_assist.data_tools.votes import (
    TIE_RULES, FrameIndex, VotesError, agreement_table, fleiss_kappa, majority, read_label_studio,
    read_votes_csv, tally,
)


@dataclass(frozen=True)
class VotesConfig:
    frames_dir: Path
    vote_files: tuple[Path, ...]
    tie: str = "unknown"
    min_votes: int = 1
    split: SplitConfig = SplitConfig(val=0.0, test=0.0)   # default: all train; split later by source


@dataclass(frozen=True)
class VotesSummary:
    manifest: Path
    frames_listed: int
    frames_voted: int
    frames_written: int
    votes: int
    ties: int
    too_few: int
    mean_agreement: float
    kappa: float

    def format(self) -> str:
        k = "undefined" if np.isnan(self.kappa) else f"{self.kappa:.3f}"
        return (f"{self.votes} votes on {self.frames_voted} of {self.frames_listed} frames; "
                f"{self.ties} ties, {self.too_few} below min-votes; mean agreement "
                f"{self.mean_agreement:.3f}, Fleiss' kappa {k}; wrote {self.frames_written} rows to {self.manifest}")


def read_frames_csv(frames_dir: Path) -> dict[str, tuple[str, tuple[str, ...]]]:
    """``{image: (source, flags)}`` from ``frames_dir/frames.csv``; flags ``fov=DEG`` when the
    file has the camera's FOV (``crossing-data frames --fov``)."""
    path = Path(frames_dir) / FRAMES_CSV
    if not path.is_file():
        raise VotesError(f"{path}: not found; run crossing-data frames first")
    with reading_csv(path, VotesError) as state, open(path, newline="", encoding="utf-8") as fh:
        reader = state["reader"] = csv.DictReader(fh)
        if not {"image", "source"} <= set(reader.fieldnames or []):
            raise VotesError(f"{path} line 1: header must have image,source")
        return {r["image"]: (r["source"], (f"fov={r['fov_deg']}",) if r.get("fov_deg") else ()) for r in reader}


def build_voted_dataset(cfg: VotesConfig) -> VotesSummary:
    """Majority-vote the frames of ``cfg.frames_dir`` and write its manifest."""
    if cfg.tie not in TIE_RULES:
        raise VotesError(f"Unknown tie rule: {cfg.tie!r}; valid: {', '.join(TIE_RULES)}")
    if not cfg.vote_files:
        raise VotesError("no vote files given")
    sources = read_frames_csv(cfg.frames_dir)
    index = FrameIndex(list(sources))
    raw = []
    for f in cfg.vote_files:
        f = Path(f)
        if not f.is_file():
            raise VotesError(f"{f}: not found")
        raw += read_label_studio(f, index) if f.suffix.lower() == ".json" else read_votes_csv(f, index)
    frames = tally(raw)
    rows, report, ties, too_few, agree = [], [], 0, 0, []
    for image in sources:               # frames.csv order
        fv = frames.get(image)
        if fv is None:
            continue
        d = majority(fv.counts)
        agree.append(d.agreement)
        report.append([image, d.n_votes, format_label(d.label), f"{d.agreement:.3f}", int(d.tie)])
        ties += d.tie
        if d.n_votes < cfg.min_votes:
            too_few += 1
            continue
        if d.tie and cfg.tie == "drop":
            continue
        source, flags = sources[image]
        rows.append(Row(image, d.label, None, source, "train", dict(fv.counts), (("tie",) if d.tie else ()) + flags))
    if not rows:
        raise VotesError("no frame has enough votes to be written")
    rows = assign_splits(rows, cfg.split) if (cfg.split.val or cfg.split.test) else rows
    path = write_manifest(cfg.frames_dir, rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["image", "n_votes", "label", "agreement", "tie"])
    w.writerows(report)
    atomic_write_text(Path(cfg.frames_dir) / "agreement.csv", buf.getvalue())
    return VotesSummary(path, len(sources), len(frames), len(rows), len(raw), ties, too_few,
                        float(np.mean(agree)), fleiss_kappa(agreement_table(frames)))
