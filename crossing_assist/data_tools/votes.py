"""Labels from people: votes from a CSV or a Label Studio export, majority vote, agreement.

Vote sources
    * CSV with a header ``frame,annotator,label`` (``bin`` is accepted for ``label``): ``frame``
      is the image path relative to the frames folder, or just its file name when that is
      unique; ``label`` is ``1``..``12`` or ``unknown``. A ``0`` is refused (in the manifest
      0 means unknown, but in people's votes it is a typo or strips numbered 0..11). Files
      saved by spreadsheets are read as they are: UTF-8 with a byte-order mark, CRLF line
      ends, semicolon- or tab-separated (the header decides).
    * Label Studio JSON export (``Export -> JSON``): a list of tasks, each with
      ``data.image`` and ``annotations[].result[]`` holding a ``choices`` result (the shipped
      config, :data:`LABEL_STUDIO_CONFIG`, names it ``strip``). The annotator is
      ``completed_by`` (its ``email`` when given as an object); cancelled annotations are
      skipped. Image URLs are matched by the path after ``?d=`` (local files), else by the file
      name with Label Studio's upload prefix (``8f3a2b1c-``) removed.

Majority vote and tie rule
    The label with the most votes wins. When two or more labels share the top count the
    frame gets ``unknown`` and the flag ``tie`` (with ``tie="drop"`` it is left out): a
    direction nobody agreed on must not be taught as the truth. One vote per annotator and
    frame: a second vote is an error (the line is named), not a silent overwrite.

Agreement
    Per frame: the winner's share of the votes. Overall: Fleiss' kappa over the frames with at
    least two votes (the general form that allows a varying number of raters per frame).
"""

from __future__ import annotations

import csv
import json
import re
import urllib.parse
from collections import Counter
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from crossing_assist.actions import N_BINS, UNKNOWN, format_label, parse_label
from crossing_assist.data_tools.manifest import reading_csv
from crossing_assist.errors import UserError, short_repr

TIE_RULES = ("unknown", "drop")
_UPLOAD_PREFIX = re.compile(r"^[0-9a-f]{8}-")


class VotesError(UserError):
    """Votes that cannot be used; names the file and line (or task)."""


def _choices_xml() -> str:
    names = [str(b) for b in range(1, N_BINS + 1)] + ["unknown"]
    return "\n".join(f'    <Choice value="{n}"/>' for n in names)


LABEL_STUDIO_CONFIG = f"""<View>
  <Header value="Where is the far end of the crossing? Pick the strip (1 = far left ... 12 = far right), or unknown."/>
  <Image name="image" value="$image" zoom="true"/>
  <Choices name="strip" toName="image" choice="single-radio" showInline="true" required="true">
{_choices_xml()}
  </Choices>
</View>
"""


@dataclass(frozen=True)
class FrameVotes:
    """Votes for one frame: ``counts[b]`` votes for bin b (0 = unknown) and who cast them."""

    frame: str
    counts: dict[int, int]
    annotators: tuple[str, ...]


@dataclass(frozen=True)
class Decision:
    """Majority vote of one frame: ``label`` (0..12), whether it was a tie, the winner's share."""

    label: int
    tie: bool
    agreement: float
    n_votes: int


class FrameIndex:
    """Resolves frame references (relative path or unique file name) to frames.csv paths."""

    def __init__(self, frames: list[str]):
        self.frames = set(frames)
        names = Counter(PurePosixPath(f).name for f in frames)
        self.by_name = {PurePosixPath(f).name: f for f in frames if names[PurePosixPath(f).name] == 1}

    def resolve(self, ref: str) -> str | None:
        ref = ref.strip().replace("\\", "/")
        if ref in self.frames:
            return ref
        for f in self.frames:       # a longer path that ends with a known frame path
            if ref.endswith("/" + f):
                return f
        return self.by_name.get(PurePosixPath(ref).name)


_DELIMITERS = (",", ";", "\t")     # comma; semicolon (Excel in comma-decimal locales); tab
_ZERO_HINT = "write unknown (or leave the frame out) for no crossing; strips are 1..12"


def _header_delimiter(first_line: str) -> str:
    """The delimiter that makes ``first_line`` a votes header (comma when none does)."""
    for d in _DELIMITERS:
        names = set(next(csv.reader([first_line], delimiter=d), []))
        if {"frame", "annotator"} <= names and names & {"label", "bin"}:
            return d
    return ","


def _is_zero(value: str | None) -> bool:
    """``"0"``, ``"00"``...: a digit string :func:`parse_label` would read as unknown."""
    s = (value or "").strip()
    return bool(s) and set(s) == {"0"}


def _is_twelve(value: str | None) -> bool:
    return (value or "").strip().lstrip("0") == "12"


def read_votes_csv(path: Path, index: FrameIndex) -> list[tuple[str, str, int, str]]:
    """Votes ``(frame, annotator, bin, where)`` from a CSV; VotesError names the bad line.

    Accepts what spreadsheets save: a UTF-8 byte-order mark (Excel's "CSV UTF-8"), CRLF line
    ends, and semicolon- or tab-separated files (the header decides). A label ``0`` is refused,
    not read as unknown: in people's votes it is a typo or strips numbered 0..11.
    """
    path = Path(path)
    with open(path, "rb") as fh:
        if fh.read(2) in (b"\xff\xfe", b"\xfe\xff"):
            raise VotesError(f"{path}: saved as UTF-16 (Excel 'Unicode Text'); save it as 'CSV UTF-8' instead")
    with reading_csv(path, VotesError) as state, open(path, newline="", encoding="utf-8-sig") as fh:
        delimiter = _header_delimiter(fh.readline())
        fh.seek(0)
        reader = state["reader"] = csv.DictReader(fh, delimiter=delimiter)
        fields = reader.fieldnames or []
        col = "label" if "label" in fields else "bin" if "bin" in fields else None
        if "frame" not in fields or "annotator" not in fields or col is None:
            raise VotesError(f"{path} line 1: header must have frame,annotator,label "
                             f"(got {','.join(fields)[:120]!r})")
        records = [(reader.line_num, rec) for rec in reader]
    zeros = sum(_is_zero(rec.get(col)) for _, rec in records)
    numbering = ""
    if zeros and not any(_is_twelve(rec.get(col)) for _, rec in records):
        numbering = (f" (this file has {zeros} label{'s' if zeros > 1 else ''} 0 and none 12: "
                     "if its strips are numbered 0..11, add 1 to every label)")
    votes = []
    for line, rec in records:
        where = f"{path} line {line}"
        if None in rec or any(rec[c] is None for c in ("frame", "annotator", col)):
            raise VotesError(f"{where}: wrong number of fields")
        frame = index.resolve(rec["frame"])
        if frame is None:
            raise VotesError(f"{where}: frame {rec['frame']!r} is not in frames.csv")
        if _is_zero(rec[col]):
            raise VotesError(f"{where}: label {short_repr(rec[col].strip(), 40)} refused: {_ZERO_HINT}{numbering}")
        try:
            b = parse_label(rec[col])
        except ValueError:
            raise VotesError(f"{where}: label {rec[col]!r} invalid; valid: 1..12 or unknown") from None
        who = rec["annotator"].strip()
        if not who:
            raise VotesError(f"{where}: annotator is empty")
        votes.append((frame, who, b, where))
    return votes


def _ls_image_ref(url: str) -> str:
    if "?d=" in url:
        return urllib.parse.unquote(url.split("?d=", 1)[1])
    name = PurePosixPath(urllib.parse.urlparse(url).path).name
    return _UPLOAD_PREFIX.sub("", urllib.parse.unquote(name))


def _ls_annotator(ann: dict, where: str, k: int, j: int) -> str:
    """``ls:<email or id>``; an annotation without ``completed_by`` counts as its own annotator."""
    who = ann.get("completed_by")
    if isinstance(who, dict):
        who = who.get("email", who.get("id"))
    if who is None or who == "":
        return f"ls:anonymous-annotation-{ann.get('id', f'{k}.{j}')}"
    if isinstance(who, bool) or not isinstance(who, (int, str)):
        raise VotesError(f"{where}: annotation {ann.get('id', j)!r} completed_by {who!r} invalid; "
                         "expected a user id or email")
    return f"ls:{who}"


def _ls_list(value: Any, what: str, where: str) -> list:
    if value is None:
        return []
    if not isinstance(value, list):
        raise VotesError(f"{where}: {what} is a {type(value).__name__}; expected a list (Label Studio 'JSON' export)")
    return value


def _ls_choices(ann: dict, where: str) -> list:
    choices = []
    for r in _ls_list(ann.get("result"), "annotation result", where):
        if not isinstance(r, dict) or r.get("type") != "choices":
            continue
        value = r.get("value")
        if not isinstance(value, dict):
            raise VotesError(f"{where}: result value is a {type(value).__name__}; expected an object")
        choices += _ls_list(value.get("choices"), "value.choices", where)
    return choices


def read_label_studio(path: Path, index: FrameIndex, *, image_key: str = "image") -> list[tuple[str, str, int, str]]:
    """Votes ``(frame, annotator, bin, where)`` from a Label Studio JSON export."""
    path = Path(path)
    try:
        tasks = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise VotesError(f"{path}: not UTF-8 text ({exc.reason}); export it again from Label Studio") from None
    except json.JSONDecodeError as exc:
        raise VotesError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except (ValueError, RecursionError) as exc:  # an int over the digit limit, absurd nesting
        raise VotesError(f"{path}: not a usable JSON export ({type(exc).__name__})") from None
    if not isinstance(tasks, list):
        raise VotesError(f"{path}: expected a list of tasks (Label Studio 'JSON' export)")
    votes = []
    for k, task in enumerate(tasks):
        tid = task.get("id", "?") if isinstance(task, dict) else "?"
        where = f"{path} task {k} (id {short_repr(tid, 40) if isinstance(tid, (int, str)) and not isinstance(tid, bool) else '?'})"
        data = task.get("data") if isinstance(task, dict) else None
        url = data.get(image_key) if isinstance(data, dict) else None
        if not isinstance(url, str):
            raise VotesError(f"{where}: no data.{image_key}")
        frame = index.resolve(_ls_image_ref(url))
        if frame is None:
            raise VotesError(f"{where}: image {url[:200]!r} is not in frames.csv")
        for j, ann in enumerate(_ls_list(task.get("annotations"), "annotations", where)):
            if not isinstance(ann, dict):
                raise VotesError(f"{where}: annotation {j} is a {type(ann).__name__}; expected an object")
            if ann.get("was_cancelled"):
                continue
            who = _ls_annotator(ann, where, k, j)
            choices = _ls_choices(ann, where)
            if len(choices) != 1 or isinstance(choices[0], bool) or not isinstance(choices[0], (str, int)):
                raise VotesError(f"{where}: annotation {ann.get('id', j)!r} has {len(choices)} choices; "
                                 "expected 1 (a strip 1..12 or unknown)")
            if _is_zero(str(choices[0])):
                raise VotesError(f"{where}: choice {str(choices[0])[:40]!r} refused: {_ZERO_HINT}")
            try:
                b = parse_label(choices[0])
            except ValueError:
                raise VotesError(f"{where}: choice {str(choices[0])[:40]!r} invalid; valid: 1..12 or unknown") from None
            votes.append((frame, who, b, where))
    return votes


def tally(votes: list[tuple[str, str, int, str]]) -> dict[str, FrameVotes]:
    """Group votes by frame; VotesError when an annotator voted twice for one frame."""
    seen: dict[tuple[str, str], str] = {}
    counts: dict[str, Counter] = {}
    who: dict[str, list[str]] = {}
    for frame, annotator, b, where in votes:
        if (frame, annotator) in seen:
            raise VotesError(f"{where}: annotator {annotator!r} already voted for {frame!r} "
                             f"({seen[(frame, annotator)]})")
        seen[(frame, annotator)] = where
        counts.setdefault(frame, Counter())[b] += 1
        who.setdefault(frame, []).append(annotator)
    return {f: FrameVotes(f, dict(c), tuple(who[f])) for f, c in counts.items()}


def majority(counts: dict[int, int]) -> Decision:
    """The most-voted label; a shared top count is a tie and gives unknown (see module doc)."""
    n = sum(counts.values())
    if n == 0:
        raise ValueError("no votes")
    top = max(counts.values())
    winners = [b for b, c in counts.items() if c == top]
    tie = len(winners) > 1
    return Decision(UNKNOWN if tie else winners[0], tie, top / n, n)


def fleiss_kappa(table: np.ndarray) -> float:
    """Fleiss' kappa of an items × categories count table (rows may have different totals).

    Rows with fewer than two ratings are ignored; nan when undefined (fewer than one such
    row, or every rating in one category).
    """
    table = np.asarray(table, dtype=np.float64)
    n = table.sum(axis=1)
    table, n = table[n >= 2], n[n >= 2]
    if len(table) == 0:
        return float("nan")
    p_item = ((table ** 2).sum(axis=1) - n) / (n * (n - 1))
    p_cat = table.sum(axis=0) / n.sum()
    p_bar, p_e = p_item.mean(), (p_cat ** 2).sum()
    return float("nan") if p_e >= 1.0 else float((p_bar - p_e) / (1.0 - p_e))


def agreement_table(frames: dict[str, FrameVotes]) -> np.ndarray:
    """Items × 13 vote counts (bins 0..12) in the order of ``frames``."""
    table = np.zeros((len(frames), N_BINS + 1), dtype=np.int64)
    for i, fv in enumerate(frames.values()):
        for b, c in fv.counts.items():
            table[i, b] = c
    return table


def describe(decision: Decision) -> str:
    """``'7 (3/4 = 0.75)'`` or ``'unknown (tie)'`` for reports."""
    if decision.tie:
        return "unknown (tie)"
    return f"{format_label(decision.label)} ({decision.agreement:.2f} of {decision.n_votes})"
