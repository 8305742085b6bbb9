"""The runtime follows the camera (issue 12): the FOV of the frame's orientation (or the
user's setting) turns strips into headings; a turn between portrait and landscape starts the
belief afresh; frames the model cannot see give the stop cue; crossing-demo --fov."""

import json
import subprocess
import sys

import numpy as np
import pytest
from runtime_toy import LANDSCAPE_FOV, PORTRAIT_FOV, TOY2, bar_frame, make_toy_bundle, toy_bundle  # noqa: F401  (fixture)

from crossing_assist.actions import bin_center_x, get_space, heading_to_x, x_to_bin
from crossing_assist.bundle import BundleError, read_bundle
from crossing_assist.runtime.beacon import KIND_BEACON, KIND_STOP
from crossing_assist.runtime.belief import belief_heading
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.pipeline import Pipeline

DEMO = [sys.executable, "-m", "crossing_assist.runtime.demo"]
STRIP = 11                                      # near the edge: a wrong FOV moves the heading a strip or two


@pytest.fixture(scope="module")
def toy2(tmp_path_factory):
    return make_toy_bundle(tmp_path_factory.mktemp("toy2") / "bundle", TOY2)


def _landscape(x=bin_center_x(STRIP)):
    return bar_frame(x, h=72, w=96)


def _portrait(x=bin_center_x(STRIP)):
    return bar_frame(x, h=128, w=96)


def test_engine_reports_the_orientations_fov_and_headings_use_it(toy2):
    eng = Engine(toy2)
    space = eng.space
    for frame, fov in ((_landscape(), LANDSCAPE_FOV), (_portrait(), PORTRAIT_FOV)):
        p = eng.predict(frame)
        assert p.ok and p.fov_deg == fov
        assert space.action_bins(p.action) == (STRIP,)
        assert p.heading_deg == pytest.approx(space.action_heading(p.action, fov))
        assert x_to_bin(heading_to_x(p.heading_deg, fov)) == STRIP       # back to the bar's strip
    # the two FOVs really give different headings for the same strip
    assert abs(space.action_heading(STRIP, LANDSCAPE_FOV) - space.action_heading(STRIP, PORTRAIT_FOV)) > 5


def test_engine_fov_override_applies_to_both_orientations_and_is_checked(toy2):
    eng = Engine(toy2, fov_deg=60.0)
    assert eng.predict(_landscape()).fov_deg == 60.0 == eng.predict(_portrait()).fov_deg
    assert eng.decision_config().fov_deg == 60.0
    assert Engine(toy2).decision_config().fov_deg == LANDSCAPE_FOV
    for bad in (10.0, 171.0):
        with pytest.raises(BundleError) as e:
            Engine(toy2, fov_deg=bad)
        assert "\n" not in str(e.value) and "20..170" in str(e.value)


def test_schema1_bundle_uses_its_one_fov_in_both_orientations(toy_bundle):  # noqa: F811
    eng = Engine(toy_bundle)
    assert eng.predict(_landscape()).fov_deg == 90.0 == eng.predict(_portrait()).fov_deg


def _run(pipe, frames, t0=0.0, fps=10.0):
    return [pipe.step(f, t0 + i / fps) for i, f in enumerate(frames)]


def test_pipeline_resets_the_belief_when_the_orientation_flips(toy2):
    pipe = Pipeline(Engine(toy2))
    steps = _run(pipe, [_landscape()] * 10)
    assert pipe.decider.cfg.fov_deg == LANDSCAPE_FOV
    assert int(np.argmax(steps[-1].decision.belief)) == STRIP and steps[-1].cue.kind == KIND_BEACON
    # a landscape frame with no crossing keeps the belief (same camera geometry)
    same = _run(pipe, [bar_frame(None, 72, 96)], t0=1.0)[0]
    assert int(np.argmax(same.decision.belief)) == STRIP and max(same.decision.belief) > 0.5
    # turned to portrait, also no crossing: the old strips mean other directions -> start afresh
    flip = _run(pipe, [bar_frame(None, 128, 96)], t0=1.1)[0]
    assert pipe.decider.cfg.fov_deg == PORTRAIT_FOV
    assert max(flip.decision.belief) < 0.2 and flip.cue.kind == KIND_STOP
    # portrait frames with the bar: a portrait heading, on the bar's strip
    steps = _run(pipe, [_portrait()] * 10, t0=1.2)
    d = steps[-1].decision
    assert steps[-1].cue.kind == KIND_BEACON
    assert x_to_bin(heading_to_x(d.heading_deg, PORTRAIT_FOV)) == STRIP


def test_a_failed_frame_at_a_new_fov_or_a_refused_size_starts_the_belief_afresh(toy2):
    """As the app (app.js step): the FOV is the frame's size's, known before the model runs, so a
    portrait frame rolled too far to level already starts the portrait belief; a frame whose FOV
    cannot be known makes the next good frame start afresh, as a first frame would."""
    eng = Engine(toy2)
    pipe = Pipeline(eng)
    _run(pipe, [_landscape()] * 10)
    rolled = pipe.step(_portrait(), 1.0, roll_deg=80.0)
    assert not rolled.prediction.ok and rolled.prediction.fov_deg == PORTRAIT_FOV
    assert pipe.decider.cfg.fov_deg == PORTRAIT_FOV and rolled.cue.kind == KIND_STOP
    assert max(rolled.decision.belief) < 0.2
    first = _run(Pipeline(eng), [_landscape()])[0].decision.belief
    _run(pipe, [_landscape()] * 10, t0=2.0)
    refused = pipe.step(np.full((1, 96, 3), 128, np.uint8), 3.0)
    assert not refused.prediction.ok and refused.prediction.fov_deg is None
    again = _run(pipe, [_landscape()], t0=3.05)[0].decision.belief
    np.testing.assert_allclose(again, first)


@pytest.mark.parametrize("shape", [(1, 96), (96, 1), (20, 200), (200, 20)])
def test_frames_the_model_cannot_see_give_not_ok_and_the_stop_cue(toy2, shape):
    eng = Engine(toy2)
    bad = np.full((*shape, 3), 128, np.uint8)
    p = eng.predict(bad)
    assert not p.ok and p.error and p.heading_deg is None
    pipe = Pipeline(eng)
    on = _run(pipe, [_landscape()] * 10)
    assert on[-1].cue.kind == KIND_BEACON
    off = _run(pipe, [bad] * 10, t0=1.0)
    assert all(not s.prediction.ok for s in off)
    assert off[-1].decision.stop and off[-1].cue.kind == KIND_STOP


def test_demo_fov_out_of_range_is_one_error_line(tmp_path, toy2):
    clip = tmp_path / "c.mp4"
    clip.write_bytes(b"")
    for fov in ("10", "171", "-67"):
        r = subprocess.run([*DEMO, str(clip), "--bundle", str(toy2), "--out", str(tmp_path / "o"), "--fov", fov],
                           capture_output=True, text=True)
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:"), r.stderr
        assert "Traceback" not in r.stderr


def _synth(tmp_path, name, size):
    out = tmp_path / f"{name}.mp4"
    r = subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", "synth", "--video", "--size", size,
                        "--seconds", "2", "--fps", "4", "--seed", "3", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.parametrize("size, orient, fov, extra", [
    ("240x320", "portrait", PORTRAIT_FOV, []),
    ("320x240", "landscape", LANDSCAPE_FOV, []),
    ("240x320", "portrait", 70.0, ["--fov", "70"]),
])
def test_demo_on_synth_video_uses_the_orientations_fov(tmp_path, toy2, size, orient, fov, extra):
    clip = _synth(tmp_path, orient, size)
    out = tmp_path / "out"
    r = subprocess.run([*DEMO, str(clip), "--bundle", str(toy2), "--out", str(out), "--no-video", "--quiet", *extra],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    w, h = size.split("x")
    assert f"frames {w}x{h} ({orient}); headings assume a horizontal field of view of {fov:g} deg" in r.stdout
    trace = [json.loads(line) for line in (out / "trace.jsonl").read_text().splitlines()]
    assert len(trace) == 8
    space = get_space(13)
    other = LANDSCAPE_FOV if fov != LANDSCAPE_FOV else PORTRAIT_FOV
    checked = 0
    for rec in trace:
        if rec["learner_heading"] is None:
            continue
        b = np.asarray(rec["belief"])
        assert rec["learner_heading"] == pytest.approx(belief_heading(b, space, fov)[1], abs=1e-3)
        assert rec["learner_heading"] != pytest.approx(belief_heading(b, space, other)[1], abs=1e-3)
        assert abs(rec["learner_heading"]) <= fov / 2 + 1e-6
        checked += 1
    assert checked > 0


def test_demo_summary_names_the_fov_on_a_bar_clip(tmp_path, toy2):
    from runtime_toy import write_clip

    clip = write_clip(tmp_path / "bar.mp4", [bin_center_x(STRIP)] * 12, fps=10, h=128, w=96)
    out = tmp_path / "o"
    r = subprocess.run([*DEMO, str(clip), "--bundle", str(toy2), "--out", str(out), "--no-video", "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert f"frames 96x128 (portrait); headings assume a horizontal field of view of {PORTRAIT_FOV:g} deg" in r.stdout
    trace = [json.loads(line) for line in (out / "trace.jsonl").read_text().splitlines()]
    on = [rec for rec in trace if rec["heading_deg"] is not None]
    assert on and all(x_to_bin(heading_to_x(rec["heading_deg"], PORTRAIT_FOV)) == STRIP for rec in on[-3:])


def _two_thresholds(folder, landscape: float, portrait: float):
    return make_toy_bundle(folder, TOY2, threshold=landscape, portrait_threshold=portrait)


def test_each_orientation_gets_its_own_gate_threshold(tmp_path, toy2):
    """A bundle whose landscape threshold silences every frame and whose portrait threshold
    does not: landscape frames stop, portrait frames guide, and turning the phone switches
    the threshold (with a fresh belief) both ways."""
    base = Engine(toy2).decision_config().threshold
    eng = Engine(_two_thresholds(tmp_path / "b", landscape=1e-3, portrait=base))
    assert eng.decision_config().threshold == 1e-3 and eng.decision_config("portrait").threshold == base
    pipe = Pipeline(eng)
    land = _run(pipe, [_landscape()] * 10)
    assert pipe.decider.cfg.threshold == 1e-3 and all(s.cue.kind == KIND_STOP for s in land)
    port = _run(pipe, [_portrait()] * 10, t0=1.0)
    assert pipe.decider.cfg.threshold == base and pipe.decider.cfg.fov_deg == PORTRAIT_FOV
    assert port[-1].cue.kind == KIND_BEACON
    assert x_to_bin(heading_to_x(port[-1].decision.heading_deg, PORTRAIT_FOV)) == STRIP
    back = _run(pipe, [_landscape()] * 3, t0=2.0)
    assert pipe.decider.cfg.threshold == 1e-3 and back[0].cue.kind == KIND_STOP   # no portrait heading carried over
    # without portrait_threshold both orientations use threshold
    plain = Engine(toy2)
    assert plain.decision_config("portrait").threshold == plain.decision_config("landscape").threshold == base


def test_a_narrow_portrait_camera_gets_the_narrow_threshold(tmp_path, toy2):
    """A bundle whose portrait threshold silences every frame and whose narrow camera's threshold
    does not: portrait frames from a 41 deg camera (at most narrow_fov_deg) guide, the same
    frames at the bundle's 53 deg stop, and landscape frames at 41 deg keep the landscape one."""
    base = Engine(toy2).decision_config().threshold
    folder = make_toy_bundle(tmp_path / "b", TOY2, threshold=1e-3, portrait_threshold=1e-3, narrow_threshold=base,
                             narrow_fov_deg=42.0)
    narrow = Pipeline(Engine(folder, fov_deg=41.0))
    steps = _run(narrow, [_portrait()] * 10)
    assert narrow.decider.cfg.threshold == base and steps[-1].cue.kind == KIND_BEACON
    wide = Pipeline(Engine(folder))
    assert all(s.cue.kind == KIND_STOP for s in _run(wide, [_portrait()] * 10))
    assert wide.decider.cfg.threshold == 1e-3 and wide.decider.cfg.fov_deg == PORTRAIT_FOV
    land = _run(narrow, [_landscape()] * 10, t0=1.0)
    assert narrow.decider.cfg.threshold == 1e-3 and all(s.cue.kind == KIND_STOP for s in land)
    # crossing-demo says which threshold the frames took
    from runtime_toy import write_clip

    clip = write_clip(tmp_path / "p.mp4", [bin_center_x(STRIP)] * 6, fps=10, h=128, w=96)
    for extra, said in ((["--fov", "41"], f"gate threshold: entropy {base:.4g} (a narrow camera's: portrait frames at "
                                          "most 42 deg across)"), ([], "gate threshold: entropy 0.001 (portrait)")):
        r = subprocess.run([*DEMO, str(clip), "--bundle", str(folder), "--out", str(tmp_path / "o"), "--no-video",
                            "--quiet", *extra], capture_output=True, text=True)
        assert r.returncode == 0 and said in r.stdout, (r.stdout, r.stderr)


def test_with_wide_fov_a_square_frame_takes_the_portrait_threshold(tmp_path, toy2):
    """``wide_fov_deg``: a square frame (landscape by its sides, ~53 deg across as a crop of the
    4:3 sensor) takes the portrait threshold and guides where the landscape threshold silences it;
    a 4:3 frame stays silent; without the field the square frame takes the landscape one."""
    from crossing_assist.geometry import Geometry

    base = Engine(toy2).decision_config().threshold
    geo = Geometry(camera_fov_deg=(67.0, 53.0), sensor_aspect=4 / 3)   # a square frame: ~52.8 deg
    square = bar_frame(bin_center_x(STRIP), h=96, w=96)
    for wide, heard in ((60.0, KIND_BEACON), (None, KIND_STOP)):
        folder = make_toy_bundle(tmp_path / f"b{wide}", TOY2, threshold=1e-3, portrait_threshold=base,
                                 wide_fov_deg=wide, geometry=geo)
        pipe = Pipeline(Engine(folder))
        steps = _run(pipe, [square] * 10)
        assert pipe.decider.cfg.fov_deg < 60.0 and steps[-1].cue.kind == heard, wide
        assert all(s.cue.kind == KIND_STOP for s in _run(pipe, [_landscape()] * 10, t0=1.0))


@pytest.mark.parametrize("bad", [-1.0, 0.0, "1.2", float("inf")])
def test_a_bad_portrait_threshold_is_one_line(tmp_path, bad):
    from crossing_assist.bundle import read_bundle

    folder = make_toy_bundle(tmp_path / "b", TOY2)
    raw = json.loads((folder / "bundle.json").read_text())
    raw["calibration"]["uncertainty"]["portrait_threshold"] = bad
    (folder / "bundle.json").write_text(json.dumps(raw).replace("Infinity", "1e999"))
    with pytest.raises(BundleError, match="calibration.uncertainty.portrait_threshold"):
        read_bundle(folder)


def test_demo_summary_says_which_rows_a_view_crop_bundle_saw(tmp_path):
    """A schema-3 bundle with the view crop: a portrait clip's summary names the rows the model
    saw (the training camera's view at its scale); a landscape clip at the training FOV loses none."""
    from runtime_toy import write_clip

    from crossing_assist.geometry import Geometry, view_rows

    bundle = make_toy_bundle(tmp_path / "b", TOY2, size=(36, 48),   # a 4:3 canvas
                             geometry=Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0,
                                               view_crop=True))
    size = read_bundle(bundle).input.size
    for name, (h, w) in (("portrait", (128, 96)), ("landscape", (96, 128))):
        clip = write_clip(tmp_path / f"{name}.mp4", [bin_center_x(STRIP)] * 6, fps=10, h=h, w=w)
        r = subprocess.run([*DEMO, str(clip), "--bundle", str(bundle), "--out", str(tmp_path / name), "--no-video",
                            "--quiet"], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        top, rows = view_rows(h, w, 53.0 if h > w else 67.0, size, 67.0)
        if name == "portrait":
            assert rows < h and f"the model sees rows {top}-{top + rows} of {h} (view crop" in r.stdout
        else:
            assert rows == h and "view crop" not in r.stdout and "padded" not in r.stdout
    # a landscape clip set narrower than its camera (zoomed in): padded to the training scale, said so
    r = subprocess.run([*DEMO, str(tmp_path / "landscape.mp4"), "--bundle", str(bundle), "--out", str(tmp_path / "z"),
                        "--no-video", "--quiet", "--fov", "41"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    rows = view_rows(96, 128, 41.0, size, 67.0)[1]
    assert rows > 96 and f"the model sees the frame padded to {rows} rows" in r.stdout, r.stdout


def test_demo_gives_9_16_video_its_crops_fov_with_sensor_aspect(tmp_path):
    """crossing-demo on a 9:16 portrait clip with a bundle that states its sensor (4:3): the
    headings assume the crop's ~41 deg, not the portrait 53, and the view crop keeps a 3:4 view.
    A clip narrower than 20 degrees' worth (1:8) is refused frame by frame (stop cue), and the
    annotated video is still written."""
    from runtime_toy import write_clip

    from crossing_assist.geometry import Geometry, view_rows

    geo = Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0, view_crop=True,
                   sensor_aspect=4 / 3)
    bundle = make_toy_bundle(tmp_path / "b", TOY2, size=(36, 48), geometry=geo)
    fov = read_bundle(bundle).camera_fov(72, 128)
    assert fov == pytest.approx(41.005, abs=1e-3)
    clip = write_clip(tmp_path / "v916.mp4", [bin_center_x(STRIP)] * 6, fps=10, h=128, w=72)
    r = subprocess.run([*DEMO, str(clip), "--bundle", str(bundle), "--out", str(tmp_path / "v916"), "--no-video",
                        "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    top, rows = view_rows(128, 72, fov, (36, 48), 67.0)
    assert 72 / rows == pytest.approx(3 / 4, abs=0.02)
    assert f"field of view of {fov:g} deg" in r.stdout and f"rows {top}-{top + rows} of 128" in r.stdout, r.stdout
    narrow = write_clip(tmp_path / "n.mp4", [bin_center_x(STRIP)] * 4, fps=10, h=128, w=16)
    r = subprocess.run([*DEMO, str(narrow), "--bundle", str(bundle), "--out", str(tmp_path / "n"), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    trace = [json.loads(line) for line in (tmp_path / "n" / "trace.jsonl").read_text().splitlines()]
    assert trace and all(t["stop"] for t in trace), trace[:2]


def test_a_stretch_bundle_levels_with_the_same_fill_as_the_app(tmp_path):
    """A stretch bundle states no pad colour; a levelled frame's corners are filled with
    geometry.PAD_RGB, as the phone app fills them (pad_rgb ?? PAD_RGB), not black."""
    from crossing_assist.geometry import PAD_RGB, Geometry

    b = read_bundle(make_toy_bundle(tmp_path / "s", TOY2, geometry=Geometry(fit="stretch", camera_fov_deg=(67.0, 53.0))))
    assert b.geometry.fit == "stretch" and tuple(b.geometry.pad_rgb) == PAD_RGB
