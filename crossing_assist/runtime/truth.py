"""Ground truth for a clip: how the decisions compare with where the goal really was.

Two kinds:

- the sidecar ``clip.json`` beside a synthetic clip (``crossing-data synth --video``): per-frame
  ``label`` (bin 1..12 or ``unknown``) and ``goal_azimuth_deg`` (bearing of the goal, + right).
  Reported: how often the beacon guided when the goal was in view vs not in view, and the heading
  error while guiding with the goal in view;
- frames of a real video labelled as a dataset (``crossing-demo VIDEO --labels DIR``: frames cut
  by ``crossing-data frames VIDEO``, labelled, made a dataset by ``crossing-data votes``): each
  labelled frame is matched to the video's frame at its time (in its file name,
  ``<video>_t<seconds>.jpg``), and the decision made on it judged as ``crossing-eval --bundle``
  judges what the user hears (:func:`~crossing_assist.runtime.listen.summarise`): beacon on and
  confidently wrong on frames with a crossing, silence on frames without one, heading error.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from crossing_assist.errors import UserError

#: The time in a frame's file name, as ``crossing-data frames`` writes it (``corner03_t0012.500.jpg``).
FRAME_TIME = re.compile(r"_t(\d+(?:\.\d+)?)\.[A-Za-z0-9]+$")


def load_truth(video: str | Path) -> dict | None:
    """The sidecar ``<video stem>.json`` if it exists and has per-frame labels, else None."""
    path = Path(video).with_suffix(".json")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("label"), list):
        return None
    if not isinstance(data.get("goal_azimuth_deg"), list) or len(data["goal_azimuth_deg"]) != len(data["label"]):
        return None
    return data


def compare(truth: dict, headings: Sequence[float | None]) -> dict | None:
    """Guidance vs truth for ``headings`` (one per frame, None = stopped); None if lengths differ."""
    labels, az = truth["label"], truth["goal_azimuth_deg"]
    if len(labels) != len(headings):
        return None
    far_x = truth.get("far_x")
    if isinstance(far_x, list) and len(far_x) == len(labels):   # in view = the goal's x is in the frame
        visible = np.array([x is not None for x in far_x])
    else:
        visible = np.array([str(lab) != "unknown" for lab in labels])
    guided = np.array([h is not None for h in headings])
    errs = [abs(h - a) for h, a, v in zip(headings, az, visible) if h is not None and v]
    return {
        "frames_goal_visible": int(visible.sum()),
        "guided_when_visible": float(guided[visible].mean()) if visible.any() else None,
        "guided_when_not_visible": float(guided[~visible].mean()) if (~visible).any() else None,
        "median_heading_error_deg": float(np.median(errs)) if errs else None,
        "p90_heading_error_deg": float(np.percentile(errs, 90)) if errs else None,
    }


def truth_line(stats: dict) -> str:
    """One summary line."""
    def pct(v):
        return "n/a" if v is None else f"{100 * v:.0f}%"

    def deg(v):
        return "n/a" if v is None else f"{v:.1f} deg"

    return (f"vs ground truth: guided {pct(stats['guided_when_visible'])} of frames with the goal in view, "
            f"{pct(stats['guided_when_not_visible'])} without; heading error when guiding: median "
            f"{deg(stats['median_heading_error_deg'])}, p90 {deg(stats['p90_heading_error_deg'])}")


class LabelsError(UserError):
    """Labels that cannot be matched with the video: one line naming the fix."""


@dataclass(frozen=True)
class LabelledFrame:
    """One labelled frame of the video: its time, bin (0 = no crossing), far point (None: none)."""

    t: float
    label: int
    far_x: float | None
    image: str


def load_labels(dataset_dir: str | Path, video: str | Path) -> list[LabelledFrame]:
    """The rows of the dataset at ``dataset_dir`` cut from ``video`` (source ``vid:<name>``, the
    name ``crossing-data frames`` gave it), by time. Raises :class:`LabelsError` when none is."""
    from crossing_assist.data_tools.frames import video_name
    from crossing_assist.data_tools.manifest import read_manifest

    ds = read_manifest(dataset_dir, check_images=False)
    source = f"vid:{video_name(Path(video), set())}"
    frames = []
    for row in ds.rows:
        m = FRAME_TIME.search(row.image)
        if row.source == source and m:
            frames.append(LabelledFrame(float(m.group(1)), row.label, row.far_x, row.image))
    if not frames:
        sources = sorted({r.source for r in ds.rows})
        raise LabelsError(f"--labels {dataset_dir}: no labelled frame of {Path(video).name} (rows with source {source} "
                          f"and a time in the image name); it has {', '.join(sources[:5]) or 'no rows'}"
                          f"{', ...' if len(sources) > 5 else ''}: label frames made by crossing-data frames "
                          f"{Path(video).name}")
    return sorted(frames, key=lambda f: f.t)


def judge_labels(labelled: Sequence[LabelledFrame], times: Sequence[float], headings: Sequence[float | None],
                 fovs: Sequence[float | None]) -> dict:
    """What the user heard at each labelled frame: the decision made on the video's frame at its
    time (within 2 ms; ``times``, ``headings`` and their ``fovs`` per decided frame), judged as
    :func:`~crossing_assist.runtime.listen.summarise` judges; ``heading_error`` from the far
    point; ``unmatched``: labelled frames no decided frame was at."""
    from crossing_assist.runtime.listen import Heard, error_stats, heading_errors, heard_strip, summarise

    ts = np.asarray(times, float)
    heard, far_x, unmatched = [], [], 0
    for f in labelled:
        i = int(np.argmin(np.abs(ts - f.t))) if len(ts) else -1
        if i < 0 or abs(ts[i] - f.t) > 0.002:
            unmatched += 1
            continue
        h, fov = headings[i], fovs[i]
        on = h is not None and fov is not None
        heard.append(Heard(f.label, on, heard_strip(h, fov) if on else 0, h if on else None, fov))
        far_x.append(f.far_x)
    out = summarise(heard)
    out["heading_error"] = error_stats(heading_errors(heard, far_x))
    out["unmatched"] = unmatched
    return out


def labels_line(stats: dict) -> str:
    """One summary line on :func:`judge_labels`' figures."""
    def pct(v):
        return "n/a" if v is None else f"{100 * v:.1f}%"

    e = stats["heading_error"]
    line = (f"vs labels: beacon on {pct(stats['beacon_on'])} of the {stats['frames_with_crossing']} labelled frames "
            f"with a crossing, confidently wrong (on, >= 2 strips off) {pct(stats['confidently_wrong'])}, right strip "
            f"{pct(stats['accuracy_heard'])}; silent on {pct(stats['silence_no_crossing'])} of the "
            f"{stats['frames_without_crossing']} without one")
    if e["n"]:
        line += f"; heading error median {e['median']:.1f} deg, p90 {e['p90']:.1f} deg ({e['n']} frames)"
    if stats["unmatched"]:
        line += f"; {stats['unmatched']} labelled frames matched no frame of the video (another video's?)"
    return line
