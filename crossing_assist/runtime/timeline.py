"""``timeline.png``: a run of ``crossing-demo`` at a glance, for the researcher reading where it went
wrong rather than the trace's lines.

Top: the heading the beacon played at each decision (its gate: the learner's or the hold's), the
stretches it was stopped shaded by why, and where the goal really was when that is known (a
synthetic clip's ground truth, or the video's labelled frames: ``--labels``; a labelled frame
with no crossing as a cross on the axis). Bottom: the turn rate the decision logic was told,
coloured by where it came from (a gyroscope, the picture, none). Made with matplotlib when it is
installed (it is not a runtime dependency); otherwise not made.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from crossing_assist.runtime.decide import REASON_FAILED, REASON_STALE, REASON_UNCERTAIN
from crossing_assist.runtime.gate import GATE_HOLD, GATE_LEARNER

STOP_COLOURS = {REASON_UNCERTAIN: "0.88", REASON_STALE: "#f6d6d6", REASON_FAILED: "#f6d6d6"}
OTHER_STOP = "#e3e3f6"   # any other reason
GATE_COLOURS = {GATE_LEARNER: "tab:blue", GATE_HOLD: "tab:orange"}
SOURCE_COLOURS = {"gyro": "tab:green", "camera": "tab:purple", "off": "0.5"}


def _spans(ts: Sequence[float], flags: Sequence[bool], end: float) -> list[tuple[float, float, int]]:
    """Maximal runs of consecutive True ``flags`` as (start, end, first index); each frame lasts
    until the next one (the last until ``end``)."""
    out, start = [], None
    for i, f in enumerate(flags):
        if f and start is None:
            start = i
        if start is not None and (not f or i == len(flags) - 1):
            last = i if f else i - 1
            out.append((ts[start], ts[last + 1] if last + 1 < len(ts) else end, start))
            start = None
    return out


def plot_timeline(records: Sequence[dict], path: str | Path, *, truth: Sequence[tuple[float, float | None]] = (),
                  truth_label: str = "goal (truth)", title: str = "") -> Path | None:
    """Draw ``records`` (trace.jsonl lines: ``t``, ``stop``, ``reason``, ``gate``, ``heading_deg``,
    ``yaw_rate_dps``, ``yaw_source``) and ``truth`` ((t, goal heading or None for no crossing)) to
    ``path``; returns it, or None where matplotlib is not installed."""
    try:
        from crossing_assist.plotting import pyplot, save_figure

        plt = pyplot()
    except ImportError:
        return None
    recs = [r for r in records if r.get("t") is not None]
    ts = [float(r["t"]) for r in recs]
    end = ts[-1] + (ts[-1] - ts[-2] if len(ts) > 1 else 0.1) if ts else 1.0
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(11, 5.5), gridspec_kw={"height_ratios": [3, 1.2]})
    reasons_seen = set()
    for t0, t1, i in _spans(ts, [bool(r["stop"]) for r in recs], end):
        reason = recs[i].get("reason") or "stop"
        top.axvspan(t0, t1, color=STOP_COLOURS.get(reason, OTHER_STOP), lw=0,
                    label=None if reason in reasons_seen else f"stopped: {reason}")
        reasons_seen.add(reason)
    for gate, colour in GATE_COLOURS.items():
        pts = [(t, r["heading_deg"]) for t, r in zip(ts, recs)
               if not r["stop"] and r.get("gate") == gate and r.get("heading_deg") is not None]
        if pts:
            top.plot(*zip(*pts), ".", ms=4, color=colour, label=f"beacon ({gate})")
    seen = [(t, h) for t, h in truth if h is not None]
    none = [t for t, h in truth if h is None]
    if seen:
        top.plot(*zip(*seen), "k_", ms=9, mew=1.5, label=truth_label)
    if none:
        top.plot(none, [0.0] * len(none), "kx", ms=5, label="no crossing (truth)")
    top.axhline(0, color="0.6", lw=0.5)
    top.set(ylabel="heading (deg, + right)", title=title or "crossing-demo: what the beacon played")
    top.legend(loc="upper right", fontsize=7, ncol=3)
    for source, colour in SOURCE_COLOURS.items():
        pts = [(t, r.get("yaw_rate_dps") or 0.0) for t, r in zip(ts, recs) if r.get("yaw_source") == source]
        if pts:
            bottom.plot(*zip(*pts), ".", ms=3, color=colour, label=f"turn from {source}")
    bottom.axhline(0, color="0.6", lw=0.5)
    bottom.set(xlabel="video time (s)", ylabel="turn (deg/s)")
    bottom.legend(loc="upper right", fontsize=7, ncol=3)
    fig.tight_layout()
    return save_figure(fig, path)
