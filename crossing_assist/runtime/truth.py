"""Ground truth beside a clip (``clip.json`` from ``crossing-data synth --video``): how the
decisions compare with where the goal really was.

The sidecar holds per-frame ``label`` (bin 1..12 or ``unknown``) and ``goal_azimuth_deg``
(bearing of the goal, + right). Reported: how often the beacon guided when the goal was in
view vs not in view, and the heading error while guiding with the goal in view.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np


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
