"""Shared decision test vectors: the phone app must reproduce these decisions exactly.

    python -m crossing_assist.testing.vectors --out android_demo/test_vectors.json

A generator, not part of the runtime: the rules it records live in the runtime
(:mod:`~crossing_assist.runtime.decide`, :mod:`~crossing_assist.runtime.beacon`,
:mod:`~crossing_assist.runtime.live`, :mod:`~crossing_assist.runtime.status`,
:mod:`~crossing_assist.runtime.camera`).

Each scenario gives the full :class:`DecisionConfig`, then one entry per step with the inputs
(``t`` seconds, ``yaw_rate_dps``, and ``obs``: null for a tick without a frame, else the
graph's raw outputs ``ok``, ``probs``, ``entropy``, ``mutual_info``, ``variance`` and the derived
``uncertainty``, the bundle's measure) and the expected :class:`Decision` (every field, the belief
included). Inputs are generated from a seeded generator, so the file is reproducible. Floats
are written at full double precision; a port should agree to ~1e-9 (``tolerance``), and on
every discrete field (gate, reason, stop, learner_action) exactly. Plus pure-function vectors
for the beacon (pan gains, ITD, pulse loop length, heading -> pan).

Version 2 adds what the live loop decides around the Decider, so the app and Python share it:

* ``guards``: the frozen-frame rule (:func:`~crossing_assist.runtime.live.same_frame`: same
  shape and every byte equal), freshness (:func:`~crossing_assist.runtime.live.is_fresh`) and
  the watchdog (:class:`~crossing_assist.runtime.watchdog.Watchdog` on a scripted clock);
* ``status``: the sentence shown and spoken for each decision
  (:func:`~crossing_assist.runtime.status.status_message`);
* ``geometry``: the camera-geometry contract's field-of-view choice
  (:func:`~crossing_assist.runtime.camera.camera_fov`:
  orientation of the frame -> the override or the bundle's ``camera_fov_deg``, refused
  outside 20..170 degrees; schema 1 reads as one FOV for both orientations), and scenarios
  whose frames are portrait and landscape of several aspects: each step's FOV comes from
  its frame, and a change of FOV (the phone turned) starts a fresh Decider with it.

Version 3: each geometry scenario also carries the bundle's ``calibration.uncertainty``
(``threshold``, optional ``portrait_threshold``); each step's gate threshold is its frame's
orientation's (:func:`~crossing_assist.runtime.camera.gate_threshold`), and a change of FOV *or*
threshold starts a fresh Decider.

Version 4: ``geometry.view_rows``, the view crop of bundle schema 3 (``geometry.view_crop``):
for frames of every :data:`FRAME_SIZES` size (and a few extreme ones), the bundle's default FOV
of the frame's orientation or an override, several canvases (``input.size``) and training FOVs,
the FOV the frame gets (:func:`~crossing_assist.runtime.camera.camera_fov` of
:data:`GEOMETRY_V3`) and the rows the graph sees, ``[top, rows]`` of
:func:`crossing_assist.geometry.view_rows` (integers: a port must agree exactly; wide cameras,
whose frames are fitted by their width, included). Its own cases,
no generator: the vectors above are those of version 3.

Version 5: ``geometry.sensor_aspect`` (optional, long / short side of the sensor
``camera_fov_deg`` describes): the default FOV of a frame narrower than the sensor in its
orientation is its crop's (:func:`crossing_assist.geometry.default_fov`; 9:16 portrait video:
~41 deg, not 53). ``geometry.fov_choice`` gains cases over :data:`ASPECT_SIZES` (9:16 to 10:1)
with and without the field (refused where a crop's FOV falls below 20 degrees);
``geometry.view_rows_sensor`` is ``view_rows`` under :data:`GEOMETRY_V3_SENSOR` (the rows seen at
the per-aspect default FOV); one more decision scenario (own generator, appended) has a phone
filming 9:16 video upright, turned to landscape and back. The vectors above are those of version 4.

Version 6: ``geometry.view_zoom`` (bundle schema 4): ``geometry.view_rows_zoom`` is ``view_rows``
under :data:`GEOMETRY_V4` with each case's ``zoom`` (frames from a camera narrower than the
training one shown magnified up to it; a large zoom fills the canvas). Its own cases, no
generator: the vectors above are those of version 5.

Version 7: the ``far_mass`` measure (:func:`crossing_assist.runtime.belief.far_mass`): scenario
``far_mass_neighbours`` gates frames and the belief by the probability beyond one strip of the
argmax; frames spread over neighbouring strips speak, frames split between far strips do not.
The scenarios before it are those of version 6.

Version 8: a narrow camera's gate threshold (``calibration.uncertainty.narrow_threshold`` for
portrait frames at most ``narrow_fov_deg`` across; each step's threshold is
``gate_threshold(frame, its FOV)``): scenario ``narrow_threshold_9x16_video`` films 9:16 video
upright (~41 deg: the narrow threshold), then 3:4 (53 deg: the portrait one), landscape, and
9:16 again, with frames whose doubt lies between the two portrait thresholds. The scenarios
before it are those of version 7.

Version 9: ``geometry.level``, levelling a rolled camera's frame
(:func:`crossing_assist.geometry.level_angle`: how far a roll is turned back, clamped, small ones
left alone) and ``pad_rgb``, what fills the corners the camera did not see. The scenarios are
those of version 8.

Version 10: step 4a of the decision logic (the first frame after a stall, more than the
watchdog since the last successful one, meets a fresh belief and no hold): scenario
``stall_then_nothing``, a steady goal, 1 s of ticks, then frames showing nothing. Before it, the
hold and the belief from before the stall put the old direction back on for 0.2-0.4 s. The
scenarios before it are those of version 9. Also in version 10: each ``geometry.level`` case says
whether the roll is ``too_far`` (:func:`crossing_assist.geometry.rolled_too_far`: beyond
``MAX_GUIDED_ROLL_DEG``, no guidance), and the ``status`` section has the ``rolled`` stop.

Version 12: ``visual_yaw``, the camera's turn read from consecutive frames
(:mod:`crossing_assist.runtime.visual_yaw`), which the app feeds the Decider without a
gyroscope: its constants; ``thumbnails`` (small RGB frames, flat row-major ``rgb`` bytes, and
the grey thumbnail each gives at a ``width``); ``shifts`` (pairs of thumbnails and the shift
``shift_between`` finds, null where it cannot tell: no texture, different sizes, a change that
is no shift); ``sequence`` (frames at times and FOVs through one ``VisualYaw`` of ``width``,
the yaw rate after each: a turn right, left, a missing frame or FOV that starts afresh, a turn
too fast to believe, a new size).
The scenarios are those of version 11.

Version 13: an edge strip means "at this edge or beyond it": a turn towards it spreads the
belief's edge mass from its moved centre back out to the edge
(:func:`crossing_assist.runtime.belief.spread_edge`), and a hold taken in an edge strip is
dropped once such a turn carries it out of that strip (step 3). Scenarios ``edge_goal_turned_towards``
(a goal seen in strip 12, then the user turns right with frames that see nothing) and
``edge_goal_turned_away`` (seen in strip 1, then the same turn right: the hold stays) are
appended; every earlier scenario whose turns move an edge strip's mass inward changes with it.

Version 14: ``turned``, step 10 (:func:`crossing_assist.runtime.decide.turned`): a decision's
``heading_deg`` and ``pan`` (null: a stop) at a camera ``fov_deg`` across, once the camera turned
``turn_deg`` since its frame's capture, and the heading and pan then played (``expect``). The
scenarios are those of version 13.

Version 15: step 10 stops a decision in an edge strip once the turn towards that edge carries its
heading out of the strip (where the goal is is unknown then, as for step 3's hold). Each
``turned`` case now also carries the decision's ``stop`` and ``reason``, before and after
(``expect``); the scenarios are unchanged.

Version 16: ``stale``, step 10 without the turn's sign (:func:`crossing_assist.runtime.decide.stale`,
the app's play while its gyroscope reports but is not followed): the same decisions and FOVs, and
turns on both sides of half a strip; the decision as played (``expect``). The scenarios are unchanged.

Version 17: the camera's width picks the gate threshold (``calibration.uncertainty.wide_fov_deg``,
:meth:`crossing_assist.bundle.UncertaintySpec.which`): scenarios ``wide_fov_square_frame``
and ``wide_fov_portrait_set_wide``: a square frame (~53 deg across, landscape by its sides: the
portrait threshold), 4:3 landscape (67 deg: the landscape one), 9:16 video upright (~41 deg: the
narrow one), 3:4 portrait (53 deg: the portrait one), then 3:4 portrait the user set to 65 deg
(the landscape one). The earlier scenarios are unchanged. And the view rows of a frame shorter than
the view the canvas shows at the training scale (a landscape camera set or zoomed narrower) are now
more than its height (``top`` < 0: rows of ``pad_rgb`` above and below, ``geometry.take_rows``),
where they were its height (it filled the canvas magnified); a frame within ``height // 50`` rows of
that view keeps its height.

Version 18: ``visual_yaw`` gains the constant ``ambiguous`` and the shift case
``stripes_a_period_off``: vertical stripes 7 px apart moved 2 px, with a wobble, match 5 px the
other way as well (a zebra's stripes under a walker's feet), and another local minimum of the
scores within ``AMBIGUOUS`` times the best is no turn (null), where it read -5.08 px. The other
vectors are unchanged.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crossing_assist.actions import DEFAULT_FOV_DEG, get_space, heading_to_pan
from crossing_assist.fileio import atomic_write_text
from crossing_assist.geometry import FOV_RANGE_DEG, PAD_RGB, level_angle, orientation, rolled_too_far, view_rows
from crossing_assist.runtime.beacon import BeaconConfig, itd_seconds, pan_gains
from crossing_assist.runtime.belief import entropy
from crossing_assist.runtime.camera import camera_fov, gate_threshold, geometry_of
from crossing_assist.runtime.decide import REASON_UNCERTAIN, Decider, DecisionConfig, Observation, stale, turned
from crossing_assist.runtime.engine import measure_value
from crossing_assist.runtime.live import is_fresh, same_frame
from crossing_assist.runtime.status import STATUS_STOP, status_message
from crossing_assist.runtime import visual_yaw as vy
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S, Watchdog

FPS = 30.0
VERSION = 18

def _probs_for(space_n: int, action: int, conf: float) -> np.ndarray:
    p = np.full(space_n, (1.0 - conf) / (space_n - 1))
    p[action] = conf
    return p


@dataclass(frozen=True)
class RawOutputs:
    """A frame's graph outputs as the bundle gives them (``ok=False``: inference failed)."""

    probs: np.ndarray | None
    entropy: float = math.inf
    mutual_info: float = math.inf
    variance: np.ndarray | None = None
    ok: bool = True

    def observation(self, measure: str) -> Observation:
        """What the decision logic sees: ``probs`` and the bundle's measure (engine rule)."""
        if not self.ok:
            return Observation(None, math.inf, ok=False)
        return Observation(self.probs, measure_value(measure, self.entropy, self.mutual_info, self.variance,
                                                     self.probs))

    def to_json(self) -> dict:
        if not self.ok:
            return {"ok": False, "probs": None, "entropy": None, "mutual_info": None, "variance": None}
        return {"ok": True, "probs": [float(v) for v in self.probs], "entropy": self.entropy,
                "mutual_info": self.mutual_info, "variance": [float(v) for v in self.variance]}


FAILED = RawOutputs(None, ok=False)


def _frame(space_n: int, action: int, conf: float, rng: np.random.Generator) -> RawOutputs:
    p = _probs_for(space_n, action, conf)
    p = p * rng.uniform(0.9, 1.1, size=space_n)
    p = p / p.sum()
    return RawOutputs(p, entropy(p), float(rng.uniform(0.0, 0.3)), rng.uniform(0.0, 0.03, size=space_n))


def _scenarios(rng: np.random.Generator) -> list[tuple[str, DecisionConfig, list[tuple[float, float, RawOutputs | None]]]]:
    base = DecisionConfig()
    flat = RawOutputs(np.full(13, 1 / 13), math.log(13), 0.0, np.zeros(13))
    out = []
    sweep = [(i / FPS, 0.0, _frame(13, 1 + min(11, i * 12 // 90), 0.9, rng)) for i in range(100)]
    out.append(("sweep_left_to_right", base, sweep))
    out.append(("noise", base, [(i / FPS, 0.0, flat) for i in range(30)]))
    out.append(("unknown", base, [(i / FPS, 0.0, _frame(13, 0, 0.8, rng)) for i in range(30)]))
    odd = [(i / FPS, 0.0, _frame(13, 11 if i == 40 else 4, 0.9, rng)) for i in range(50)]
    out.append(("odd_frame", base, odd))
    hold = [(i / FPS, 0.0, _frame(13, 8, 0.95, rng)) for i in range(30)]
    hold += [((30 + i) / FPS, 25.0, flat) for i in range(75)]
    out.append(("hold_with_yaw_then_stop", base, hold))
    freeze = [(i / FPS, 0.0, _frame(13, 6, 0.9, rng)) for i in range(20)]
    freeze += [(20 / FPS + 0.05 * (j + 1), 0.0, None) for j in range(14)]
    out.append(("freeze_ticks_stale", base, freeze))
    fail = [(i / FPS, 0.0, _frame(13, 10, 0.9, rng)) for i in range(20)]
    fail[12] = (12 / FPS, 0.0, FAILED)
    out.append(("inference_failure", base, fail))
    jump = [(i / FPS, 0.0, _frame(13, 3 if i < 30 else 11, 0.97, rng)) for i in range(45)]
    out.append(("disagreement_jump", base, jump))
    turn = [(i / FPS, -60.0 if i >= 20 else 0.0, _frame(13, 2, 0.9, rng)) for i in range(40)]
    out.append(("fast_turn_goal_leaves_frame", base, turn))
    c4 = dataclasses.replace(base, n_actions=4)
    out.append(("four_actions", c4, [(i / FPS, 5.0, _frame(4, 1 + (i // 15) % 3, 0.85, rng))
                                      for i in range(45)]))
    c8 = dataclasses.replace(base, n_actions=8, measure="mutual_info", threshold=0.2)
    out.append(("eight_actions_mutual_info", c8, [(i / 15.0, 0.0, _frame(8, 1 + (i // 8) % 7, 0.8, rng))
                                                   for i in range(40)]))
    cv = dataclasses.replace(base, measure="variance", threshold=0.02)
    out.append(("variance_measure", cv, [(i / FPS, 0.0, _frame(13, 10, 0.9, rng)) for i in range(40)]))
    irregular = [(0.0, 0.0, _frame(13, 5, 0.9, rng))]
    t = 0.0
    for i in range(40):
        t += float(rng.uniform(0.01, 0.3))
        k = 9 if rng.uniform() < 0.7 else int(rng.integers(0, 13))
        obs = None if i % 7 == 3 else _frame(13, k, float(rng.uniform(0.5, 0.99)), rng)
        irregular.append((t, float(rng.uniform(-40, 40)), obs))
    out.append(("irregular_random", base, irregular))
    near = np.full(13, 0.004)
    near[5:8] = (0.3, 0.4, 0.3 - 0.004 * 10)   # strips 5..7: high entropy, little mass beyond one strip
    far = np.full(13, 0.004)
    far[[3, 9]] = (0.6, 0.4 - 0.004 * 11)       # strips 3 and 9: the same doubt, two strips and more apart
    raw = lambda p: RawOutputs(p, entropy(p), 0.1, np.zeros(13))  # noqa: E731
    cf = dataclasses.replace(base, measure="far_mass", threshold=0.06)
    out.append(("far_mass_neighbours", cf, [(i / FPS, 0.0, raw(near if i < 30 or i >= 90 else far))
                                            for i in range(120)]))
    # version 10: the camera stalls for 1 s (ticks keep coming), then frames come back showing
    # nothing: the direction from before the stall must not come back (step 4a)
    stall = [(i / FPS, 0.0, _frame(13, 9, 0.95, rng)) for i in range(20)]
    resume = 20 / FPS + 1.0
    stall += [(20 / FPS + 0.1 * (j + 1), 0.0, None) for j in range(10)]
    stall += [(resume + j / FPS, 0.0, flat) for j in range(1, 16)]
    out.append(("stall_then_nothing", base, stall))
    # version 11: the camera turns with no yaw input: unsure frames see the goal 6 strips from the
    # hold, which they drop (step 4b); the hold played the old direction for 1.5 s before
    pan = [(i / FPS, 0.0, _frame(13, 9, 0.95, rng)) for i in range(30)]
    pan += [((30 + i) / FPS, 0.0, _frame(13, 3, 0.3, rng)) for i in range(30)]
    out.append(("pan_without_yaw_input", base, pan))
    # version 13 (its own draws, so the scenarios after it keep theirs): a goal seen at an edge,
    # then a turn right at 30 deg/s with frames that see nothing
    r13 = np.random.default_rng(13)
    nothing = [((30 + i) / FPS, 30.0, _frame(13, 0, 0.8, r13)) for i in range(45)]
    out.append(("edge_goal_turned_towards", base, [(i / FPS, 0.0, _frame(13, 12, 0.95, r13)) for i in range(30)]
                + nothing))
    out.append(("edge_goal_turned_away", base, [(i / FPS, 0.0, _frame(13, 1, 0.95, r13)) for i in range(30)]
                + nothing))
    return out


#: Frame sizes (width, height) the geometry scenarios use: portrait and landscape, several aspects.
FRAME_SIZES = ((640, 480), (480, 640), (1280, 720), (720, 1280), (480, 480), (360, 720), (720, 360), (1080, 2400))
GEOMETRY_V2 = {"fit": "letterbox", "pad_rgb": [124, 116, 104], "strips": "frame",
               "camera_fov_deg": {"landscape": 67.0, "portrait": 53.0}, "train_fov_deg": 67.0}
#: Schema 3's geometry: the same with the view crop on.
GEOMETRY_V3 = {**GEOMETRY_V2, "view_crop": True}
#: Schema 3 with ``sensor_aspect`` (version 5): the exporter's letterbox geometry.
GEOMETRY_V3_SENSOR = {**GEOMETRY_V3, "sensor_aspect": 4 / 3}
#: Schema 4 (version 6): the same magnifying narrower cameras' frames up to a zoom (cases carry theirs).
GEOMETRY_V4 = {**GEOMETRY_V3_SENSOR, "view_zoom": 1.3}
#: Frame sizes (width, height) for the sensor-aspect FOV vectors: 9:16, 3:4, 1:1, 4:3, 16:9 and
#: extremes (1:10, 1:8 and their landscape twins), a frame just wider than 3:4 and one just narrower.
ASPECT_SIZES = ((1080, 1920), (720, 1280), (480, 640), (3, 4), (600, 640), (479, 640), (480, 480), (640, 480),
                (4, 3), (500, 400), (1920, 1080), (1280, 720), (100, 1000), (1000, 100), (180, 1440), (1440, 180))
#: Canvases (input.size, [H, W]) for the view-crop vectors: the default bundle's 3:4, square, the
#: phone app toy's 1:2, and a tall one.
VIEW_CANVASES = ((168, 224), (224, 224), (24, 48), (320, 240))


def _geometry_scenarios(rng: np.random.Generator) -> list[tuple]:
    """Decision scenarios whose frames have sizes: (name, geometry, overrides, uncertainty,
    steps) with steps (t, yaw, raw outputs, (width, height))."""
    out = []
    one = {"measure": "entropy", "threshold": DecisionConfig().threshold}   # one threshold for both
    for w, h in FRAME_SIZES[:6]:
        steps = [(i / FPS, 0.0, _frame(13, 10 if i < 25 else 3, 0.9, rng), (w, h)) for i in range(40)]
        out.append((f"frames_{w}x{h}", GEOMETRY_V2, {}, one, steps))
    turn = []
    for i in range(90):
        w, h = FRAME_SIZES[(i // 30) % 2]  # landscape, portrait, landscape: the phone turned twice
        turn.append((i / FPS, 0.0, _frame(13, 9, 0.9, rng), (w, h)))
    out.append(("phone_turned_landscape_portrait_landscape", GEOMETRY_V2, {}, one, turn))
    steps = [(i / FPS, 10.0, _frame(13, 11, 0.9, rng), FRAME_SIZES[i // 20 % 2]) for i in range(40)]
    out.append(("user_fov_portrait_60", GEOMETRY_V2, {"portrait": 60.0}, one, steps))
    schema1 = geometry_of({"schema_version": 1, "fov_deg": DEFAULT_FOV_DEG})
    steps = [(i / FPS, 0.0, _frame(13, 2, 0.9, rng), FRAME_SIZES[3]) for i in range(30)]
    out.append(("schema1_portrait", schema1, {}, one, steps))
    # Version 3: a portrait threshold above the landscape one. Frames whose entropy (~1.4 nats)
    # lies between the two: silent while landscape, guided while portrait (own generator, so
    # the vectors above are those of version 2).
    own = np.random.default_rng(3)
    two = {"measure": "entropy", "threshold": 0.8, "portrait_threshold": 1.6}
    steps = [(i / FPS, 0.0, _frame(13, 4, 0.7, own), FRAME_SIZES[(i // 30) % 2]) for i in range(90)]
    out.append(("portrait_threshold_phone_turned", GEOMETRY_V2, {}, two, steps))
    # Version 5: 9:16 video held upright (its crop's FOV, ~41 deg), turned to 16:9 landscape and back.
    own = np.random.default_rng(5)
    sizes = ((1080, 1920), (1920, 1080))
    steps = [(i / FPS, 0.0, _frame(13, 8, 0.9, own), sizes[(i // 30) % 2]) for i in range(90)]
    out.append(("sensor_aspect_9x16_video_turned", GEOMETRY_V3_SENSOR, {}, two, steps))
    # Version 8: a narrow camera's threshold. Frames of entropy ~1.9 nats (between the portrait
    # threshold and the narrow one) speak only while the frame is 9:16 portrait video (~41 deg).
    own = np.random.default_rng(8)
    narrow = {**two, "narrow_threshold": 2.4, "narrow_fov_deg": 45.0}
    sizes = ((1080, 1920), (480, 640), (1920, 1080), (1080, 1920))
    steps = [(i / FPS, 0.0, _frame(13, 4, 0.5, own), sizes[i // 30]) for i in range(120)]
    out.append(("narrow_threshold_9x16_video", GEOMETRY_V3_SENSOR, {}, narrow, steps))
    # Version 17: by the camera's width. Frames whose doubt (~1.4 nats, as version 3's) lies
    # between the landscape and the portrait thresholds speak on a square frame (~53 deg: the
    # portrait threshold), not on 4:3 landscape; and not on 3:4 portrait the user set to 65 deg
    # (the landscape threshold).
    own = np.random.default_rng(17)
    wide = {**narrow, "wide_fov_deg": 60.0}
    sizes = ((480, 480), (640, 480), (1080, 1920), (480, 640))
    steps = [(i / FPS, 0.0, _frame(13, 4, 0.7, own), sizes[i // 30]) for i in range(120)]
    out.append(("wide_fov_square_frame", GEOMETRY_V3_SENSOR, {}, wide, steps))
    steps = [(i / FPS, 0.0, _frame(13, 4, 0.7, own), FRAME_SIZES[1 - i // 30]) for i in range(60)]
    out.append(("wide_fov_portrait_set_wide", GEOMETRY_V3_SENSOR, {"portrait": 65.0}, wide, steps))
    return out


def _run_geometry_scenario(geometry: dict, overrides: dict, uncertainty: dict, steps: list,
                           base: DecisionConfig) -> list[dict]:
    """The app's rule: each step's FOV is camera_fov(frame) and its gate threshold
    gate_threshold(frame, FOV); a new FOV or threshold starts a fresh Decider."""
    rows, decider, now = [], None, None
    for t, yaw, raw, (w, h) in steps:
        fov = camera_fov(geometry, w, h, overrides.get(orientation(w, h)))
        threshold = gate_threshold(uncertainty, w, h, fov)
        if (fov, threshold) != now:
            decider, now = Decider(dataclasses.replace(base, fov_deg=fov, threshold=threshold)), (fov, threshold)
        dec = decider.step(t, raw.observation(base.measure), yaw)
        rows.append({"t": t, "yaw_rate_dps": yaw, "frame": [w, h], "fov_deg": fov, "threshold": threshold,
                     "obs": _obs_json(raw, base.measure), "expect": dec.to_json()})
    return rows


def _fov_choices() -> list[dict]:
    """orientation -> FOV cases: bundle defaults, overrides, schema 1, refused values."""
    schema1 = geometry_of({"schema_version": 1, "fov_deg": DEFAULT_FOV_DEG})
    cases = []
    for geom in (GEOMETRY_V2, schema1):
        for w, h in FRAME_SIZES:
            for override in (None, 60.0, 20.0, 170.0, 19.9, 170.5, 0.0, 200.0):
                row = {"geometry": geom, "frame": [w, h], "override": override, "orientation": orientation(w, h)}
                try:
                    row["fov_deg"] = camera_fov(geom, w, h, override)
                except ValueError:
                    row["fov_deg"] = None  # refused: the runtime plays the stop cue
                cases.append(row)
    odd = {**GEOMETRY_V2, "camera_fov_deg": {"landscape": 80.0, "portrait": 50.0}, "sensor_aspect": 16 / 9}
    square = {**GEOMETRY_V2, "sensor_aspect": 1.0}
    for geom in (GEOMETRY_V2, GEOMETRY_V3_SENSOR, odd, square):   # version 5: with and without sensor_aspect
        for w, h in ASPECT_SIZES:
            for override in (None, 60.0, 19.9):
                row = {"geometry": geom, "frame": [w, h], "override": override, "orientation": orientation(w, h)}
                try:
                    row["fov_deg"] = camera_fov(geom, w, h, override)
                except ValueError:
                    row["fov_deg"] = None
                cases.append(row)
    return cases


def _view_rows_sensor() -> list[dict]:
    """The view crop under :data:`GEOMETRY_V3_SENSOR` (version 5): the per-aspect default FOV
    (or an override) -> the rows the graph sees; frames whose default FOV is refused left out."""
    cases = []
    for w, h in ASPECT_SIZES[:12]:
        for override in (None, 60.0):
            fov = camera_fov(GEOMETRY_V3_SENSOR, w, h, override)
            for canvas in VIEW_CANVASES:
                for train in (67.0, 53.0):
                    top, rows = view_rows(h, w, fov, canvas, train)
                    cases.append({"frame": [w, h], "override": override, "fov_deg": fov, "canvas": list(canvas),
                                  "train_fov_deg": train, "top": top, "rows": rows})
    return cases


def _view_rows_zoom() -> list[dict]:
    """The view crop magnified up to a zoom (version 6): frames of several aspects at the
    per-aspect default FOV (or an override) x canvas x zoom -> the rows the graph sees."""
    cases = []
    for w, h in ASPECT_SIZES[:12]:
        for override in (None, 40.0, 60.0, 100.0):
            fov = camera_fov(GEOMETRY_V4, w, h, override)
            for canvas in VIEW_CANVASES:
                for zoom in (1.0, 1.1, 1.3, 1.7, 4.0):
                    top, rows = view_rows(h, w, fov, canvas, GEOMETRY_V4["train_fov_deg"], zoom)
                    cases.append({"frame": [w, h], "override": override, "fov_deg": fov, "canvas": list(canvas),
                                  "train_fov_deg": GEOMETRY_V4["train_fov_deg"], "zoom": zoom, "top": top, "rows": rows})
    return cases


def _view_rows() -> list[dict]:
    """The view crop (schema 3): frame size x FOV (the orientation's default or an override)
    x canvas x training FOV -> the FOV the frame gets and the rows the graph sees."""
    cases = []
    sizes = FRAME_SIZES + ((9, 8), (8, 9), (640, 1), (1, 640), (1920, 1080), (1080, 1920), (3000, 4000))
    for w, h in sizes:
        for override in (None, 40.0, 53.0, 60.0, 67.0, 100.0, 20.0, 170.0):
            fov = camera_fov(GEOMETRY_V3, w, h, override)
            for canvas in VIEW_CANVASES:
                for train in (67.0, 53.0, 90.0):
                    top, rows = view_rows(h, w, fov, canvas, train)
                    cases.append({"frame": [w, h], "override": override, "fov_deg": fov, "canvas": list(canvas),
                                  "train_fov_deg": train, "top": top, "rows": rows})
    # Values the formula itself is sensitive to: a half-way rounding and fractional degrees.
    for w, h, fov, canvas, train in ((640, 480, 67.0, (168, 224), 67.0), (642, 600, 67.0, (168, 224), 67.0),
                                     (480, 640, 53.3, (168, 224), 66.7), (720, 1280, 52.25, (168, 224), 67.0),
                                     (3, 100, 169.9, (16, 4096), 20.1), (4096, 4096, 20.0, (4096, 16), 170.0)):
        top, rows = view_rows(h, w, fov, canvas, train)
        cases.append({"frame": [w, h], "override": fov, "fov_deg": camera_fov(GEOMETRY_V3, w, h, fov),
                      "canvas": list(canvas), "train_fov_deg": train, "top": top, "rows": rows})
    return cases


def _guards(rng: np.random.Generator) -> dict:
    """Frozen-frame, freshness and watchdog vectors (the live loop's guards)."""
    a = rng.integers(0, 256, size=(9, 15, 3), dtype=np.uint8)
    off_grid = a.copy()
    off_grid[4, 5, 1] ^= 1  # a pixel a 7-stride sample would miss: the frames still differ
    on_grid = a.copy()
    on_grid[7, 7, 2] ^= 1
    rotated = np.ascontiguousarray(a.transpose(1, 0, 2))

    def frame(x: np.ndarray | None) -> dict | None:
        return None if x is None else {"width": int(x.shape[1]), "height": int(x.shape[0]),
                                       "rgb": [int(v) for v in x.reshape(-1)]}

    pairs = [(None, a), (a, a.copy()), (a, off_grid), (a, on_grid), (a, rotated), (a, a[:, :14].copy())]
    same = [{"prev": frame(p), "cur": frame(c), "same": bool(same_frame(p, c))} for p, c in pairs]
    fresh = [{"now": n, "captured": c, "watchdog_s": w, "fresh": is_fresh(n, c, w)}
             for n, c, w in ((1.0, 0.9, 0.5), (1.0, 0.5, 0.5), (1.0, 0.49, 0.5), (2.0, 2.0, 0.5), (3.3, 3.0, 0.3),
                             (3.31, 3.0, 0.3))]
    clock = [0.0]
    dog = Watchdog(DEFAULT_WATCHDOG_S, lambda: None, clock=lambda: clock[0])
    ops = []
    script = [("poll", 0.1), ("beat", 0.2), ("poll", 0.6), ("poll", 0.71), ("poll", 0.75), ("poll", 1.0),
              ("beat", 1.05), ("poll", 1.1), ("poll", 1.56), ("beat", 1.6), ("poll", 2.0), ("poll", 2.2)]
    for op, t in script:
        clock[0] = t
        if op == "beat":
            dog.beat(t)
            ops.append({"op": "beat", "t": t})
        else:
            fired_before = dog.fired
            stale = dog.poll()
            ops.append({"op": "poll", "t": t, "stale": stale, "fired": dog.fired > fired_before})
    return {"same_frame": same, "fresh": fresh, "watchdog": {"period_s": DEFAULT_WATCHDOG_S, "start": 0.0, "ops": ops}}


def _status_vectors() -> list[dict]:
    out = []
    for reason in STATUS_STOP:   # every stop reason the app can show, the tilts included
        text, cls = status_message(True, reason, None)
        out.append({"stop": True, "reason": reason, "heading_deg": None, "text": text, "cls": cls})
    for h in (0.0, -7.4999, 7.5, -7.5, 12.0, -22.4999, 22.5, -22.5, 40.0, -80.0):
        text, cls = status_message(False, "ok", h)
        out.append({"stop": False, "reason": "ok", "heading_deg": h, "text": text, "cls": cls})
    return out


def _config_json(cfg: DecisionConfig) -> dict:
    return dataclasses.asdict(cfg)


def _obs_json(raw: RawOutputs | None, measure: str) -> dict | None:
    if raw is None:
        return None
    obs = raw.observation(measure)
    return {**raw.to_json(), "uncertainty": obs.uncertainty if math.isfinite(obs.uncertainty) else None}


def _texture(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A smooth random grey texture (h x w, 0..255): noise blurred along both axes."""
    x = rng.uniform(0, 255, (h + 4, w + 4))
    for axis in (0, 1):
        x = (np.roll(x, 1, axis) + 2 * x + np.roll(x, -1, axis)) / 4
    return x[2:-2, 2:-2]


def _visual_yaw_vectors(rng: np.random.Generator) -> dict:
    """Version 12: the visual yaw estimator's thumbnails, shifts and one stream of frames."""
    def rgb(a: np.ndarray) -> dict:
        return {"width": int(a.shape[1]), "height": int(a.shape[0]), "rgb": a.reshape(-1).tolist()}

    thumbs = []
    for (h, w), width in (((7, 11), 4), ((13, 9), 4), ((6, 6), 8), ((20, 30), 7)):
        f = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        thumbs.append({"frame": rgb(f), "width": width, "thumb": vy.thumbnail(f, width).tolist()})
    base = np.round(_texture(rng, 14, 40))
    edges_only = base[:, 8:32].copy()
    edges_only[:, 6:18] = 120.0      # textured sides, a flat middle: the template cannot tell
    bus = base[:, 8:32].copy()
    bus[5:, 2:22] = base[5:, 15:35]  # a still camera; its lower two thirds (a bus) moved 5 px
    # version 18: stripes 7 px apart moved 2 px: 5 px the other way matches as well (no draws)
    xs, ys = np.arange(40), np.arange(14)[:, None]
    stripes = 128 + 60 * np.sign(np.sin(2 * np.pi * (xs + 0.5) / 7))[None, :] + 0 * ys
    wobble = np.round(6 * np.sin(ys * 2.3 + xs[None, :24] * 1.7))
    shifts = []
    for name, prev, cur in (
            ("right_3", base[:, 8:32], base[:, 11:35]), ("left_5", base[:, 8:32], base[:, 3:27]),
            ("half_pixel", base[:, 8:32], (base[:, 9:33] + base[:, 10:34]) / 2),
            ("down_1_right_2", base[1:13, 8:32], base[2:14, 10:34]),
            ("still", base[:, 8:32], base[:, 8:32] + 0.5), ("flat", np.full((14, 24), 90.0), np.full((14, 24), 91.0)),
            ("flat_middle", edges_only, edges_only), ("part_moved", base[:, 8:32], bus),
            ("new_scene", base[:, 8:32], np.round(_texture(rng, 14, 24))), ("sizes_differ", base[:, 8:32], base[:, 8:30]),
            ("stripes_a_period_off", np.round(stripes[:, 8:32]), np.round(stripes[:, 10:34] + wobble))):
        s = vy.shift_between(prev, cur)
        shifts.append({"name": name, "prev": prev.tolist(), "cur": cur.tolist(), "shift": s})
    scene = np.stack([_texture(rng, 24, 90)] * 3, axis=2)
    scene[..., 1] *= 0.8      # channels differ: the thumbnail is the mean of R, G, B
    width, seq, yaw = 16, [], vy.VisualYaw(16)      # frames 48 wide: a thumbnail pixel is 3 of theirs
    for t, x0, fov in ((0.0, 30, 60.0), (0.1, 33, 60.0), (0.2, 39, 60.0), (0.3, 36, 60.0), (0.4, None, 60.0),
                       (0.5, 36, 60.0), (0.6, 30, 60.0), (0.7, 30, None), (0.8, 30, 60.0), (0.81, 24, 60.0),
                       (0.9, 29, 60.0)):
        frame = None if x0 is None else np.clip(scene[:, x0:x0 + 48], 0, 255).astype(np.uint8)
        if t == 0.9:
            frame = np.clip(scene[:, 29:29 + 36], 0, 255).astype(np.uint8)    # a new size: afresh
        seq.append({"t": t, "fov_deg": fov, "frame": None if frame is None else rgb(frame),
                    "yaw_rate_dps": yaw.update(frame, t, fov)})
    return {"thumb_width": vy.THUMB_WIDTH, "dy": vy.DY, "min_texture": vy.MIN_TEXTURE, "max_match": vy.MAX_MATCH,
            "min_shift": vy.MIN_SHIFT, "tiles": vy.TILES, "tile_veto": vy.TILE_VETO, "ambiguous": vy.AMBIGUOUS,
            "max_turn_dps": vy.MAX_TURN_DPS, "thumbnails": thumbs, "shifts": shifts,
            "sequence": {"width": width, "steps": seq}}


def _turned_vectors(play=turned, turns=(-20.0, -5.0, -1.0, 0.0, 1.0, 3.0, 7.5, 40.0)) -> list[dict]:
    """Step 10 (:func:`turned`, or ``play``): a decision's heading and pan once the camera turned
    since its capture, inside the frame and in either edge strip, turned towards (within the strip
    and out of it) and away, and a stop."""
    d0 = Decider(DecisionConfig()).step(0.0, Observation(_probs_for(13, 6, 0.9), 0.1), 0.0)
    cases = []
    for fov in (67.0, 40.8):
        for h in (None, -31.0, -25.0, -10.0, 0.0, 12.5, 17.9, 33.4, 60.0):
            d = dataclasses.replace(d0, stop=h is None, reason=REASON_UNCERTAIN if h is None else d0.reason,
                                    heading_deg=h, pan=None if h is None else heading_to_pan(h, fov / 2))
            for turn in turns:
                t = play(d, turn, fov)
                cases.append({"stop": d.stop, "reason": d.reason, "heading_deg": h, "pan": d.pan, "turn_deg": turn,
                              "fov_deg": fov, "expect": {"stop": t.stop, "reason": t.reason, "heading_deg": t.heading_deg,
                                                         "pan": t.pan}})
    return cases


def build_vectors(seed: int = 20240601) -> dict:
    """All scenarios and beacon vectors as one JSON-ready dict."""
    rng = np.random.default_rng(seed)
    scenarios = []
    for name, cfg, steps in _scenarios(rng):
        d = Decider(cfg)
        rows = []
        for t, yaw, raw in steps:
            dec = d.step(t, None if raw is None else raw.observation(cfg.measure), yaw)
            rows.append({"t": t, "yaw_rate_dps": yaw, "obs": _obs_json(raw, cfg.measure), "expect": dec.to_json()})
        scenarios.append({"name": name, "config": _config_json(cfg), "steps": rows})
    base = DecisionConfig()
    for name, geom, overrides, unc, steps in _geometry_scenarios(rng):
        scenarios.append({"name": name, "config": _config_json(base), "geometry": geom, "fov_override": overrides,
                          "uncertainty": unc, "steps": _run_geometry_scenario(geom, overrides, unc, steps, base)})
    bcfg = BeaconConfig()
    pans = [-1.0, -0.5, -0.1, 0.0, 0.3, 0.77, 1.0]
    headings = [-80.0, -45.0, -12.5, 0.0, 7.5, 30.0, 60.0]
    return {
        "version": VERSION,
        "generator": "python -m crossing_assist.testing.vectors",
        "tolerance": 1e-9,
        "spec": "docs/runtime.md (Decision logic)",
        "scenarios": scenarios,
        "beacon": {
            "config": dataclasses.asdict(bcfg),
            "pan_gains": [{"pan": p, "left": pan_gains(p)[0], "right": pan_gains(p)[1]} for p in pans],
            "itd_seconds": [{"heading_deg": h, "itd_s": itd_seconds(h)} for h in headings],
            "heading_to_pan": [{"heading_deg": h, "fov_deg": DEFAULT_FOV_DEG, "pan": heading_to_pan(h, DEFAULT_FOV_DEG / 2)}
                               for h in headings],
            "loop_samples": [{"rate_hz": r, "samples": round(bcfg.sample_rate / r)} for r in (2.0, 3.3, 4.0, 6.0)],
        },
        "actions": {str(n): [list(g) for g in get_space(n).groups] for n in (4, 8, 13)},
        "guards": _guards(rng),
        "status": _status_vectors(),
        "turned": _turned_vectors(),
        # half a strip: 2.79 deg at 67 deg across, 1.7 deg at 40.8
        "stale": _turned_vectors(stale, (-20.0, -2.9, -1.6, 0.0, 1.6, 1.8, 2.7, 2.9, 40.0)),
        "visual_yaw": _visual_yaw_vectors(np.random.default_rng([seed, 12])),
        "geometry": {"fov_range_deg": list(FOV_RANGE_DEG), "fov_choice": _fov_choices(),
                     "view_rows": {"geometry": GEOMETRY_V3, "cases": _view_rows()},
                     "view_rows_sensor": {"geometry": GEOMETRY_V3_SENSOR, "cases": _view_rows_sensor()},
                     "view_rows_zoom": {"geometry": GEOMETRY_V4, "cases": _view_rows_zoom()},
                     # how far a rolled camera's frame is turned back (geometry.level_angle), and the fill
                     "level": {"pad_rgb": list(PAD_RGB), "cases": [{"roll_deg": r, "angle_deg": level_angle(r),
                                                                     "too_far": rolled_too_far(r)} for r in
                                                                    (None, 0.0, 0.3, -0.49, 0.5, 7.25, -12.0, 44.9, 45.0,
                                                                     60.0, 60.5, -60.5, -90.0)]}},
    }


def write_vectors(path: str | Path, seed: int = 20240601) -> Path:
    """Write the vectors JSON atomically; returns the path."""
    return atomic_write_text(path, json.dumps(build_vectors(seed), allow_nan=False) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m crossing_assist.testing.vectors", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("android_demo/test_vectors.json"))
    ap.add_argument("--seed", type=int, default=20240601)
    a = ap.parse_args(argv)
    try:
        path = write_vectors(a.out, a.seed)
    except OSError as exc:
        print(f"error: cannot write {a.out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    n = sum(len(s["steps"]) for s in json.loads(path.read_text())["scenarios"])
    print(f"wrote {path} ({n} decision steps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
