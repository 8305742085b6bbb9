"""A motion-sensor log recorded with a video (``crossing-demo --imu``): read as the live gyroscope
reads its samples, written by the clip generator, followed only once the picture confirms it,
levelling rolled frames, bad logs refused in one line."""

import json
import math
import re
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest
from runtime_toy import needs_audio

from crossing_assist.data_tools.augment import roll as roll_image
from crossing_assist.data_tools.synth import ClipConfig, clip_pose, clip_scene, imu_path, synth_clip
from crossing_assist.runtime import demo
from crossing_assist.runtime.demo import DEFAULT_BUNDLE, DEFAULT_CLIP
from crossing_assist.runtime.gyro import MAX_SAMPLE_GAP_S, YawIntegrator, integrate
from crossing_assist.runtime.imu import ImuError, ImuLog, align, picture_turns
from crossing_assist.runtime.offline import OfflineConfig, run_offline
from crossing_assist.runtime.sources import VideoSource

CLIP_IMU = imu_path(DEFAULT_CLIP)


def write_log(path, t, yaw, roll=None):
    rows = ["t,yaw_dps" + (",roll_deg" if roll is not None else "")]
    for k in range(len(t)):
        rows.append(f"{t[k]},{yaw[k]}" + (f",{roll[k]}" if roll is not None else ""))
    path.write_text("\n".join(rows) + "\n")
    return path


def test_a_log_turns_as_the_live_gyroscope_turns_on_the_same_samples(tmp_path):
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.005, 0.3, 400))          # some gaps longer than a sensor's
    yaw = rng.normal(0, 40, 400)
    log = ImuLog.load(write_log(tmp_path / "g.csv", t, yaw), offset=1.5)
    gyro = YawIntegrator()
    for ti, r in zip(t - 1.5, yaw):
        gyro.add(r, ti)
    end = t[-1] - 1.5
    for _ in range(200):
        t0 = rng.uniform(end - 2.5, end)
        t1 = t0 + rng.uniform(0, 0.5)
        assert log.turn(t0, t1) == pytest.approx(gyro.turn(t0, t1), abs=1e-9)
        last = max(s for s in t - 1.5 if s <= t1)   # the sample a live gyroscope had given by t1
        assert log.reporting(t1) == (t1 - last <= MAX_SAMPLE_GAP_S)
    assert not log.reporting(-1.6) and log.reporting(t[0] - 1.5)


def test_a_synthetic_clip_logs_the_motion_it_was_filmed_with(tmp_path):
    video, _ = synth_clip(ClipConfig(tmp_path / "c.mp4", seed=1, seconds=6, fps=8, width=64, height=48,
                                     progress=False))
    log = ImuLog.load(imu_path(video))
    scene = clip_scene(1)
    pose = lambda t: clip_pose(scene, t, 6, 67.0)[0]  # noqa: E731
    for t0, t1 in [(0.0, 6.0), (1.0, 2.5), (3.33, 3.41)]:
        assert log.turn(t0, t1) == pytest.approx(pose(t1).yaw - pose(t0).yaw, abs=0.05)
    assert log.roll_at(2.345) == pytest.approx(pose(2.345).roll, abs=0.01)
    assert abs(log.turn(1.0, 2.5)) > 20   # the clip turns: the log is not flat
    # the embedded sample clip carries its own, the same as the generator writes now
    sample = json.loads(DEFAULT_CLIP.with_suffix(".json").read_text())
    from crossing_assist.data_tools.synth import clip_imu_csv
    assert CLIP_IMU.read_text() == clip_imu_csv(sample["seed"], sample["n_frames"] / sample["fps"], sample["fov_deg"])


@pytest.mark.parametrize("text, says", [
    ("t,yaw\n0,1\n1,2\n", "no column yaw_dps"),
    ("t,yaw_dps\n0,1\n0,2\n", "line 3: t 0 is not after"),
    ("t,yaw_dps\n0,1\n1,abc\n", "line 3: yaw_dps 'abc' is not a finite number"),
    ("t,yaw_dps\n0,1\n1,nan\n", "not a finite number"),
    ("t,yaw_dps\n0,1\n1,5000\n", "beyond a gyroscope's"),
    ("t,yaw_dps,roll_deg\n0,1,0\n1,2,400\n", "roll_deg 400 invalid"),
    ("t,yaw_dps\n0,1\n", "has 1 rows; needs at least 2"),
    ("", "no column t or yaw_dps"),
])
def test_a_bad_log_is_one_clear_line_and_exit_2(tmp_path, capsys, text, says):
    bad = tmp_path / "bad.csv"
    bad.write_text(text)
    with pytest.raises(ImuError, match=says):
        ImuLog.load(bad)
    assert demo.main([str(DEFAULT_CLIP), "--imu", str(bad), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: IMU log") and says in err[0]
    assert not (tmp_path / "o").exists()   # refused before anything ran


def test_bad_imu_flags_are_refused(tmp_path, capsys):
    assert demo.main(["--follow-gyro"]) == 2
    assert demo.main(["--imu-offset", "2"]) == 2
    assert demo.main(["--camera", "0", "--live", "--imu", str(CLIP_IMU)]) == 2
    assert demo.main([str(DEFAULT_CLIP), "--imu", str(tmp_path / "none.csv")]) == 2
    err = capsys.readouterr().err
    assert "need --imu CSV" in err and "not --camera" in err and "does not exist" in err


def _offline(tmp_path, name, imu=None, follow=False, video=DEFAULT_CLIP):
    out = tmp_path / name
    summary = run_offline(OfflineConfig(video=video, bundle=DEFAULT_BUNDLE, out_dir=out, annotate=False,
                                        progress=False, imu=imu, follow_gyro=follow))
    trace = [json.loads(line) for line in (out / "trace.jsonl").read_text().splitlines()]
    return summary, trace


@pytest.fixture(scope="module")
def without_log(tmp_path_factory):
    return _offline(tmp_path_factory.mktemp("plain"), "plain")


def test_the_offline_demo_tells_the_logged_turn_once_the_picture_confirms_it(tmp_path, without_log):
    log = ImuLog.load(CLIP_IMU)
    summary, trace = _offline(tmp_path, "imu", imu=CLIP_IMU)
    fps = VideoSource(DEFAULT_CLIP).fps
    gyro = [r for r in trace if r["yaw_source"] == "gyro"]
    first = gyro[0]["frame"]
    assert 1.0 < first / fps < 8.0, "confirmed by the clip's turn, not at once"
    assert all(r["yaw_source"] == "gyro" for r in trace[first:]) and len(gyro) == len(trace) - first
    for r in gyro[:20]:   # the decision logic is told the log's own turn between the two frames
        i = r["frame"]
        assert r["yaw_rate_dps"] == pytest.approx(log.between((i - 1) / fps, i / fps), abs=1e-6)
    assert "once the picture's turn had confirmed it by clear turns" in summary.gyro and "reported on 100%" in summary.gyro
    assert any(line == summary.gyro for line in summary.lines())
    # guided as often, and no worse than the frames' own turn (2.3 deg p90 without, 1.5 with, 2026-12-07)
    plain = without_log[0].truth
    assert summary.truth["guided_when_visible"] >= plain["guided_when_visible"] - 0.02
    assert summary.truth["p90_heading_error_deg"] <= plain["p90_heading_error_deg"]
    assert without_log[0].gyro is None


def test_a_gyroscope_logged_the_wrong_way_round_never_changes_a_decision(tmp_path, without_log):
    log = ImuLog.load(CLIP_IMU)
    reversed_ = write_log(tmp_path / "rev.csv", log.t, [-v for v in log.yaw_dps])   # no roll: nothing levelled
    summary, trace = _offline(tmp_path, "rev", imu=reversed_)
    assert all(r["yaw_source"] == "camera" for r in trace)
    plain = without_log[1]
    assert [(r["cue"], r["heading_deg"]) for r in trace] == [(r["cue"], r["heading_deg"]) for r in plain]
    assert "wrong way round" in summary.gyro
    # followed from the start, unchecked, until the picture finds it out: then never again
    summary, trace = _offline(tmp_path, "rev_follow", imu=reversed_, follow=True)
    sources = [r["yaw_source"] for r in trace]
    k = sources.index("camera", 1)
    assert sources[1:k] == ["gyro"] * (k - 1) and set(sources[k:]) == {"camera"}
    assert "wrong way round" in summary.gyro


def test_a_logged_roll_levels_a_rolled_video(tmp_path):
    src = VideoSource(DEFAULT_CLIP)
    frames = [f for i, (_, f) in enumerate(src) if 150 <= i < 196]   # walking, the goal in strip 3-5
    rolled_path = tmp_path / "rolled.mp4"
    writer = cv2.VideoWriter(str(rolled_path), cv2.VideoWriter_fourcc(*"mp4v"), src.fps,
                             (frames[0].shape[1], frames[0].shape[0]))
    for f in frames:
        img = roll_image(f, 0.5, 0.5, 6, 40.0, fill="reflect")[0]   # the camera turned 40 deg clockwise
        writer.write(cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    writer.release()
    level_path = tmp_path / "level.mp4"
    writer = cv2.VideoWriter(str(level_path), cv2.VideoWriter_fourcc(*"mp4v"), src.fps,
                             (frames[0].shape[1], frames[0].shape[0]))
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()
    t = np.arange(0, 2.5, 0.01)
    log = write_log(tmp_path / "roll.csv", t, np.zeros_like(t), np.full_like(t, 40.0))
    _, level = _offline(tmp_path, "level", video=level_path)
    _, as_is = _offline(tmp_path, "as_is", video=rolled_path)
    _, levelled = _offline(tmp_path, "levelled", video=rolled_path, imu=log)
    gap = lambda a, b: np.mean([np.abs(np.subtract(x["probs"], y["probs"])).sum() for x, y in zip(a, b)])  # noqa: E731
    assert gap(levelled, level) < 0.5 * gap(as_is, level)
    same = lambda a, b: np.mean([x["action"] == y["action"] for x, y in zip(a, b)])  # noqa: E731
    assert same(levelled, level) > 0.6 and same(as_is, level) < 0.3   # 2026-12-07: 0.74 against 0.13


def test_a_replayed_log_reaches_the_live_gyroscope_at_its_own_times(tmp_path):
    t = np.arange(0, 0.6, 0.01)
    log = ImuLog.load(write_log(tmp_path / "g.csv", t, 30 * np.sin(8 * t)))
    gyro = YawIntegrator()
    start = time.monotonic()
    with log.replay(gyro, start):
        time.sleep(0.25)
        assert gyro.reporting(time.monotonic())
        seen = gyro.turn(start, start + 0.1)
    assert seen == pytest.approx(log.turn(0, 0.1), abs=1e-9) and seen > 0.5
    assert not gyro.reporting(start + 1.0)   # stopped: nothing after the log's end



@needs_audio
def test_the_live_demo_follows_a_replayed_log(tmp_path):
    (tmp_path / ".asoundrc").write_text("pcm.!default { type null }\nctl.!default { type hw; card 0 }\n")
    env = {"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"}
    out = tmp_path / "o"
    proc = subprocess.run([sys.executable, "-m", "crossing_assist.runtime.demo", "--live", "--imu", str(CLIP_IMU),
                           "--follow-gyro", "--max-seconds", "1.5", "--out", str(out)], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    trace = [json.loads(line) for line in (out / "trace.jsonl").read_text().splitlines()]
    told = sum(r["yaw_source"] == "gyro" for r in trace)
    assert len(trace) >= 5 and told >= len(trace) - 1   # the first frame has no turn before it
    assert f"its turn told on {told} of {len(trace)} decisions" in proc.stdout


def test_many_turns_at_once_are_the_live_rule_s_turns(tmp_path):
    """The log's vectorised integral is :func:`gyro.integrate`'s (the live YawIntegrator's rule)
    over all its samples, also before the first sample, after the last and across gaps."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.choice([0.01, 0.35], 500, p=[0.95, 0.05]))   # gaps longer than a sensor's
    yaw = rng.normal(0, 30, 500)
    log = ImuLog.load(write_log(tmp_path / "g.csv", t, yaw))
    t0 = rng.uniform(-1, t[-1] + 1, 300)
    t1 = t0 + rng.uniform(0, 0.4, 300)
    samples = list(zip(log.t, log.yaw_dps))
    want = [integrate(samples, a, b) for a, b in zip(t0, t1)]
    np.testing.assert_allclose(log.turns(t0, t1), want, atol=1e-9)
    assert [log.turn(a, b) for a, b in zip(t0, t1)] == pytest.approx(want, abs=1e-9)


@pytest.fixture(scope="module")
def clip_turns():
    return picture_turns(VideoSource(DEFAULT_CLIP), lambda frame: 67.0)


@pytest.mark.parametrize("shift", [0.7, -1.23])
def test_a_log_s_offset_is_found_from_the_turns_read_from_the_video(tmp_path, clip_turns, shift):
    log = ImuLog.load(CLIP_IMU)
    moved = write_log(tmp_path / "moved.csv", [v + shift for v in log.t], log.yaw_dps)   # started `shift` s earlier
    found = align(ImuLog.load(moved), *clip_turns)
    assert found.offset == pytest.approx(shift, abs=0.02) and found.corr > 0.9 and found.frames > 100


def test_a_log_that_cannot_be_aligned_is_refused_in_one_line(tmp_path, clip_turns):
    log = ImuLog.load(CLIP_IMU)
    reversed_ = ImuLog.load(write_log(tmp_path / "rev.csv", log.t, [-v for v in log.yaw_dps]))
    with pytest.raises(ImuError, match="run opposite to it: is yaw_dps's sign the other way"):
        align(reversed_, *clip_turns)
    t0, t1, rates = clip_turns
    with pytest.raises(ImuError, match="too few turns"):   # a still camera: nothing to line up
        align(log, t0, t1, np.zeros_like(rates))


def test_the_demo_finds_the_offset_itself(tmp_path, capsys):
    log = ImuLog.load(CLIP_IMU)
    moved = write_log(tmp_path / "moved.csv", [v + 0.7 for v in log.t], log.yaw_dps)
    assert demo.main([str(DEFAULT_CLIP), "--imu", str(moved), "--imu-offset", "auto", "--no-video", "--quiet",
                      "--out", str(tmp_path / "o")]) == 0
    assert "aligned with the video at --imu-offset +0.70 s" in capsys.readouterr().out
    with pytest.raises(SystemExit) as bad:
        demo.main(["--imu-offset", "soon", "--imu", str(moved)])
    assert bad.value.code == 2 and "'soon' is neither seconds nor auto" in capsys.readouterr().err


def _labelled_clip(tmp_path, shift_strips=0):
    """The sample clip's frames cut at 2 fps by crossing-data frames, labelled from its ground truth
    (each label moved ``shift_strips`` strips, clipped to 1..12), as a dataset."""
    from crossing_assist.actions import UNKNOWN, parse_label
    from crossing_assist.data_tools.frames import FramesConfig, extract_frames
    from crossing_assist.data_tools.manifest import Row, write_manifest

    out = tmp_path / "frames"
    results, _ = extract_frames(FramesConfig((DEFAULT_CLIP,), out, fps=2.0, progress=False))
    truth = json.loads(DEFAULT_CLIP.with_suffix(".json").read_text())
    rows = []
    for image, t in results[0].frames:
        k = int(round(t * truth["fps"]))
        label = parse_label(truth["label"][k])
        if label != UNKNOWN:
            label = min(12, max(1, label + shift_strips))
        rows.append(Row(image, label, truth["far_x"][k] if not shift_strips else None, f"vid:{results[0].name}", "test"))
    write_manifest(out, rows)
    return out


def test_the_demo_judges_what_the_user_heard_on_a_video_s_labelled_frames(tmp_path, without_log):
    labels = _labelled_clip(tmp_path)
    summary = run_offline(OfflineConfig(video=DEFAULT_CLIP, bundle=DEFAULT_BUNDLE, out_dir=tmp_path / "o",
                                        annotate=False, progress=False, labels=labels))
    got = summary.labels
    assert got["unmatched"] == 0 and got["frames_with_crossing"] + got["frames_without_crossing"] == 32
    # the decisions are the plain run's, judged at 2 fps: as often on as the sidecar's truth says
    assert got["beacon_on"] == pytest.approx(without_log[0].truth["guided_when_visible"], abs=0.12)
    assert got["confidently_wrong"] == 0 and got["silence_no_crossing"] >= 0.9
    assert got["heading_error"]["n"] > 5 and got["heading_error"]["median"] < 3
    assert any(line.startswith("vs labels: beacon on") for line in summary.lines())
    # labels four strips off: every frame heard with the beacon on is confidently wrong
    wrong = run_offline(OfflineConfig(video=DEFAULT_CLIP, bundle=DEFAULT_BUNDLE, out_dir=tmp_path / "w",
                                      annotate=False, progress=False, labels=_labelled_clip(tmp_path / "x", 4))).labels
    assert wrong["beacon_on"] == got["beacon_on"] and wrong["confidently_wrong"] >= 0.8 * wrong["beacon_on"] > 0


def test_labels_of_another_video_are_refused_in_one_line(tmp_path, capsys):
    labels = _labelled_clip(tmp_path)
    other = tmp_path / "walk.mp4"
    other.write_bytes(DEFAULT_CLIP.read_bytes())
    assert demo.main([str(other), "--labels", str(labels), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no labelled frame of walk.mp4 (rows with source vid:walk" in err[0]
    assert "vid:sample_clip" in err[0]
    assert demo.main([str(DEFAULT_CLIP), "--labels", str(labels), "--live"]) == 2


def test_a_log_in_radians_per_second_is_named(tmp_path, without_log):
    """The picture's turn and a deg/s log agree in size (0.999 on the sample clip, 2026-12-07); a
    log in rad/s reads 57 times too slow, never confirms, and the summary says why."""
    log = ImuLog.load(CLIP_IMU)
    rad = write_log(tmp_path / "rad.csv", log.t, [math.radians(v) for v in log.yaw_dps])
    summary, trace = _offline(tmp_path, "rad", imu=rad)
    m = re.search(r"the picture turns ([\d.]+) times as fast as the log says \(a log in rad/s", summary.gyro)
    assert m and 50 < float(m.group(1)) < 65, summary.gyro
    assert all(r["yaw_source"] == "camera" for r in trace)
    plain, _ = _offline(tmp_path, "deg", imu=CLIP_IMU)
    assert "times as fast" not in plain.gyro
