"""What the user hears: labelled photos played through the runtime as a user meets them.

Each photo is played as a still clip (``seconds`` at ``fps``, 1 s at 10 fps by default): every
frame runs through the bundle's :class:`~crossing_assist.runtime.engine.Engine` (a fresh MC
dropout draw each time) and the runtime's decision logic (:class:`Decider`: filter, gate,
watchdog), exactly as :class:`~crossing_assist.runtime.pipeline.Pipeline` does; the *last*
decision is what the user hears. The engine outputs are kept, so the decision logic can be
replayed at other gate thresholds (the risk-coverage curve) without running the model again.

Per frame: the beacon is *on* (not the stop cue) or off; when on, the strip it points at is
``x_to_bin(heading_to_x(heading, fov))`` with the camera FOV of the frame. A frame with a
crossing is *confidently wrong* when the beacon is on and that strip is >= 2 strips from the
label; a frame with no crossing (label ``unknown``) should be *silent* (beacon off).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import Callable, Iterable, Sequence

import numpy as np

from crossing_assist.actions import UNKNOWN, heading_to_x, x_to_bin, x_to_heading
from crossing_assist.fileio import atomic_path
from crossing_assist.runtime.belief import PROBS_MEASURES
from crossing_assist.runtime.decide import Decider, Decision, DecisionConfig, stale, turned
from crossing_assist.runtime.engine import Engine, Prediction
from crossing_assist.runtime.gate import GATE_HOLD

WRONG_STRIPS = 2     # >= this many strips off with the beacon on: confidently wrong
#: What :meth:`Listener.save` writes besides its ``extra`` arrays.
SAVED = ("seconds", "fps", "labels", "probs", "ok", "uncertainty", "action", "fov_deg", "orientation")


@dataclass(frozen=True)
class Heard:
    """The last decision of one still clip: ``on`` (beacon playing), ``strip`` it points at
    (0 when off), ``label`` (bin 1..12, 0 = no crossing), ``heading_deg`` played (None when off)
    and the camera FOV ``fov_deg`` it was read with."""

    label: int
    on: bool
    strip: int
    heading_deg: float | None = None
    fov_deg: float | None = None


def play_still(engine: Engine, frame: np.ndarray, seconds: float = 1.0, fps: float = 10.0,
               fov_deg: float | None = None, roll_deg: float | None = None) -> list[Prediction]:
    """The engine's predictions for ``frame`` (camera FOV ``fov_deg``, None = the engine's; the
    sensor's camera roll ``roll_deg``, None = none) held still for ``seconds`` at ``fps``."""
    return [engine.predict(frame, fov_deg, roll_deg) for _ in range(max(1, int(round(seconds * fps))))]


def decide_still(preds: Sequence[Prediction], cfg: DecisionConfig, fps: float = 10.0) -> Heard | None:
    """Replay the decision logic over one clip's predictions; the last decision as heard
    (label filled in by the caller)."""
    fov = next((p.fov_deg for p in preds if p.ok and p.fov_deg is not None), cfg.fov_deg)
    decider = Decider(replace(cfg, fov_deg=fov))
    d = None
    for i, p in enumerate(preds):
        d = decider.step(i / fps, p.observation())
    if d is None or d.stop or d.heading_deg is None:
        return Heard(0, False, 0, None, fov)
    return Heard(0, True, heard_strip(d.heading_deg, fov), float(d.heading_deg), fov)


def heard_strip(heading_deg: float, fov_deg: float) -> int:
    """The strip (1..12) a beacon playing ``heading_deg`` points at, for a camera ``fov_deg`` across
    (beyond the frame: the edge strip)."""
    return x_to_bin(min(max(heading_to_x(heading_deg, fov_deg), 0.0), 1.0 - 1e-9))


def summarise(heard: Iterable[Heard]) -> dict:
    """Rates over frames: ``beacon_on`` (frames with a crossing), ``confidently_wrong`` (of
    frames with a crossing: on and >= 2 strips off), ``accuracy_heard`` (on and the right strip),
    ``strip_mae_on`` (mean strip error while on), ``silence_no_crossing`` (beacon off on frames
    with no crossing), with the counts behind them."""
    heard = list(heard)
    pos = [h for h in heard if h.label != UNKNOWN]
    neg = [h for h in heard if h.label == UNKNOWN]
    on = [h for h in pos if h.on]
    err = np.asarray([abs(h.strip - h.label) for h in on], float)
    rate = lambda k, n: float(k / n) if n else None  # noqa: E731
    return {
        "frames_with_crossing": len(pos), "frames_without_crossing": len(neg),
        "beacon_on": rate(len(on), len(pos)),
        "confidently_wrong": rate(int((err >= WRONG_STRIPS).sum()), len(pos)),
        "accuracy_heard": rate(int((err == 0).sum()), len(pos)),
        "strip_mae_on": float(err.mean()) if len(err) else None,
        "silence_no_crossing": rate(sum(not h.on for h in neg), len(neg)),
    }


def heading_errors(heard: Sequence[Heard], far_x: Sequence[float | None]) -> np.ndarray:
    """Degrees between the heading played and the goal's own heading (``far_x``, the far point's
    position across the frame, read with the clip's FOV), for the clips whose beacon is on and
    whose goal is in view (``0 <= far_x <= 1``; None or NaN = no goal): the error a user walks with, comparable across
    cameras of different FOV where strips are not (a 53 deg strip is 0.79 of a 67 deg one)."""
    if len(heard) != len(far_x):
        raise ValueError(f"{len(heard)} clips but {len(far_x)} goal positions")
    return np.asarray([abs(h.heading_deg - x_to_heading(x, h.fov_deg)) for h, x in zip(heard, far_x)
                       if h.on and h.heading_deg is not None and h.fov_deg is not None
                       and x is not None and 0.0 <= x <= 1.0], float)


def error_stats(errors_deg: np.ndarray) -> dict:
    """``n``, ``median``, ``mean`` and ``p90`` of heading errors in degrees (None without any)."""
    e = np.asarray(errors_deg, float)
    if not len(e):
        return {"n": 0, "median": None, "mean": None, "p90": None}
    return {"n": int(len(e)), "median": float(np.median(e)), "mean": float(e.mean()), "p90": float(np.percentile(e, 90))}


@dataclass
class Listener:
    """Plays frames through ``engine`` and keeps their predictions for threshold sweeps."""

    engine: Engine
    seconds: float = 1.0
    fps: float = 10.0
    measure: str | None = None   # the gate's measure for decisions; None = the bundle's

    def __post_init__(self) -> None:
        self.clips: list[list[Prediction]] = []
        self.labels: list[int] = []

    def add(self, frame: np.ndarray, label: int, fov_deg: float | None = None, roll_deg: float | None = None) -> None:
        self.clips.append(play_still(self.engine, frame, self.seconds, self.fps, fov_deg, roll_deg))
        self.labels.append(int(label))

    def save(self, path: str | os.PathLike, **extra: np.ndarray) -> None:
        """The clips' predictions, as far as the decision logic and the model's own accuracy read
        them (probs, uncertainty, ok, argmax, FOV, orientation), their labels and ``extra``
        arrays, in one ``.npz`` written atomically: :meth:`load` replays any gate threshold or
        decision setting without running the model again."""
        if clash := set(extra) & set(SAVED):
            raise ValueError(f"extra arrays named like saved fields: {sorted(clash)}")
        n, a = len(self.clips), self.engine.space.n
        frames = max((len(c) for c in self.clips), default=0)
        if any(len(c) != frames for c in self.clips):
            raise ValueError("clips of different lengths; one Listener plays every clip for the same time")

        def at(get, fill, dtype, *shape) -> np.ndarray:   # one value a frame: [clip, frame, *shape]
            return np.asarray([[get(p) if p.ok else fill for p in clip] for clip in self.clips],
                              dtype).reshape(n, frames, *shape)

        probs = at(lambda p: p.probs, np.full(a, np.nan), np.float64, a)
        with atomic_path(path) as tmp:
            np.savez_compressed(
                tmp, seconds=self.seconds, fps=self.fps, labels=np.asarray(self.labels, np.int64), probs=probs,
                ok=at(lambda p: True, False, bool), uncertainty=at(lambda p: p.uncertainty, np.inf, np.float64),
                action=at(lambda p: p.action, 0, np.int64),
                fov_deg=at(lambda p: np.nan if p.fov_deg is None else p.fov_deg, np.nan, np.float64),
                orientation=at(lambda p: p.orientation or "", "", str), **extra)

    @classmethod
    def load(cls, engine: Engine, path: str | os.PathLike,
             measure: str | None = None) -> tuple["Listener", dict[str, np.ndarray]]:
        """A Listener over the predictions :meth:`save` wrote (decisions replayed with ``engine``'s
        bundle: its decision settings and gate thresholds), and the saved ``extra`` arrays.
        ``measure``: replay the gate with this measure instead of the bundle's, recomputed from
        the saved probabilities (``entropy`` or ``far_mass``: the measures a probability vector
        gives; MC-dropout spreads are not saved)."""
        _check_replayable(measure)
        with np.load(path) as z:
            d = {k: z[k] for k in z.files}
        return cls._replay(engine, d, measure)

    @classmethod
    def average(cls, engine: Engine, paths: Sequence[str | os.PathLike],
                measure: str | None = None) -> tuple["Listener", dict[str, np.ndarray]]:
        """What an ensemble of the bundles that saved ``paths`` would have heard: their predictions
        of one draw, played alike, averaged frame by frame as an ensemble bundle pools its members
        (:mod:`crossing_assist.export.ensemble`); the argmax and the gate's measure (``measure``,
        default the engine's bundle's: one a probability vector gives) recomputed from the averaged
        probabilities; a frame that failed in any member failed. The first file's ``extra`` arrays."""
        measure = measure or engine.measure
        _check_replayable(measure)
        ds = []
        for path in paths:
            with np.load(path) as z:
                ds.append({k: z[k] for k in z.files})
        first = ds[0]
        for path, d in zip(paths[1:], ds[1:]):
            same = all(np.array_equal(d[k], first[k]) for k in ("labels", "orientation", "seconds", "fps")) and \
                np.array_equal(d["fov_deg"], first["fov_deg"], equal_nan=True)
            if not same or d["probs"].shape != first["probs"].shape:
                raise ValueError(f"{path} did not play the clips {paths[0]} played; average plays of one draw")
        d = dict(first, probs=np.mean([d["probs"] for d in ds], axis=0), ok=np.logical_and.reduce([d["ok"] for d in ds]))
        d["action"] = np.where(d["ok"], np.nan_to_num(d["probs"], nan=-1.0).argmax(2), 0)
        return cls._replay(engine, d, measure)

    @classmethod
    def _replay(cls, engine: Engine, d: dict[str, np.ndarray],
                measure: str | None) -> tuple["Listener", dict[str, np.ndarray]]:
        lis = cls(engine, float(d["seconds"]), float(d["fps"]), measure)
        if measure is not None:
            of = PROBS_MEASURES[measure]
            d["uncertainty"] = np.apply_along_axis(lambda p: of(p) if np.all(np.isfinite(p)) else math.inf, 2, d["probs"])
        for k, label in enumerate(d["labels"]):
            lis.clips.append([
                Prediction(ok=True, probs=d["probs"][k, i], uncertainty=float(d["uncertainty"][k, i]),
                           action=int(d["action"][k, i]), orientation=str(d["orientation"][k, i]) or None,
                           fov_deg=None if np.isnan(d["fov_deg"][k, i]) else float(d["fov_deg"][k, i]))
                if d["ok"][k, i] else Prediction(ok=False, error="failed when listened to")
                for i in range(d["probs"].shape[1])])
            lis.labels.append(int(label))
        return lis, {k: v for k, v in d.items() if k not in SAVED}

    def camera(self, i: int) -> tuple[str, float | None]:
        """Clip ``i``'s (orientation, camera FOV) as its first good frame saw them (a clip with none:
        landscape at the bundle's FOV): what picks its gate threshold."""
        first = next((p for p in self.clips[i] if p.ok), None)
        return ("landscape", None) if first is None else (first.orientation or "landscape", first.fov_deg)

    def heard(self, threshold: float | None = None, idx: Sequence[int] | None = None, *,
              scale: float | None = None) -> list[Heard]:
        """The last decisions at the bundle's gate threshold for each clip's orientation and FOV
        (or ``threshold`` for all; or ``scale`` times each clip's own threshold)."""
        if threshold is not None and scale is not None:
            raise ValueError("give a threshold for every clip or a scale of each clip's own, not both")
        over = ({} if threshold is None else {"threshold": float(threshold)}) | \
            ({} if self.measure is None else {"measure": self.measure})
        cfgs: dict = {}
        out = []
        for i in range(len(self.clips)) if idx is None else idx:
            key = self.camera(i)
            if key not in cfgs:
                cfgs[key] = self.engine.decision_config(*key, **over)
                if scale is not None:
                    cfgs[key] = replace(cfgs[key], threshold=cfgs[key].threshold * float(scale))
            out.append(replace(decide_still(self.clips[i], cfgs[key], self.fps), label=self.labels[i]))
        return out

    def risk_coverage(self, thresholds: Sequence[float] = (), idx: Sequence[int] | None = None, *,
                      scales: Sequence[float] = ()) -> list[dict]:
        """For each gate threshold (every clip at it), or each scale of every clip's own threshold
        (``scales``: a sweep in which a set of mixed orientations and cameras plays as the bundle
        plays it at 1): beacon-on rate, confidently-wrong rate, silence off-crossing."""
        return [{"threshold": float(t), **summarise(self.heard(t, idx))} for t in thresholds] + \
            [{"scale": float(m), **summarise(self.heard(idx=idx, scale=m))} for m in scales]


def _check_replayable(measure: str | None) -> None:
    if measure is not None and measure not in PROBS_MEASURES:
        raise ValueError(f"cannot replay measure {measure!r} from saved probabilities; valid: {', '.join(PROBS_MEASURES)}")


def choose_threshold(curve: Sequence[dict], max_wrong: float = 0.005, min_silence: float = 0.98) -> dict | None:
    """The curve point with the most beacon-on whose confidently-wrong rate is <= ``max_wrong``
    and whose silence on no-crossing frames is >= ``min_silence`` (None if no point qualifies)."""
    ok = [c for c in curve if (c["confidently_wrong"] or 0) <= max_wrong
          and (c["silence_no_crossing"] is None or c["silence_no_crossing"] >= min_silence)]
    return max(ok, key=lambda c: (c["beacon_on"] or 0, -c["threshold"])) if ok else None


#: A scan (:func:`scan_yaw`): still for this long first (the belief forms), and the frame rate.
SCAN_STILL_S = 1.0
SCAN_FPS = 10.0


def scan_yaw(amplitude_deg: float = 20.0, rate_dps: float = 30.0, fps: float = SCAN_FPS) -> np.ndarray:
    """A user scanning for the crossing: the camera's yaw (degrees, + = turned right) at each
    frame, ``SCAN_STILL_S`` still, then 0 -> +A -> -A -> 0 at ``rate_dps``."""
    if not (0 < amplitude_deg < 90 and rate_dps > 0 and fps > 0):
        raise ValueError(f"Invalid scan: amplitude {amplitude_deg} deg (0..90), rate {rate_dps} deg/s, "
                         f"{fps} fps (> 0)")
    step = rate_dps / fps
    legs = [np.arange(0, amplitude_deg, step), np.arange(amplitude_deg, -amplitude_deg, -step),
            np.arange(-amplitude_deg, 0, step)]
    return np.concatenate([np.zeros(int(round(SCAN_STILL_S * fps))), *legs, [0.0]])


def sway_yaw(amplitude_deg: float = 2.5, rate_dps: float = 14.0, cycles: int = 3, fps: float = SCAN_FPS) -> np.ndarray:
    """A walker's sway instead of a scan: ``SCAN_STILL_S`` still, then the camera's yaw swings
    ``amplitude_deg`` either side, a sine whose fastest turn is ``rate_dps``, for ``cycles``
    periods (the defaults: the sample clip's step sway, 2.5 deg at 0.9 Hz)."""
    if not (0 < amplitude_deg < 90 and rate_dps > 0 and fps > 0 and cycles >= 1):
        raise ValueError(f"Invalid sway: amplitude {amplitude_deg} deg (0..90), rate {rate_dps} deg/s, "
                         f"{fps} fps (> 0), {cycles} cycles (>= 1)")
    omega = rate_dps / amplitude_deg                  # rad/s: the sine's fastest turn is A * omega
    t = np.arange(int(round(cycles * 2 * np.pi / omega * fps)) + 1) / fps
    return np.concatenate([np.zeros(int(round(SCAN_STILL_S * fps))), amplitude_deg * np.sin(omega * t)])


#: How a scan's turn reaches the decision logic (:func:`judge_scans`): told by a gyroscope (the
#: app's opt-in one), read from the frames (:mod:`~crossing_assist.runtime.visual_yaw`, the app's
#: and the Python pipeline's default without one), or not at all.
SCAN_YAW_INPUTS = {"gyro": "turn from a gyroscope", "camera": "turn read from the frames", "no_yaw": "no turn input"}


#: The extra readings :func:`judge_scans` gives when decisions are heard late: the decisions of a
#: :data:`SCAN_YAW_INPUTS` reading, each played turned by the gyroscope's turn since its frame's
#: capture (:func:`~crossing_assist.runtime.decide.turned`; the app's ``followTurn``: the
#: gyroscope followed, or the picture followed and the gyroscope confirmed by it).
TURNED_READINGS = {"gyro_turned": ("gyro", "turn from a gyroscope, the beacon turned with it until heard"),
                   "camera_turned": ("camera", "turn read from the frames, the beacon turned by a gyroscope until heard")}

#: And the app's play while its gyroscope reports but is not followed (not yet confirmed by the
#: picture): the picture's decisions, each a stop once the gyroscope's turn since its capture,
#: carried on at its rate to the end of the play, passes half a strip
#: (:func:`~crossing_assist.runtime.decide.stale`: the size of the turn known, not its way), judged
#: as :data:`READ_STALE_READINGS` with the gyroscope's turn (since 2026-12-07, night: judged as it
#: stood, a walker's sway left held-out landscape frames 1.25 % confidently wrong, carried 0.23 %).
STALE_READINGS = {"camera_stale": ("camera", "turn read from the frames, a stop once the gyroscope's turn "
                                             "carried to the end of the play is half a strip (a gyroscope not followed)")}

#: And a player with no gyroscope at all (the Python live loop, the app on a phone without one):
#: nothing measures the turn once the frame is read, so each decision of the picture's reading is a
#: stop when the rate read at its frame, carried to the end of its play (heard, then one frame more),
#: passes half a strip, or when by the moment heard the frames read since (those captured before
#: it) turned that far, carried on at the last one's rate to the end of its play
#: (:meth:`~crossing_assist.runtime.pipeline.Pipeline.heard`, checked as the live loop checks it).
READ_STALE_READINGS = {"camera_read_stale": ("camera", "turn read from the frames, a stop once the turn read at "
                                                       "its frame or since makes it half a strip stale (no gyroscope)")}

#: Every reading :func:`judge_scans` adds when decisions are heard late: name -> (the
#: :data:`SCAN_YAW_INPUTS` reading it plays, what it is)
LATE_READINGS = {**TURNED_READINGS, **STALE_READINGS, **READ_STALE_READINGS}


def judge_scans(engine: Engine, clips: Sequence[Sequence[Prediction]], labels: np.ndarray,
                psi: np.ndarray, camera_rates: np.ndarray, fps: float = SCAN_FPS,
                heard_after_s: float = 0.0, **overrides) -> dict:
    """Replay the decision logic over scanned clips (``clips[i][j]``: photo ``i`` seen with the
    camera turned ``psi[j]`` degrees; ``labels[i, j]`` its goal's strip then, 0 once out of view)
    once per :data:`SCAN_YAW_INPUTS`: told the turn, told the rates ``camera_rates[i, j]`` read from
    the frames, told nothing. Every frame after the still second is judged against the goal in
    *that* frame: with the goal in view, beacon on and confidently wrong, and how many of the
    wrong frames the heading hold played, and on how many photos any frame was (``wrong_photos``:
    a photo the model misreads stays wrong over many frames, so the frames are not independent);
    with the goal out of view, the beacon on and pointing to the side the goal did not leave by.

    ``heard_after_s`` (rounded to whole frames): each decision is judged when it is heard, that
    long after its frame's capture (the model's run, then playing until the next decision),
    against the goal and the camera's turn then (the phone app, in its e2e run: heard 0.28 s to
    0.51 s after capture; docs/results.md, "Heard when it plays"). It adds :data:`TURNED_READINGS`:
    a reading's decisions with the beacon turned by the gyroscope's turn since the capture, and
    :data:`STALE_READINGS`: with only that turn's size known, each a stop once it passes half a
    strip by the end of its play, and
    :data:`READ_STALE_READINGS`: with no turn measured but the frames', each a stop when the turn
    read at its frame, or by the frames read since, makes it half a strip stale by the end of its play.
    ``overrides``: decision settings for every clip instead of the bundle's (e.g. ``threshold``
    and ``measure``: a gate swept, :meth:`Engine.decision_config`)."""
    psi = np.asarray(psi, float)
    lag = int(round(heard_after_s * fps))
    if not 0 <= lag < len(psi):
        raise ValueError(f"Invalid heard_after_s: {heard_after_s}; valid: 0 <= s < {len(psi) / fps:g} (the scan)")
    gyro = np.broadcast_to(np.diff(psi, prepend=psi[0]) * fps, (len(clips), len(psi)))
    rates = {"gyro": gyro, "camera": np.asarray(camera_rates, float), "no_yaw": np.zeros((len(clips), len(psi)))}
    res = {k: _judge_scan_input(engine, clips, labels, psi, rates[k], fps, lag, overrides=overrides)
           for k in SCAN_YAW_INPUTS}
    if lag:
        for name, (reading, _) in TURNED_READINGS.items():
            res[name] = _judge_scan_input(engine, clips, labels, psi, rates[reading], fps, lag, play=turned,
                                          overrides=overrides)
        for readings, turn in ((STALE_READINGS, "gyro"), (READ_STALE_READINGS, None)):
            for name, (reading, _) in readings.items():
                res[name] = _judge_scan_input(engine, clips, labels, psi, rates[reading], fps, lag, play=stale,
                                              overrides=overrides, turn_rates=rates[turn or reading])
    return res


def _judge_scan_input(engine: Engine, clips: Sequence[Sequence[Prediction]], labels: np.ndarray,
                      psi: np.ndarray, rates: np.ndarray, fps: float, lag: int = 0,
                      play: Callable[[Decision, float, float], Decision] | None = None,
                      overrides: dict | None = None, turn_rates: np.ndarray | None = None) -> dict:
    # turn_rates: the turn is known only as these rates (a stop once stale), not psi at the moment heard
    start = int(round(SCAN_STILL_S * fps))
    c = dict.fromkeys(("in_view", "on", "wrong", "wrong_hold", "wrong_photos", "out_of_view", "out_on",
                       "out_wrong_side"), 0)
    for i, (clip, labs, clip_rates) in enumerate(zip(clips, labels, rates)):
        turn_read = None if turn_rates is None else turn_rates[i]
        wrong_before = c["wrong"]
        first = next((p for p in clip if p.ok), None)
        decider = Decider(engine.decision_config((first and first.orientation) or "landscape", first and first.fov_deg,
                                                 **(overrides or {})))
        fov = decider.cfg.fov_deg
        for j, p in enumerate(clip):
            d = decider.step(j / fps, p.observation(), float(clip_rates[j]))
            h = j + lag    # the frame whose moment the decision is heard at
            if j < start or h >= len(clip):
                continue
            if turn_read is not None:   # the turn's rate at its frame, carried to the end of its play;
                # then the turn read since (by the frames captured before h), carried on as far
                d = play(d, float(turn_read[j]) * (lag + 1) / fps, fov)
                if h - 1 > j:
                    d = play(d, float(np.sum(turn_read[j + 1:h]) + turn_read[h - 1] * 2) / fps, fov)
            elif play is not None:   # played as heard: the decision and the gyroscope's turn since its capture
                d = play(d, float(psi[h] - psi[j]), fov)
            label = int(labs[h])
            if label != UNKNOWN:
                c["in_view"] += 1
                c["on"] += int(not d.stop)
                bad = not d.stop and abs(heard_strip(d.heading_deg, fov) - label) >= WRONG_STRIPS
                c["wrong"] += int(bad)
                c["wrong_hold"] += int(bad and d.gate == GATE_HOLD)
            else:
                c["out_of_view"] += 1
                c["out_on"] += int(not d.stop)
                # turned right (psi > 0), the goal left the view on the left: a beacon to the right is wrong
                c["out_wrong_side"] += int(not d.stop and (d.heading_deg > 0) == (psi[h] > 0))
        c["wrong_photos"] += int(c["wrong"] > wrong_before)
    rate = lambda k, n: c[k] / c[n] if c[n] else None  # noqa: E731
    return {**c, "beacon_on": rate("on", "in_view"), "confidently_wrong": rate("wrong", "in_view"),
            "wrong_by_hold": rate("wrong_hold", "wrong"), "out_of_view_on": rate("out_on", "out_of_view"),
            "out_of_view_wrong_side": rate("out_wrong_side", "out_of_view")}
