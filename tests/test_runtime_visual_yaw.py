"""The turn read from the frames (runtime.visual_yaw): thumbnails, shifts, rates, the pipeline's use."""

import math

import numpy as np
import pytest
from runtime_toy import toy_bundle  # noqa: F401  (fixture)

from crossing_assist.runtime import visual_yaw as vy
from crossing_assist.runtime.decide import Decider
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.pipeline import Pipeline

FOV = 60.0


def _texture(h: int, w: int, seed: int = 0) -> np.ndarray:
    """A smooth random RGB scene (uint8): noise blurred along both axes, channels differing."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 255, (h + 8, w + 8, 3))
    for axis in (0, 1):
        x = sum(np.roll(x, k, axis=axis) for k in range(-4, 5)) / 9
    x = x[4:-4, 4:-4]
    return np.clip((x - x.mean()) * 4 + 128, 0, 255).astype(np.uint8)


def _turn_deg(shift_px: float, width_px: int, fov: float = FOV) -> float:
    f = (width_px / 2) / math.tan(math.radians(fov) / 2)
    return math.degrees(math.atan(shift_px / f))


def test_thumbnail_is_the_area_mean_of_grey():
    frame = np.random.default_rng(1).integers(0, 256, (37, 53, 3), dtype=np.uint8)
    thumb = vy.thumbnail(frame, 10)
    h = max(8, round(10 * 37 / 53))     # at least 8 rows
    assert thumb.shape == (h, 10)
    grey = frame.astype(float).mean(axis=2)
    for i in range(h):
        for j in range(10):
            cell = grey[(i * 37) // h:((i + 1) * 37) // h, (j * 53) // 10:((j + 1) * 53) // 10]
            assert thumb[i, j] == pytest.approx(cell.mean(), abs=1e-9)
    with pytest.raises(ValueError, match="H x W x 3"):
        vy.thumbnail(np.zeros((10, 10)))


@pytest.mark.parametrize("step_px", [-14, -5, 3, 9])
def test_a_sideways_slide_is_read_as_its_turn(step_px):
    """The camera sweeping a wide scene: each frame is the window moved by step_px, so the turn
    per frame is that shift's angle; + = the window moved right = the camera turned right."""
    scene = _texture(120, 700)
    yaw, rates = vy.VisualYaw(), []
    for k in range(6):
        x0 = 300 + k * step_px
        rates.append(yaw.update(scene[:, x0:x0 + 160], k / 10, FOV))
    assert rates[0] == 0.0                                 # nothing to compare the first with
    want = _turn_deg(step_px, 160) * 10
    assert rates[1:] == pytest.approx([want] * 5, rel=0.08, abs=0.5)


def test_a_real_photo_turned_by_a_known_angle(ptl_dir):
    """PTL photos re-rendered as turned by psi (the augmentation's perspective warp, not a slide)."""
    cv2 = pytest.importorskip("cv2")
    from crossing_assist.data_tools.augment import yaw as turn
    photos = sorted((ptl_dir / "images").glob("*"))[:4]
    errors = []
    for path in photos:
        img = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        img = cv2.resize(img, (320, 240), interpolation=cv2.INTER_AREA)
        for psi in (-4.0, 2.0, 6.0):
            yaw = vy.VisualYaw()
            yaw.update(img, 0.0, 90.0)
            errors.append(yaw.update(turn(img, None, 12, psi, 90.0)[0], 1.0, 90.0) - psi)
    assert max(abs(e) for e in errors) < 1.0, errors


def test_no_turn_is_read_where_there_is_none():
    scene = _texture(48, 64)
    still = vy.VisualYaw()
    assert [still.update(scene, t, FOV) for t in (0.0, 0.1, 0.2)] == [0.0, 0.0, 0.0]
    # a blank wall; a flat middle with textured sides (a template without texture scored ties)
    flat = np.full((48, 64, 3), 90, np.uint8)
    edges = scene.copy()
    edges[:, 16:48] = 120
    for frames in ((flat, flat + 1), (edges, edges)):
        yaw = vy.VisualYaw()
        assert [yaw.update(f, t, FOV) for t, f in enumerate(frames)] == [0.0, 0.0]
    # an unrelated picture (a bus fills the view) is not a turn
    assert vy.shift_between(vy.thumbnail(scene), vy.thumbnail(_texture(48, 64, seed=5))) is None


def test_stripes_matched_a_period_off_are_no_turn(monkeypatch):
    """A zebra's stripes fill the view (a walker on the crossing): moved 2 thumbnail pixels, they
    match as well 5 the other way, a stripe period (7) off. That is no turn, never a guess: the
    synthetic walks read -130 to -200 deg/s for single such frames, and the belief jumped two
    strips. A textured scene moved alike is still read."""
    xs, ys = np.arange(40), np.arange(14)[:, None]
    stripes = 128 + 60 * np.sign(np.sin(2 * np.pi * (xs + 0.5) / 7))[None, :] + 0 * ys
    wobble = np.round(6 * np.sin(ys * 2.3 + xs[None, :24] * 1.7))   # what else changed between them
    prev, cur = np.round(stripes[:, 8:32]), np.round(stripes[:, 10:34] + wobble)
    assert vy.shift_between(prev, cur) is None
    monkeypatch.setattr(vy, "AMBIGUOUS", 0.0)                        # the check off
    assert vy.shift_between(prev, cur) == pytest.approx(-5.08, abs=0.01)   # a period off: read the other way
    monkeypatch.undo()
    # frames: a striped view moved 10 px (2 thumbnail pixels) cannot tell; a textured one reads it
    w, y = 320, np.arange(120)[:, None]
    bars = np.where(np.sin(2 * np.pi * (np.arange(w + 40) + 2.5) / 35) > 0, 200.0, 60.0)[None, :] + 0 * y
    grey = lambda a: np.repeat(np.clip(a, 0, 255)[..., None], 3, axis=2).astype(np.uint8)  # noqa: E731
    moved = grey(bars[:, 20:20 + w] + 20 * np.sin(y * 0.46 + np.arange(w)[None, :] * 0.34))
    assert vy.shift_between(vy.thumbnail(grey(bars[:, 10:10 + w])), vy.thumbnail(moved)) is None
    plain = _texture(120, w + 40, seed=3)
    assert vy.shift_between(vy.thumbnail(plain[:, 10:10 + w]), vy.thumbnail(plain[:, 20:20 + w])) == pytest.approx(2.0, abs=0.2)


@pytest.mark.parametrize("cover", [(0.3, 0.5), (0.5, 0.6), (0.8, 0.7)])
def test_a_bus_passing_a_still_camera_is_no_turn(cover):
    """A textured block (a bus: `cover` of the frame's width and height, from the bottom) crossing
    a still view at 30 px a frame moves part of the picture; the tiles it covers veto any shift
    (without them the estimator read the bus's motion as the camera turning the other way)."""
    view, bus = _texture(120, 160, seed=1), _texture(120, 400, seed=2)
    bw, bh = int(cover[0] * 160), int(cover[1] * 120)
    yaw, turned = vy.VisualYaw(), 0.0
    for k in range(12):
        frame, x = view.copy(), -bw + 30 * k
        x0, x1 = max(0, x), min(160, x + bw)
        if x1 > x0:
            frame[120 - bh:, x0:x1] = bus[:bh, x0 - x + 100:x1 - x + 100]
        turned += yaw.update(frame, k / 10, FOV) / 10
    assert abs(turned) < 2.0, turned


def test_a_missing_frame_or_fov_or_a_cut_starts_afresh():
    scene = _texture(120, 700)
    yaw = vy.VisualYaw()
    yaw.update(scene[:, 300:460], 0.0, FOV)
    assert yaw.update(None, 0.1, FOV) == 0.0
    assert yaw.update(scene[:, 305:465], 0.2, FOV) == 0.0     # nothing before it: afresh
    assert yaw.update(scene[:, 310:470], 0.3, None) == 0.0
    assert yaw.update(scene[:, 315:475], 0.4, FOV) == 0.0
    assert yaw.update(scene[:, 320:480], 0.5, FOV) > 0
    assert yaw.update(scene[:, 350:510], 0.51, FOV) == 0.0    # ~1000 deg/s: a cut, not a turn
    assert yaw.update(scene[:, 350:510], 0.51, FOV) == 0.0    # time did not move


def _recording(monkeypatch):
    seen = []
    step = Decider.step

    def record(self, t, obs, yaw_rate_dps=0.0):
        seen.append(yaw_rate_dps)
        return step(self, t, obs, yaw_rate_dps)
    monkeypatch.setattr(Decider, "step", record)
    return seen


def test_the_pipeline_follows_a_turn_seen_in_the_frames_unless_given_one(toy_bundle, monkeypatch):  # noqa: F811
    seen = _recording(monkeypatch)
    scene = _texture(96, 800)
    frames = [scene[:, 300 + 6 * k:300 + 6 * k + 128] for k in range(8)]
    engine = Engine(toy_bundle)
    for visual, gyro, check in ((True, None, lambda r: min(r[1:]) > 5.0),
                                (False, None, lambda r: r == [0.0] * 8),
                                (True, -3.0, lambda r: r == [-3.0] * 8)):
        seen.clear()
        pipe = Pipeline(engine, visual_yaw=visual)
        for k, f in enumerate(frames):
            pipe.step(f, k / 10, yaw_rate_dps=gyro)
        assert check(seen), (visual, gyro, seen)
    # a watchdog tick (no frame) is no turn, and the frame after it has nothing to compare with
    seen.clear()
    pipe = Pipeline(engine)
    for k, f in enumerate(frames[:3]):
        pipe.step(f if k != 1 else None, k / 10)
    assert seen == [0.0, 0.0, 0.0]


def test_a_rolled_camera_is_read_levelled_as_the_app_reads_it(toy_bundle, monkeypatch):  # noqa: F811
    """A street (the sample clip's 5th frame) seen by a 67 deg camera rolled 30 deg, turning by
    known angles: told the roll, the pipeline reads the turn from the frame levelled (as the model
    sees it, and as the app reads it); unlevelled the picture moves along the rolled axis and the
    turn read is further off. The model's outputs are those of the engine levelling the frame
    itself."""
    cv2 = pytest.importorskip("cv2")
    from crossing_assist.data_tools.augment import roll, yaw as turn
    from crossing_assist.runtime.demo import DEFAULT_CLIP

    cap = cv2.VideoCapture(str(DEFAULT_CLIP))
    for _ in range(5):
        ok, bgr = cap.read()
    assert ok
    scene = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    seen = _recording(monkeypatch)
    turns = [0.0, 1.0, 4.0, 0.0, -3.0]          # the camera's yaw at each frame, 10 fps
    frames = [roll(turn(scene, None, 12, psi, 67.0)[0], None, 0.5, 0, 30.0, fill="reflect")[0] for psi in turns]
    truth = np.diff(turns) * 10
    errors = {}
    for told in (30.0, None):
        seen.clear()
        pipe, ref = Pipeline(Engine(toy_bundle, fov_deg=67.0, seed=5)), Engine(toy_bundle, fov_deg=67.0, seed=5)
        for k, f in enumerate(frames):   # the same MC-dropout draws in the same order: the same outputs
            assert np.array_equal(pipe.step(f, k / 10, roll_deg=told).prediction.probs,
                                  ref.predict(f, roll_deg=told).probs)
        errors[told] = np.abs(np.asarray(seen[1:]) - truth)
    assert errors[30.0].max() < 2.0, errors                     # 0.2 deg a frame at 10 fps
    assert errors[None].mean() > 2 * errors[30.0].mean(), errors


def test_the_check_script_reads_known_turns_buses_and_the_sample_clip(tmp_path):
    """scripts/visual_yaw_check.py on toy bar photos: its figures are the estimator's (turns read
    near their angle, a bus read as less turn with the veto than without, the sample clip's turn
    to the crossing read within a few degrees); a missing manifest is one line and exit 1."""
    import json
    import sys
    from pathlib import Path

    from runtime_toy import bar_dataset
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import visual_yaw_check as check

    out = tmp_path / "vy.json"
    assert check.main(["--data", str(bar_dataset(tmp_path / "d", n=3)), "--photos", "3", "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    turns = res["known_turns"]
    assert turns["pairs"] == 15 and turns["refused"] < 15 and turns["mae_deg"] < 1.0
    assert all(b["veto"]["mean_abs_deg"] <= b["no_veto"]["mean_abs_deg"] for b in res["buses"].values())
    assert set(res["rolled"]) == {"10", "20", "30"}
    assert all(r[k]["pairs"] == 15 and r[k]["refused"] < 15 for r in res["rolled"].values() for k in ("as_is", "levelled"))
    clip = res["sample_clip"]["turn"]
    assert abs(clip["read_sum_deg"] - clip["true_sum_deg"]) < 5 and abs(clip["true_sum_deg"]) > 90
    assert check.main(["--data", str(tmp_path / "none")]) == 1
