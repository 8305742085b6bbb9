"""A walk begun facing the crossing: does the picture confirm the phone's gyroscope, and what does
the user hear while walking?

The app (and ``run_live``) follows a gyroscope only once the picture's turn has confirmed its sign
(``runtime/gyro.py`` ``GyroCheck``). Until then a decision plays as a stop once the gyroscope's turn
since its capture passes half a strip, which under a walker's sway silences most of a walk. A user
who scans for the crossing first confirms it with clear turns (15 deg/s); one who starts walking
straight at it only sways. This plays synthetic first-person clips (``crossing-data synth --video``:
3-D scenes with the walker's translation, step bob and 2.5 deg step sway) from the start of their
walk phase, live and paced, the model slowed to a phone's pace (``--extra``), the clip's own motion
log replayed as the gyroscope, once per rule:

- ``none``: no gyroscope (the picture's stop);
- ``clear``: confirmed by clear turns only (the rule before 2026-12-07's sway route);
- ``sway``: the shipped rule (clear turns, or the sway agreeing with the picture's);
- ``follow``: followed from the start (the app's opt-in);
- ``reversed``: the shipped rule with the log's sign flipped (it must never be followed).

Each decision is judged against the goal at the moment it was made, frames with the goal in view:
beacon on, heading error, and decisions two strips off or more. A synthetic walk, not a phone's:
the picture's turn is read from rendered frames without motion blur or rolling shutter.

Usage: python scripts/walk_confirm.py [CLIP.mp4 ...] [--extra 0.1] [--rules none,clear,sway,follow,reversed]
(default clip: the sample clip; each clip needs its ``.json`` truth and ``.imu.csv`` beside it).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from crossing_assist.errors import UserError, run_cli
from crossing_assist.runtime.beacon import BeaconConfig, CuePlayer
from crossing_assist.runtime.demo import DEFAULT_BUNDLE, DEFAULT_CLIP
from crossing_assist.runtime.gyro import GYRO_CHECK, GyroFollow, YawIntegrator
from crossing_assist.runtime.imu import ImuLog
from crossing_assist.runtime.live import LiveConfig, run_live
from crossing_assist.runtime.pipeline import open_pipeline
from crossing_assist.runtime.sources import VideoSource
from crossing_assist.runtime.truth import load_truth

RULES = ("none", "clear", "sway", "follow", "reversed")
WRONG_STRIPS = 2


def walk_frames(clip: Path, t_walk: float):
    """The clip's frames from its walk on, timed from there."""
    for t, frame in VideoSource(clip):
        if t >= t_walk - 1e-6:
            yield t - t_walk, frame


def play(clip: Path, rule: str, extra_s: float, bundle: Path) -> dict:
    truth = load_truth(clip)
    if truth is None or "walk" not in (truth.get("phase") or ()):
        raise UserError(f"{clip.with_suffix('.json')} is not a synthetic clip's truth with a walk phase "
                        "(crossing-data synth --video writes one)")
    fps = float(truth["fps"])
    phase = truth["phase"]
    k_walk = phase.index("walk")
    t_walk = k_walk / fps
    az = np.array([np.nan if a is None else a for a in truth["goal_azimuth_deg"]], float)[k_walk:]
    pipe = open_pipeline(bundle)
    decide = pipe.decide

    def slow(seen):
        time.sleep(extra_s)
        return decide(seen)
    pipe.decide = slow
    fov = float(truth["fov_deg"])
    half_view = fov / 2
    cfg = GYRO_CHECK if rule != "clear" else replace(GYRO_CHECK, sway_window=10 ** 9)
    follow = GyroFollow(rule == "follow", cfg)
    gyro = None if rule == "none" else YawIntegrator()
    log = ImuLog.load(clip.with_suffix(".imu.csv")).shifted(t_walk)
    if rule == "reversed":
        log = replace(log, yaw_dps=tuple(-r for r in log.yaw_dps))
    rec: list[tuple[float, object]] = []
    start = time.monotonic()
    replay = log.replay(gyro, start) if gyro is not None else None
    try:
        run_live(walk_frames(clip, t_walk), pipe, CuePlayer(BeaconConfig()), LiveConfig(pace=True),
                 on_step=lambda i, s: rec.append((time.monotonic(), s)), gyro=gyro, follow_gyro=follow, start=start)
    finally:
        if replay is not None:
            replay.close()
    n = on = wrong = 0
    errors = []
    for when, s in rec:
        k = min(len(az) - 1, int(round((when - start) * fps)))
        if np.isnan(az[k]) or abs(az[k]) > half_view:
            continue
        n += 1
        if not s.decision.stop:
            on += 1
            err = abs(s.decision.heading_deg - az[k])
            errors.append(err)
            wrong += int(err >= WRONG_STRIPS * fov / 12)
    e = np.array(errors) if errors else np.array([np.nan])
    confirmed = None if rule in ("none", "follow") else follow.confirmed_at
    return {"clip": clip.name, "rule": rule, "decisions": n, "on": on, "wrong": wrong,
            "median": float(np.nanmedian(e)), "p90": float(np.nanpercentile(e, 90)),
            "confirmed_s": confirmed, "walk_s": (len(az) - 1) / fps}


def main(argv=None) -> int:
    """Bad input in one line and exit 2 (``--debug``: the traceback)."""
    return run_cli(_main, argv)


def _main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("clips", nargs="*", type=Path, default=[DEFAULT_CLIP])
    ap.add_argument("--extra", type=float, default=0.1, help="seconds added to each model run (a phone's pace)")
    ap.add_argument("--rules", default=",".join(RULES))
    ap.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE)
    a = ap.parse_args(argv)
    return measure(a.clips, a.rules.split(","), a.extra, a.bundle)


def measure(clips: list[Path], rules: list[str], extra_s: float, bundle: Path) -> int:
    if bad := [r for r in rules if r not in RULES]:
        raise UserError(f"unknown rule(s) {', '.join(bad)}; valid: {', '.join(RULES)}")
    for clip in clips:
        for need in (clip, clip.with_suffix(".json"), clip.with_suffix(".imu.csv")):
            if not need.is_file():
                raise UserError(f"{need} does not exist (a clip needs its .json truth and .imu.csv log beside it)")
    pooled = {r: [0, 0, 0, []] for r in rules}
    for clip in clips:
        for rule in rules:
            r = play(clip, rule, extra_s, bundle)
            conf = "-" if r["confirmed_s"] is None else f"{r['confirmed_s']:.1f} s"
            print(f"{r['clip']:18s} {rule:8s} walk {r['walk_s']:.1f} s, {r['decisions']:3d} decisions: "
                  f"on {100 * r['on'] / max(1, r['decisions']):5.1f} %, heading error median {r['median']:.1f} deg "
                  f"p90 {r['p90']:.1f}, >= 2 strips off {r['wrong']}, gyroscope followed from {conf}", flush=True)
            p = pooled[rule]
            p[0] += r["decisions"]
            p[1] += r["on"]
            p[2] += r["wrong"]
            p[3].append(r["confirmed_s"])
    if len(clips) > 1:
        for rule, (n, on, wrong, conf) in pooled.items():
            got = [c for c in conf if c is not None]
            print(f"pooled {rule:8s}: {n} decisions, on {100 * on / max(1, n):5.1f} %, >= 2 strips off {wrong}; "
                  f"followed in {len(got)} of {len(conf)} walks" + (f", median from {np.median(got):.1f} s" if got else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
