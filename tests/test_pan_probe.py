"""scripts/pan_probe.py: photos played as a scanning phone sees them: the turn from a gyroscope,
read from the frames, or not told."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from runtime_toy import bar_dataset, toy_bundle  # noqa: F401  (fixture)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import pan_probe as pp  # noqa: E402



def test_scan_goes_still_right_left_and_back():
    from crossing_assist.runtime.listen import scan_yaw

    psi = scan_yaw(20.0, 30.0)
    assert np.all(psi[:10] == 0) and psi.max() >= 17 and psi.min() <= -17 and psi[-1] == 0
    assert np.abs(np.diff(psi)).max() <= 3.0 + 1e-9   # 30 deg/s at 10 fps


def test_scans_replay_from_the_cache(tmp_path, toy_bundle):  # noqa: F811
    """The toy places bars; a scan moves each bar across the view (and out of it, relabelled
    unknown), played with the turn told by a gyroscope, read from the frames and not told.
    Replaying the cache decides as the play did. (Step 4b itself: tests/test_runtime_decide.py and the vectors.)"""
    data = bar_dataset(tmp_path / "data", n=6)
    cache, out, again = tmp_path / "c.npz", tmp_path / "a.json", tmp_path / "b.json"
    args = ["--bundle", str(toy_bundle), "--data", str(data), "--photos", "6", "--amplitude", "30"]
    assert pp.main([*args, "--cache", str(cache), "--out", str(out)]) == 0
    assert pp.main(["--bundle", str(toy_bundle), "--cache", str(cache), "--replay", "--out", str(again)]) == 0
    res = json.loads(out.read_text())
    assert res == json.loads(again.read_text())
    assert res["photos"] == 6 and res["amplitude_deg"] >= 27 and res["rate_dps"] == 30
    for name in ("gyro", "camera", "no_yaw"):
        assert res[name]["in_view"] > 0 and res[name]["out_of_view"] > 0 and res[name]["confidently_wrong"] == 0
    assert res["gyro"]["beacon_on"] >= 0.9   # the toy places bars
    # the same frames: a decision told the turn, by a gyroscope or by the frames, stops pointing
    # once the bar left the view
    assert res["gyro"]["out_of_view_on"] < res["no_yaw"]["out_of_view_on"]
    assert res["camera"]["out_of_view_on"] < res["no_yaw"]["out_of_view_on"]
    with np.load(cache) as z:
        labels, rates = z["scan_labels"], z["camera_rates"]   # a Listener file: its clips, goal and turn per frame
    assert len(set(labels[0].tolist())) > 2   # the bar moved across strips as the camera turned
    turning = np.abs(np.diff(pp.scan_yaw(30.0, 30.0))) > 0
    assert np.median(np.abs(rates[:, 1:][:, turning])) > 15   # read from the frames: ~30 deg/s while turning
    # --heard-after: judged 0.3 s after capture (9 deg at 30 deg/s, ~2 of the toy's 7.5 deg strips)
    late = tmp_path / "late.json"
    assert pp.main(["--bundle", str(toy_bundle), "--cache", str(cache), "--replay", "--heard-after", "0.3",
                    "--out", str(late)]) == 0
    res = json.loads(late.read_text())
    assert res["heard_after_s"] == 0.3 and res["gyro"]["confidently_wrong"] > 0.1
    assert res["gyro_turned"]["confidently_wrong"] < 0.25 * res["gyro"]["confidently_wrong"]
    assert pp.main(["--bundle", str(toy_bundle), "--cache", str(cache), "--replay", "--heard-after", "60"]) == 1


def test_replay_without_a_cache_is_one_line(tmp_path, toy_bundle, capsys):  # noqa: F811
    assert pp.main(["--bundle", str(toy_bundle), "--replay", "--cache", str(tmp_path / "none.npz")]) == 1
    assert capsys.readouterr().err.count("\n") == 1


def test_a_narrow_camera_scans_the_middle_window(tmp_path, toy_bundle):  # noqa: F811
    """--window: the same scans seen by a narrow camera (the middle 3:4 window of each turned view,
    at the window's FOV), as crossing-eval --scan --portrait plays them; goals beside the window
    but in the photo are its edge strips, so as many frames have the goal in view."""
    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.listen import Listener

    data = bar_dataset(tmp_path / "data", n=4)
    args = ["--bundle", str(toy_bundle), "--data", str(data), "--photos", "4"]
    wide, narrow = tmp_path / "w.npz", tmp_path / "n.npz"
    assert pp.main([*args, "--cache", str(wide), "--out", str(tmp_path / "w.json")]) == 0
    assert pp.main([*args, "--window", "--cache", str(narrow), "--out", str(tmp_path / "n.json")]) == 0
    engine = Engine(toy_bundle, threads=1)
    fov = lambda path: {round(p.fov_deg, 1) for c in Listener.load(engine, path)[0].clips for p in c}  # noqa: E731
    (f_wide,), (f_narrow,) = fov(wide), fov(narrow)
    assert f_narrow < 0.75 * f_wide   # the toy camera 90 deg, its 3:4 window ~59
    res_w, res_n = (json.loads((tmp_path / f).read_text()) for f in ("w.json", "n.json"))
    assert res_n["gyro"]["in_view"] == res_w["gyro"]["in_view"]
    with np.load(narrow) as z:
        edge = np.isin(z["scan_labels"], (1, 12)).mean()
    with np.load(wide) as z:
        assert edge > np.isin(z["scan_labels"], (1, 12)).mean()   # the window's edges hold more goals


def test_a_phone_held_in_portrait_scans_the_middle_of_each_turned_view(tmp_path):
    """--phone: the same scans seen by a phone held in portrait (3:4 frames at the bundle's portrait
    FOV, the middle of each turned view as choose_gate's portrait view cuts it); --window with it
    is refused."""
    from runtime_toy import TOY2, make_toy_bundle

    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.listen import Listener

    bundle = make_toy_bundle(tmp_path / "bundle", TOY2)   # 80 deg landscape, 50 deg portrait
    data = bar_dataset(tmp_path / "data", n=4)
    args = ["--bundle", str(bundle), "--data", str(data), "--photos", "4"]
    wide, phone = tmp_path / "w.npz", tmp_path / "p.npz"
    assert pp.main([*args, "--cache", str(wide)]) == 0
    assert pp.main([*args, "--phone", "--cache", str(phone)]) == 0
    engine = Engine(bundle, threads=1)
    lis = Listener.load(engine, phone)[0]
    assert {round(p.fov_deg, 1) for c in lis.clips for p in c} == {round(engine.bundle.geometry.camera_fov_deg[1], 1)}
    assert {p.orientation for c in lis.clips for p in c} == {"portrait"}
    with np.load(phone) as z, np.load(wide) as w:
        # narrower than the photo's camera: the goal leaves the view sooner, and sits at the edges more
        assert (z["scan_labels"] == 0).sum() >= (w["scan_labels"] == 0).sum()
        assert not np.array_equal(z["scan_labels"], w["scan_labels"])
    with pytest.raises(SystemExit):
        pp.main([*args, "--phone", "--window"])


def test_a_portrait_phone_scan_reads_the_turn_from_the_rows_the_photo_has(tmp_path, monkeypatch):
    """A phone held in portrait sees more rows than a landscape photo has; phone_views repeats the
    photo's edge rows there. The turn read from the frames uses the photo's own rows (a phone would
    see a real scene above and below), and follows the scan's turn rate; the model sees the whole
    phone frame."""
    import cv2
    from runtime_toy import TOY2, make_toy_bundle

    from crossing_assist.models.evaluate import scan_clips
    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.listen import SCAN_FPS, scan_yaw
    from crossing_assist.runtime.visual_yaw import VisualYaw

    engine = Engine(make_toy_bundle(tmp_path / "bundle", TOY2), threads=1)   # portrait 50 deg, landscape 80
    rng = np.random.default_rng(0)
    image = cv2.resize(rng.integers(0, 255, (24, 64, 3), dtype=np.uint8), (640, 240), interpolation=cv2.INTER_CUBIC)
    read, seen = VisualYaw.update, {"yaw": set(), "model": set()}
    monkeypatch.setattr(VisualYaw, "update", lambda self, frame, *a: seen["yaw"].add(frame.shape[0]) or read(self, frame, *a))
    predict = Engine.predict
    monkeypatch.setattr(Engine, "predict", lambda self, frame, *a, **k: seen["model"].add(frame.shape[0]) or predict(self, frame, *a, **k))
    psi = scan_yaw(20.0, 30.0)
    _, _, rates = scan_clips(engine, image, 0.5, 6, psi, phone_fov_deg=50.0)
    assert seen["yaw"] == {240} and min(seen["model"]) > 240   # 3:4 phone frames, ~474 rows of which 240 real
    turn = np.diff(psi, prepend=psi[0]) * SCAN_FPS
    turning = np.abs(turn) > 0
    assert np.median(np.abs(rates[turning] - turn[turning])) < 3.0   # deg/s, at 30 deg/s
