"""The picture's check of a gyroscope (runtime/gyro.py ``GyroCheck``): a walker's sway confirms a
gyroscope that reads it as the picture does, and never one read the wrong way, blind to yaw or in
another unit; a walk begun facing the crossing has its gyroscope followed offline too."""

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest

from crossing_assist.runtime import offline
from crossing_assist.runtime.demo import DEFAULT_BUNDLE, DEFAULT_CLIP
from crossing_assist.runtime.gyro import GYRO_CHECK, GyroCheck, GyroFollow
from crossing_assist.runtime.imu import ImuLog
from crossing_assist.runtime.offline import OfflineConfig, run_offline
from crossing_assist.runtime.sources import VideoSource
from crossing_assist.runtime.truth import load_truth

FPS = 10.0


def sway_rates(seconds: float, amplitude: float = 2.5, hz: float = 0.9) -> np.ndarray:
    """A walker's step sway: the mean turn rate (deg/s) between frames FPS apart."""
    t = np.arange(int(seconds * FPS) + 1) / FPS
    return np.diff(amplitude * np.sin(2 * np.pi * hz * t)) * FPS


def picture(gyro: np.ndarray, seed: int = 0, misreads: float = 0.03) -> np.ndarray:
    """The picture's reading of the same turns: 3 % larger, noisy, now and then a frame matched a
    stripe period off (-200 deg/s), and now and then no turn read (0)."""
    rng = np.random.default_rng(seed)
    p = gyro * 1.03 + rng.normal(0, 1.0, len(gyro))
    p[rng.random(len(p)) < misreads] = -200.0
    p[rng.random(len(p)) < 0.1] = 0.0
    return p


def first_confirmed(gyro, pic, check=None):
    check = check or GyroCheck()
    for k, (g, p) in enumerate(zip(gyro, pic)):
        check.add(float(g), float(p))
        if check.confirmed():
            return k, check
    return None, check


def test_a_walker_s_sway_confirms_a_gyroscope_the_picture_reads_alike():
    gyro = sway_rates(20)
    assert np.abs(gyro).max() < GYRO_CHECK.turn_dps   # never a clear turn: the rule before never confirmed it
    k, check = first_confirmed(gyro, picture(gyro))
    assert k is not None and k / FPS < 4.0, k
    assert check.verdict == "unchecked" and check.confirmation() == "sway"   # not 'ok' by clear turns
    # the picture's misreads are left out, not counted against it: a gyroscope this good is confirmed
    # however many stripes are misread
    assert first_confirmed(gyro, picture(gyro, misreads=0.2))[0] is not None
    # the rule without the sway route never confirms it
    strict = GyroCheck(replace(GYRO_CHECK, sway_window=10 ** 9))
    assert first_confirmed(gyro, picture(gyro), strict)[0] is None


@pytest.mark.parametrize("how", ["reversed", "another axis", "noise", "rad/s", "twice too large"])
def test_a_sway_never_confirms_a_gyroscope_that_does_not_read_the_picture_s_turn(how):
    """Ten minutes of walking. 'another axis': a gyroscope reading the walker's bob (3 deg at
    twice the step frequency), whose turns pass 15 deg/s where the picture's sway now and then
    does too: sign votes alone confirmed it (the clear-turn rule before the size check)."""
    true = sway_rates(600)
    rng = np.random.default_rng(1)
    gyro = {"reversed": -true,
            "another axis": np.diff(3 * np.sin(2 * np.pi * 1.8 * np.arange(len(true) + 1) / FPS + 0.4)) * FPS,
            "noise": rng.normal(0, 10, len(true)),
            "rad/s": np.radians(true),
            "twice too large": 2 * true}[how]
    assert first_confirmed(gyro, picture(true))[0] is None


@pytest.mark.parametrize("late_s", [0.0, 0.1, 0.15, 0.25])
def test_a_sway_confirms_frames_stamped_late_against_the_gyroscope(late_s):
    """Frames stamped up to a quarter of a second late (a browser giving no capture time): the
    gyroscope's turn over the frame's interval moved back by each of ``sway_lags_s`` finds the
    sway; at no lag alone, 0.15 s late already never confirms (cosine ~0.66)."""
    t = np.arange(201) / FPS
    yaw = lambda s: 2.5 * np.sin(2 * np.pi * 0.9 * s)  # noqa: E731
    pic = picture(np.diff(yaw(t - late_s)) * FPS)   # the picture's turn happened late_s before its stamp

    def gyro_over(lag):   # the gyroscope's mean rate over each frame interval moved back by lag
        return np.diff(yaw(t - lag)) * FPS

    g0, lagged = gyro_over(0.0), np.stack([gyro_over(lag) for lag in GYRO_CHECK.sway_lags_s[1:]], axis=1)
    check = GyroCheck()
    k = next((k for k in range(len(pic)) if check.add(float(g0[k]), float(pic[k]), lagged[k].tolist()) and check.confirmed()),
             None)
    assert k is not None and k / FPS < 5.0, k
    at_no_lag = first_confirmed(g0, pic)[0]
    assert (at_no_lag is not None) == (late_s <= 0.1), at_no_lag


def test_a_gyroscope_found_the_wrong_way_by_clear_turns_is_not_confirmed_by_a_sway_after():
    check = GyroCheck()
    for _ in range(GYRO_CHECK.least):
        check.add(-30.0, 30.0)
    assert check.verdict == "wrong"
    gyro = sway_rates(20)
    assert first_confirmed(gyro, picture(gyro), check)[0] is None


def test_a_walk_begun_facing_the_crossing_follows_its_logged_gyroscope_once_its_sway_confirms_it(tmp_path, monkeypatch):
    """The sample clip from its walk on (the user already faces the crossing, not scanning for
    it), replayed offline with its own motion log: the walker's sway confirms the gyroscope within
    5 s and its turn is told from then on; without the sway, a second or more later."""
    truth = load_truth(DEFAULT_CLIP)
    k_walk = truth["phase"].index("walk")
    src = VideoSource(DEFAULT_CLIP)
    t_walk = k_walk / src.fps
    video = tmp_path / "walk.mp4"
    writer = None
    for t, rgb in src:
        if t < t_walk - 1e-6:
            continue
        if writer is None:
            writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), src.fps, (rgb.shape[1], rgb.shape[0]))
        writer.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    writer.release()
    log = ImuLog.load(DEFAULT_CLIP.with_suffix(".imu.csv")).shifted(t_walk)
    imu = tmp_path / "walk.imu.csv"
    imu.write_text("t,yaw_dps\n" + "".join(f"{t},{r}\n" for t, r in zip(log.t, log.yaw_dps) if t >= -0.5))

    def play(name):
        out = tmp_path / name
        summary = run_offline(OfflineConfig(video=video, bundle=DEFAULT_BUNDLE, out_dir=out, annotate=False,
                                            progress=False, imu=imu, plot=False))
        return summary, [json.loads(line) for line in (out / "trace.jsonl").read_text().splitlines()]

    summary, trace = play("sway")
    sources = [r["yaw_source"] for r in trace]
    assert "gyro" in sources, summary.gyro
    first = sources.index("gyro")
    assert 1.0 < first / src.fps < 5.0 and set(sources[first:]) == {"gyro"}
    assert "once the picture's turn had confirmed it by the walker's sway" in summary.gyro
    strict = lambda follow=False: GyroFollow(follow, replace(GYRO_CHECK, sway_window=10 ** 9))  # noqa: E731
    monkeypatch.setattr(offline, "GyroFollow", strict)
    summary, trace = play("clear_only")
    sources = [r["yaw_source"] for r in trace]
    # its veer passes 15 deg/s now and then: clear turns alone confirmed it 2.2 s later (2026-12-07)
    assert "gyro" not in sources or sources.index("gyro") >= first + src.fps
