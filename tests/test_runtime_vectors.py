"""The shared decision vectors (android_demo/test_vectors.json) are current and replayable from
their JSON alone, which is all the phone app gets."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from crossing_assist.runtime import belief as bf
from crossing_assist.runtime.decide import Decider, DecisionConfig, Observation, edge_side, turned_out_of_edge
from crossing_assist.runtime.gate import GateConfig
from crossing_assist.runtime.live import is_fresh, same_frame
from crossing_assist.geometry import view_rows
from crossing_assist.runtime.camera import camera_fov, gate_threshold
from crossing_assist.testing.vectors import (
    VERSION,
    ASPECT_SIZES,
    FRAME_SIZES,
    GEOMETRY_V2,
    GEOMETRY_V3_SENSOR,
    VIEW_CANVASES,
    build_vectors,
    main,
)

VECTORS = Path(__file__).resolve().parents[1] / "android_demo" / "test_vectors.json"


@pytest.fixture(scope="module")
def stored():
    if not VECTORS.is_file():
        pytest.fail(f"{VECTORS} is missing; run python -m crossing_assist.testing.vectors")
    return json.loads(VECTORS.read_text())


def test_stored_vectors_match_the_current_logic(stored):
    fresh = json.loads(json.dumps(build_vectors()))
    assert _same(fresh, stored, 1e-9), "decision logic changed: regenerate android_demo/test_vectors.json"


def _same(a, b, tol) -> bool:
    """Equal JSON trees, floats within ``tol`` (last-bit libm differences across platforms)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k], tol) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same(x, y, tol) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=tol, abs_tol=tol)
    return a == b


def _config(d: dict) -> DecisionConfig:
    d = dict(d)
    d["filter"] = bf.FilterConfig(**d["filter"])
    d["gate"] = GateConfig(**d["gate"])
    return DecisionConfig(**d)


def _close(a, b, tol):
    if isinstance(a, list):
        return len(a) == len(b) and all(_close(x, y, tol) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return a is not None and b is not None and math.isclose(a, b, rel_tol=tol, abs_tol=tol)
    return a == b


def test_vectors_replay_from_json_alone(stored):
    kinds = set()
    for sc in stored["scenarios"]:
        d = Decider(_config(sc["config"]))
        now = None
        for row in sc["steps"]:
            if "frame" in row:   # the FOV and gate threshold of the frame's orientation and FOV (versions 3, 8)
                threshold = gate_threshold(sc["uncertainty"], *row["frame"], row["fov_deg"])
                assert threshold == row["threshold"]
                if (row["fov_deg"], threshold) != now:   # the phone turned: a fresh Decider
                    now = (row["fov_deg"], threshold)
                    d = Decider(dataclasses.replace(_config(sc["config"]), fov_deg=row["fov_deg"], threshold=threshold))
            o = row["obs"]
            obs = None
            if o is not None and o["ok"]:  # the port starts from the graph's raw outputs
                measure = sc["config"]["measure"]
                u = (o["entropy"] if measure == "entropy" else o["mutual_info"] if measure == "mutual_info"
                     else bf.far_mass(np.array(o["probs"])) if measure == "far_mass"
                     else o["variance"][int(np.argmax(o["probs"]))])
                assert u == o["uncertainty"]
                obs = Observation(np.array(o["probs"]), u)
            elif o is not None:
                obs = Observation(None, math.inf, ok=False)
            got = d.step(row["t"], obs, row["yaw_rate_dps"]).to_json()
            for key, want in row["expect"].items():
                assert _close(got[key], want, stored["tolerance"]), (sc["name"], row["t"], key)
            kinds.add((row["expect"]["gate"], row["expect"]["reason"]))
    # the vectors exercise every gate state and every stop reason
    turned = next(sc for sc in stored["scenarios"] if sc["name"] == "portrait_threshold_phone_turned")
    by_orientation = {(row["frame"][1] > row["frame"][0], row["expect"]["stop"]) for row in turned["steps"][10:]}
    assert (True, False) in by_orientation and (False, False) not in by_orientation  # guided only in portrait
    assert {("learner", "ok"), ("hold", "ok"), ("stop", "uncertain"), ("stop", "stale"), ("stop", "failed")} <= kinds


def test_narrow_camera_vectors_speak_only_at_the_narrow_threshold(stored):
    """Version 8: 9:16 portrait video (~41 deg, at most narrow_fov_deg) gets narrow_threshold,
    a 3:4 frame (53 deg) the portrait one and landscape its own; frames whose doubt lies between
    the portrait and the narrow thresholds are guided only while the video is 9:16."""
    sc = next(sc for sc in stored["scenarios"] if sc["name"] == "narrow_threshold_9x16_video")
    unc = sc["uncertainty"]
    by_frame = {tuple(r["frame"]): r["threshold"] for r in sc["steps"]}
    assert by_frame == {(1080, 1920): unc["narrow_threshold"], (480, 640): unc["portrait_threshold"],
                        (1920, 1080): unc["threshold"]}
    assert all(unc["portrait_threshold"] < r["obs"]["uncertainty"] < unc["narrow_threshold"] for r in sc["steps"])
    guided = {(tuple(r["frame"]), not r["expect"]["stop"]) for i, r in enumerate(sc["steps"]) if i % 30 >= 10}
    assert guided == {((1080, 1920), True), ((480, 640), False), ((1920, 1080), False)}


def test_wide_fov_vectors_pick_the_threshold_by_the_cameras_width(stored):
    """Version 17: with ``wide_fov_deg`` a square frame (~53 deg) takes the portrait threshold, 4:3
    the landscape one, 9:16 video the narrow one, and a 3:4 frame set to 65 deg the landscape one;
    frames whose doubt lies between the landscape and portrait thresholds guide only on the
    frames under 60 deg."""
    sc = next(sc for sc in stored["scenarios"] if sc["name"] == "wide_fov_square_frame")
    unc = sc["uncertainty"]
    assert {tuple(r["frame"]): r["threshold"] for r in sc["steps"]} == {
        (480, 480): unc["portrait_threshold"], (640, 480): unc["threshold"],
        (1080, 1920): unc["narrow_threshold"], (480, 640): unc["portrait_threshold"]}
    assert all(unc["threshold"] < r["obs"]["uncertainty"] < unc["portrait_threshold"] for r in sc["steps"])
    guided = {(tuple(r["frame"]), not r["expect"]["stop"]) for i, r in enumerate(sc["steps"]) if i % 30 >= 10}
    assert guided == {((480, 480), True), ((640, 480), False), ((1080, 1920), True), ((480, 640), True)}
    wide = next(sc for sc in stored["scenarios"] if sc["name"] == "wide_fov_portrait_set_wide")
    assert {(tuple(r["frame"]), r["fov_deg"], r["threshold"]) for r in wide["steps"]} == {
        ((480, 640), 65.0, unc["threshold"]), ((640, 480), 67.0, unc["threshold"])}
    assert all(r["expect"]["stop"] for r in wide["steps"])


def test_no_direction_from_before_a_stall_comes_back(stored):
    """Version 10, step 4a: guided before a 1 s stall; when frames showing nothing come back,
    the beacon stays off (the hold and belief from before the stall put the old heading back on
    for 0.2-0.4 s: a stale direction after the stop cue)."""
    sc = next(sc for sc in stored["scenarios"] if sc["name"] == "stall_then_nothing")
    steps = sc["steps"]
    assert not steps[19]["expect"]["stop"]                        # guided before the stall
    assert any(r["expect"]["reason"] == "stale" for r in steps)   # the stall was noticed
    after = [r for r in steps if r["obs"] is not None and r["t"] > steps[19]["t"]]
    assert after and all(r["expect"]["stop"] and r["expect"]["hold_heading"] is None for r in after)


def test_a_turn_without_yaw_input_does_not_keep_the_old_direction(stored):
    """Version 11, step 4b: guided at strip 9, then unsure frames see the goal at strip 3 with no
    yaw input: the hold is dropped (it played strip 9's heading for 1.5 s) and guidance stops."""
    steps = next(sc for sc in stored["scenarios"] if sc["name"] == "pan_without_yaw_input")["steps"]
    assert not steps[29]["expect"]["stop"]
    after = [r["expect"] for r in steps[30:]]
    assert all(e["hold_heading"] is None and e["gate"] != "hold" for e in after)
    assert after[-1]["stop"]


def test_turned_cases_move_by_the_turn_or_half_of_it_towards_an_edge(stored):
    """Versions 14-15, step 10: the stored cases hold whole turns, half turns (an edge strip turned
    towards, within it), stops for an edge strip turned towards out of it, beyond-the-view pans and
    stops, so a port is checked on each branch."""
    cases = stored["turned"]
    moved = {"whole": 0, "half": 0, "stop": 0, "turned_out": 0, "saturated": 0}
    for c in cases:
        e = c["expect"]
        if c["heading_deg"] is None:
            assert e["heading_deg"] is None and e["pan"] is None and e["stop"] and c["stop"]
            moved["stop"] += 1
            continue
        side = edge_side(c["heading_deg"], c["fov_deg"])
        if turned_out_of_edge(side, c["heading_deg"] - c["turn_deg"], c["turn_deg"], c["fov_deg"]):
            assert e == {"stop": True, "reason": "uncertain", "heading_deg": None, "pan": None}, c
            moved["turned_out"] += 1
            continue
        assert not e["stop"] and e["reason"] == c["reason"] == "ok"
        delta = c["heading_deg"] - e["heading_deg"]
        assert delta == pytest.approx(c["turn_deg"]) or delta == pytest.approx(c["turn_deg"] / 2)
        moved["half" if c["turn_deg"] and delta == pytest.approx(c["turn_deg"] / 2) else "whole"] += 1
        moved["saturated"] += abs(e["pan"]) == 1.0
    assert all(n > 0 for n in moved.values()), moved


def test_stale_cases_play_as_decided_within_half_a_strip_and_stop_beyond(stored):
    """Version 16, step 10 without the turn's sign: the heading never moves; past half a strip of
    turn, either way, the decision is a stop; the cases hold both sides of the line at both FOVs."""
    seen = {"kept": 0, "stopped": 0}
    for c in stored["stale"]:
        e = c["expect"]
        if c["heading_deg"] is not None and abs(c["turn_deg"]) > c["fov_deg"] / 12 / 2:
            assert e == {"stop": True, "reason": "uncertain", "heading_deg": None, "pan": None}, c
            seen["stopped"] += 1
        else:
            assert (e["stop"], e["heading_deg"], e["pan"]) == (c["stop"], c["heading_deg"], c["pan"]), c
            seen["kept"] += c["heading_deg"] is not None and c["turn_deg"] != 0
    assert all(n > 0 for n in seen.values()), seen
    assert {c["fov_deg"] for c in stored["stale"]} == {67.0, 40.8}


def test_cli_writes_the_file(tmp_path, capsys):
    assert main(["--out", str(tmp_path / "v.json")]) == 0
    assert json.loads((tmp_path / "v.json").read_text())["version"] == VERSION == 18
    assert "decision steps" in capsys.readouterr().out


def test_geometry_scenarios_cover_both_orientations_and_several_aspects(stored):
    frames = {tuple(row["frame"]) for sc in stored["scenarios"] for row in sc["steps"] if "frame" in row}
    portrait = {f for f in frames if f[1] > f[0]}
    assert len(portrait) >= 3 and len(frames - portrait) >= 3, frames
    fovs = {row["fov_deg"] for sc in stored["scenarios"] for row in sc["steps"] if "frame" in row}
    assert {67.0, 53.0, 60.0, 90.0} <= fovs
    refused = [c for c in stored["geometry"]["fov_choice"] if c["fov_deg"] is None]
    assert refused and all(c["override"] is not None and not 20 <= c["override"] <= 170 for c in refused
                           if "sensor_aspect" not in c["geometry"] or c["override"] is not None)
    # without an override, only a crop narrower than 20 degrees (1:8 and beyond, portrait) is refused
    assert {tuple(c["frame"]) for c in refused if c["override"] is None} == {(100, 1000), (180, 1440)}


def _documented_rows(c: dict) -> int:
    """A view-rows case's rows by the formula in docs (geometry.view_rows), from its JSON alone."""
    (w, h), (ch, cw) = c["frame"], c["canvas"]
    t = max(1.0, math.tan(math.radians(c["train_fov_deg"]) / 2) / math.tan(math.radians(c["fov_deg"]) / 2)
            / c.get("zoom", 1.0))
    full = max(1, math.floor(w * ch * t / cw + 0.5))
    return full if t > 1 and full > h + h // 50 else min(h, full)


def test_view_crop_vectors_cover_orientations_aspects_and_fovs(stored):
    """Version 4: the view crop's rows for portrait and landscape frames of several aspects, the
    orientation's default FOV and overrides, every canvas; each case replays from its JSON alone
    with the formula in docs (the integers a port must reproduce exactly)."""

    section = stored["geometry"]["view_rows"]
    assert section["geometry"]["view_crop"] is True and section["geometry"]["fit"] == "letterbox"
    cases = section["cases"]
    frames = {tuple(c["frame"]) for c in cases}
    assert set(FRAME_SIZES) <= frames
    assert set(VIEW_CANVASES) <= {tuple(c["canvas"]) for c in cases}
    defaults = {(c["frame"][1] > c["frame"][0], c["fov_deg"]) for c in cases if c["override"] is None}
    assert defaults == {(False, 67.0), (True, 53.0)}            # each orientation's default FOV
    assert {60.0, 100.0, 20.0, 170.0} <= {c["override"] for c in cases}
    cropped = {(c["frame"][1] > c["frame"][0]) for c in cases if c["rows"] < c["frame"][1]}
    assert cropped == {True, False}                             # portrait and landscape frames lose rows
    for c in cases:
        w, h = c["frame"]
        assert [c["top"], c["rows"]] == list(view_rows(h, w, c["fov_deg"], tuple(c["canvas"]), c["train_fov_deg"]))
        assert c["rows"] == _documented_rows(c)
        assert c["top"] == (h - c["rows"]) // 2
    padded = {(c["frame"][1] > c["frame"][0]) for c in cases if c["rows"] > c["frame"][1]}
    assert False in padded                                      # landscape frames set narrower are padded


def test_view_zoom_vectors_magnify_narrow_frames_up_to_their_zoom(stored):
    """Version 6 (schema 4's geometry.view_zoom): each case replays from its JSON with the formula
    in docs; zoom 1 is the view crop's own rows, a portrait phone keeps fewer rows the larger the
    zoom until a 4:3 band fills the canvas, and a landscape frame at the training FOV never changes."""
    section = stored["geometry"]["view_rows_zoom"]
    assert section["geometry"]["view_zoom"] > 1 and section["geometry"]["view_crop"] is True
    cases = section["cases"]
    assert {1.0, 4.0} < {c["zoom"] for c in cases}
    for c in cases:
        w, h = c["frame"]
        assert c["rows"] == _documented_rows(c)
        assert c["top"] == (h - c["rows"]) // 2
        if c["zoom"] == 1.0:
            assert [c["top"], c["rows"]] == list(view_rows(h, w, c["fov_deg"], tuple(c["canvas"]), c["train_fov_deg"]))
    phone = sorted((c["zoom"], c["rows"]) for c in cases
                   if c["frame"] == [480, 640] and c["override"] is None and c["canvas"] == [168, 224])
    assert [r for _, r in phone] == sorted((r for _, r in phone), reverse=True) and phone[0][1] > phone[-1][1] == 360
    assert {c["rows"] for c in cases if c["frame"] == [640, 480] and c["override"] is None
            and c["canvas"] == [168, 224]} == {480}


def test_sensor_aspect_vectors_give_crops_their_fov(stored):
    """Version 5: with sensor_aspect the default FOV of a frame narrower than the sensor is its
    crop's (9:16 -> ~41 deg, 1:1 -> ~52.8), the full sensor's and wider frames keep theirs, an
    override wins; without the field every frame of an orientation gets the same default."""
    choice = stored["geometry"]["fov_choice"]
    by = {(c["geometry"].get("sensor_aspect"), tuple(c["frame"]), c["override"]): c["fov_deg"] for c in choice
          if c["geometry"]["camera_fov_deg"] == GEOMETRY_V2["camera_fov_deg"] and tuple(c["frame"]) in ASPECT_SIZES}
    s = GEOMETRY_V3_SENSOR["sensor_aspect"]
    assert by[(s, (1080, 1920), None)] == pytest.approx(41.005, abs=1e-3) and by[(None, (1080, 1920), None)] == 53.0
    assert by[(s, (480, 480), None)] == pytest.approx(52.801, abs=1e-3)
    for frame, fov in (((480, 640), 53.0), ((600, 640), 53.0), ((640, 480), 67.0), ((1920, 1080), 67.0)):
        assert by[(s, frame, None)] == fov == by[(None, frame, None)]
    assert all(by[(s, f, 60.0)] == 60.0 for f in ASPECT_SIZES)
    assert {c["fov_deg"] for c in choice if c["override"] is None and "sensor_aspect" not in c["geometry"]
            and c["geometry"]["camera_fov_deg"] == GEOMETRY_V2["camera_fov_deg"]} == {67.0, 53.0}
    turned = next(sc for sc in stored["scenarios"] if sc["name"] == "sensor_aspect_9x16_video_turned")
    assert {(tuple(r["frame"]), round(r["fov_deg"], 3)) for r in turned["steps"]} == {((1080, 1920), 41.005),
                                                                                       ((1920, 1080), 67.0)}
    section = stored["geometry"]["view_rows_sensor"]
    assert section["geometry"] == GEOMETRY_V3_SENSOR
    for c in section["cases"]:
        w, h = c["frame"]
        assert c["fov_deg"] == pytest.approx(camera_fov(section["geometry"], w, h, c["override"]), rel=1e-12)
        assert [c["top"], c["rows"]] == list(view_rows(h, w, c["fov_deg"], tuple(c["canvas"]), c["train_fov_deg"]))
    v916 = next(c for c in section["cases"] if c["frame"] == [1080, 1920] and c["override"] is None
                and c["canvas"] == [168, 224] and c["train_fov_deg"] == 67.0)
    assert 1080 / v916["rows"] == pytest.approx(3 / 4, abs=0.01)          # a 3:4 view, not a square


def test_fov_rule_matches_the_geometry_module():
    """One truth: the vectors' reference FOV choice is the bundle geometry's (where it exists)."""
    geometry = pytest.importorskip("crossing_assist.geometry", reason="crossing_assist.geometry not merged yet")
    cam = (GEOMETRY_V2["camera_fov_deg"]["landscape"], GEOMETRY_V2["camera_fov_deg"]["portrait"])
    for geom, g in ((GEOMETRY_V2, geometry.Geometry(camera_fov_deg=cam)),
                    (GEOMETRY_V3_SENSOR, geometry.Geometry(camera_fov_deg=cam, sensor_aspect=4 / 3))):
        for w, h in FRAME_SIZES + ASPECT_SIZES:
            for override in (None, 60.0, 19.0, 171.0):
                try:
                    want = g.camera_fov(w, h, override)
                except ValueError:
                    want = None
                try:
                    got = camera_fov(geom, w, h, override)
                except ValueError:
                    got = None
                assert got == want, (w, h, override)


def test_guard_vectors_follow_the_live_loop(stored):
    g = stored["guards"]
    rows = g["same_frame"]
    assert [r["same"] for r in rows] == [False, True, False, False, False, False]  # any changed byte counts
    a = np.array(rows[1]["prev"]["rgb"], np.uint8).reshape(rows[1]["prev"]["height"], rows[1]["prev"]["width"], 3)
    assert same_frame(a, a.copy()) and not same_frame(None, a)
    assert all(is_fresh(r["now"], r["captured"], r["watchdog_s"]) == r["fresh"] for r in g["fresh"])
    assert sum(op.get("fired", False) for op in g["watchdog"]["ops"]) == 3
