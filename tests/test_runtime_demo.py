"""The offline demo end to end on the toy bundle: the WAV follows the goal, noise stops it."""

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
import soundfile as sf
from runtime_toy import toy_bundle, write_clip  # noqa: F401  (fixture)

from crossing_assist.actions import x_to_bin, x_to_heading
from crossing_assist.runtime import demo
from crossing_assist.runtime.beacon import BeaconConfig
from crossing_assist.runtime.engine import Engine, Prediction
from crossing_assist.runtime.offline import OfflineConfig, Summary, run_offline

SR = 16000
BEACON = BeaconConfig(sample_rate=SR)


def band_energy(x: np.ndarray, hz: float, sr: int = SR, width: float = 30.0) -> float:
    """Share of the signal's energy within ``width`` Hz of ``hz`` (0 for pure silence)."""
    spec = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(len(x), 1 / sr)
    total = spec.sum()
    return float(spec[(f > hz - width) & (f < hz + width)].sum() / total) if total > 0 else 0.0


def run(tmp_path, bundle, xs, name, engine=None, noise=0.0, annotate=False):
    clip = write_clip(tmp_path / f"{name}.mp4", xs, noise=noise)
    cfg = OfflineConfig(video=clip, bundle=bundle, out_dir=tmp_path / name, annotate=annotate,
                        progress=False, beacon=BEACON)
    summary = run_offline(cfg, engine=engine)
    audio, sr = sf.read(tmp_path / name / "beacon.wav")
    trace = [json.loads(line) for line in (tmp_path / name / "trace.jsonl").read_text().splitlines()]
    return summary, audio, sr, trace


def test_wav_left_right_energy_follows_a_goal_moving_left_to_right(tmp_path, toy_bundle):  # noqa: F811
    xs = np.linspace(0.04, 0.96, 150)
    truth = {"label": [str(x_to_bin(x)) for x in xs], "goal_azimuth_deg": [x_to_heading(x) for x in xs]}
    (tmp_path / "move.json").write_text(json.dumps(truth))  # ground truth beside the clip
    summary, audio, sr, trace = run(tmp_path, toy_bundle, xs, "move", annotate=True)
    assert sr == SR and audio.shape == (round(150 / 30 * SR), 2)  # on the video's timeline
    assert len(trace) == 150 == summary.frames
    win = SR // 2
    balance = []
    for i in range(0, len(audio) - win + 1, win):
        el, er = (audio[i:i + win] ** 2).sum(0)
        balance.append((er - el) / (er + el))
    # window 0 may hold a few start-up frames of the (centred) stop cue while evidence builds up
    assert balance[0] < 0 and balance[1] < -0.6 and balance[-1] > 0.6
    assert np.corrcoef(np.arange(len(balance)), balance)[0, 1] > 0.95
    assert band_energy(audio.sum(1), BEACON.tone_hz) > 0.5
    tone_step = 2 * np.pi * BEACON.tone_hz / SR * BEACON.amplitude
    assert np.abs(np.diff(audio, axis=0)).max() < 1.15 * tone_step  # 150 cue changes, no click
    assert summary.truth["guided_when_visible"] > 0.9
    assert summary.truth["median_heading_error_deg"] < 4.0
    assert any(line.startswith("vs ground truth") for line in summary.lines())
    cap = cv2.VideoCapture(str(tmp_path / "move" / "annotated.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 150
    ok, img = cap.read()
    assert ok and img.shape == (72, 96, 3)


@pytest.mark.parametrize("noise", [0.0, 1.0], ids=["no-crossing", "noise"])
def test_no_crossing_or_noise_keeps_the_beacon_off_and_plays_the_stop_cue(tmp_path, toy_bundle, noise):  # noqa: F811
    _, audio, _, trace = run(tmp_path, toy_bundle, [None] * 60, "none", noise=noise)
    assert all(r["stop"] and r["cue"] == "stop" and r["pan"] is None for r in trace)
    mono = audio.sum(1)
    assert band_energy(mono, BEACON.tone_hz) < 1e-3  # no beacon tone at all
    assert band_energy(mono, BEACON.stop_hz) + band_energy(mono, 0.75 * BEACON.stop_hz) > 0.5
    assert np.abs(audio).max() > 0.1


def test_failing_inference_stops_the_beacon_for_those_frames(tmp_path, toy_bundle, monkeypatch):  # noqa: F811
    engine = Engine(toy_bundle)
    real = engine.predict
    calls = {"n": 0}

    def flaky(frame, fov_deg=None, roll_deg=None):   # Engine.predict's signature
        calls["n"] += 1
        if 40 <= calls["n"] <= 60:
            return Prediction(ok=False, error="RuntimeError: simulated")
        return real(frame, fov_deg, roll_deg)

    monkeypatch.setattr(engine, "predict", flaky)
    summary, audio, _, trace = run(tmp_path, toy_bundle, [0.8] * 90, "flaky", engine=engine)
    assert [r["reason"] for r in trace[39:60]] == ["failed"] * 21
    assert {r["cue"] for r in trace[39:60]} == {"stop"}
    assert summary.failed == 21
    seg = audio[round(40 / 30 * SR) + 400:round(60 / 30 * SR)].sum(1)  # after the fade
    assert band_energy(seg, BEACON.tone_hz) < 1e-3
    assert not trace[-1]["stop"]  # recovers


def test_a_gap_between_frames_plays_the_stop_cue_from_the_watchdogs_moment(tmp_path, toy_bundle, monkeypatch):  # noqa: F811
    """A variable-frame-rate video whose frames stop for 0.9 s: as the live loop's watchdog, the
    direction stops 0.5 s after the last frame and the stop cue plays until the next one (the
    tone went on through the whole gap); the frames after it guide again."""
    from crossing_assist.runtime import sources

    class Gappy(sources.VideoSource):    # frames 20.. come 0.9 s late
        def __iter__(self):
            for i, (t, frame) in enumerate(super().__iter__()):
                yield (t + 0.9 if i >= 20 else t), frame

    monkeypatch.setattr(sources, "VideoSource", Gappy)
    summary, audio, _, trace = run(tmp_path, toy_bundle, [0.8] * 40, "gap")
    assert summary.frames == len(trace) == 40
    assert trace[19]["cue"] == "beacon" and trace[-1]["cue"] == "beacon"
    last, back = 19 / 30, 20 / 30 + 0.9
    gap = audio[round((last + 0.5) * SR) + 400:round(back * SR)].sum(1)    # after the fade
    assert band_energy(gap, BEACON.tone_hz) < 1e-3
    assert band_energy(gap, BEACON.stop_hz) + band_energy(gap, 0.75 * BEACON.stop_hz) > 0.5
    before = audio[round(last * SR):round((last + 0.45) * SR)].sum(1)     # within the watchdog: still guided
    assert band_energy(before, BEACON.tone_hz) > 0.5


def test_cli_runs_and_says_where_the_outputs_are(tmp_path, toy_bundle):  # noqa: F811
    clip = write_clip(tmp_path / "c.mp4", np.linspace(0.2, 0.8, 20))
    out = tmp_path / "o"
    proc = subprocess.run([sys.executable, "-m", "crossing_assist.runtime.demo", str(clip), "--bundle",
                           str(toy_bundle), "--out", str(out), "--quiet"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert str(out.resolve()) in proc.stdout
    assert {p.name for p in out.iterdir()} >= {"beacon.wav", "annotated.mp4", "trace.jsonl"}


def test_threads_make_the_same_decisions(tmp_path, toy_bundle, capsys, monkeypatch):  # noqa: F811
    """``--threads 2`` (the model on two onnxruntime threads) writes the same trace as the default
    one thread (the MC-dropout masks do not depend on the threads); a thread count out of range
    is one line and exit 2."""
    from crossing_assist.runtime import pipeline

    opened, engine = [], pipeline.Engine
    monkeypatch.setattr(pipeline, "Engine", lambda *a, **k: opened.append(k["threads"]) or engine(*a, **k))
    clip = write_clip(tmp_path / "c.mp4", np.linspace(0.2, 0.8, 12), noise=8.0)
    traces = []
    for threads in ("1", "2"):
        out = tmp_path / f"t{threads}"
        assert demo.main([str(clip), "--bundle", str(toy_bundle), "--out", str(out), "--quiet", "--no-video",
                          "--threads", threads]) == 0
        traces.append((out / "trace.jsonl").read_text())
    assert opened == [1, 2] and traces[0] == traces[1] and traces[0].count("\n") >= 12
    capsys.readouterr()
    for bad in ("-1", "65"):
        assert demo.main([str(clip), "--bundle", str(toy_bundle), "--threads", bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--threads" in err


def test_cli_bad_input_is_one_line(tmp_path, toy_bundle):  # noqa: F811
    proc = subprocess.run([sys.executable, "-m", "crossing_assist.runtime.demo", str(tmp_path / "nope.mp4"),
                           "--bundle", str(toy_bundle)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.startswith("error:") and proc.stderr.count("\n") == 1
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video")
    proc = subprocess.run([sys.executable, "-m", "crossing_assist.runtime.demo", str(bad), "--bundle",
                           str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.startswith("error: bundle") and proc.stderr.count("\n") == 1
    clip = write_clip(tmp_path / "ok.mp4", [0.5] * 3)
    proc = subprocess.run([sys.executable, "-m", "crossing_assist.runtime.demo", str(clip), "--bundle",
                           str(toy_bundle), "--out", str(bad / "sub"), "--quiet"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and "sub: Not a directory" in proc.stderr and proc.stderr.count("\n") == 1


def test_missing_default_assets_name_what_is_missing(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(demo, "DEFAULT_BUNDLE", tmp_path / "default_bundle")
    monkeypatch.setattr(demo, "DEFAULT_CLIP", tmp_path / "sample_clip.mp4")
    assert demo.main([]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "default_bundle" in err and "sample_clip.mp4" in err


def test_benchmark_reports_decisions_per_second(tmp_path, toy_bundle):  # noqa: F811
    from pathlib import Path

    clip = write_clip(tmp_path / "b.mp4", np.linspace(0.1, 0.9, 30))
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "demo_throughput.py"
    proc = subprocess.run([sys.executable, str(script), "--bundle", str(toy_bundle), "--video", str(clip),
                           "--repeat", "1", "--json", "--threads", "1", "2"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    rec = json.loads(proc.stdout.strip().splitlines()[-1])
    assert rec["decisions_per_s"] > 0 and rec["x_real_time"] == pytest.approx(rec["decisions_per_s"] / 30, rel=1e-6)
    assert str(toy_bundle) in proc.stdout and "model on 1 thread," in proc.stdout and "model on 2 threads:" in proc.stdout


def test_with_ffmpeg_on_path_the_beacon_is_muxed_into_the_video(tmp_path, toy_bundle, monkeypatch):  # noqa: F811
    fake = tmp_path / "bin" / "ffmpeg"
    fake.parent.mkdir()
    log = tmp_path / "ffmpeg_args.txt"
    fake.write_text(f'#!/bin/sh\necho "$@" > {log}\nfor a; do last="$a"; done\necho muxed > "$last"\n')
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake.parent}:/usr/bin:/bin")
    summary, _, _, _ = run(tmp_path, toy_bundle, [0.5] * 10, "mux", annotate=True)
    muxed = tmp_path / "mux" / "annotated_with_audio.mp4"
    assert summary.outputs["with_audio"] == str(muxed) and muxed.read_text() == "muxed\n"
    args = log.read_text()
    assert "annotated.mp4" in args and "beacon.wav" in args and "libx264" in args


def test_the_summary_advises_sideways_only_for_a_mostly_unsure_portrait_video():
    """Unsure where a crossing is on most frames of a portrait video: hold it sideways. Unsure
    because the model sees no crossing (a walk with none in view): no such advice, it would not help."""
    def lines(size, uncertain, ok, seeing=None):
        return Summary(frames=uncertain + ok, video_s=1.0, wall_s=1.0, gates={}, failed=0, outputs={},
                       reasons={"uncertain": uncertain, "ok": ok}, frame_size=size, fov_deg=(53.0,),
                       unsure_seeing=uncertain if seeing is None else seeing).lines()

    advice = [line for line in lines((480, 640), 6, 4) if line.startswith("advice:")]
    assert len(advice) == 1 and "unsure where the crossing is on 60% of these portrait frames" in advice[0]
    assert "sideways" in advice[0]
    assert not any(line.startswith("advice:") for line in lines((640, 480), 6, 4))   # landscape already
    assert not any(line.startswith("advice:") for line in lines((480, 640), 4, 6))   # mostly guided
    assert not any(line.startswith("advice:") for line in lines((480, 640), 10, 0, seeing=1))   # no crossing seen


def test_a_phone_video_plays_upright_at_its_frames_own_times():
    """crossing-demo's source on a portrait phone video with variable frame rate: upright portrait
    frames, stamped with the container's times (index / average fps drifted by up to 0.9 s)."""
    from pathlib import Path

    from crossing_assist.runtime.sources import VideoSource
    from crossing_assist.video_clock import FrameClock

    src = VideoSource(Path(__file__).parent / "data" / "videos" / "rot90_vfr_h264.mp4")
    frames = list(src)
    ts = [round(t, 3) for t, _ in frames]
    assert len(frames) == 40 and src.frame_count == 40
    assert ts[:3] == [0.0, 0.033, 0.067] and ts[29:32] == [0.967, 1.333, 1.533] and ts[-1] == 3.133
    assert all(f.shape[0] > f.shape[1] for _, f in frames)            # portrait, as the phone was held
    top = frames[0][1][: 360 // 16]
    assert ((top[..., 0] > 180) & (top[..., 1] < 90)).mean() > 0.3     # the red bar on top: upright
    clock = FrameClock(25.0)                                            # a raw stream: no times (always 0)
    assert [round(clock.time(0.0), 3) for _ in range(3)] == [0.0, 0.04, 0.08]
    clock = FrameClock(30.0)
    assert [clock.time(m) for m in (0.0, 100.0, 50.0, float("nan"))] == pytest.approx([0.0, 0.1, 0.1 + 1 / 30, 0.1 + 2 / 30])


@pytest.mark.parametrize("w, h, want", [(1280, 721, (361, 640)), (1280, 720, (360, 640)), (1920, 1081, (360, 640)),
                                        (1281, 3, (1, 640)), (640, 480, (480, 640))])
def test_video_frames_are_downscaled_to_the_apps_size(w, h, want):
    """Frames wider than 640 px are scaled down as the app scales them (camera.js grab: halves
    round up), so Python and the phone give the graph the same number of rows."""
    from crossing_assist.runtime.sources import _to_rgb

    assert _to_rgb(np.zeros((h, w, 3), np.uint8), 640).shape[:2] == want


class _QueueingCamera:
    """A camera driver's queue: a frame every ``period`` s, each stamped in its pixels with its
    index; ``read()`` blocks for the next one."""

    def __init__(self, period: float, n: int) -> None:
        import time

        self.period, self.n, self.start, self.i, self.released = period, n, time.monotonic(), 0, False

    def isOpened(self):   # noqa: N802 (OpenCV's name)
        return True

    def get(self, prop):
        return 0.0

    def read(self):
        import time

        if self.i >= self.n:
            return False, None
        due = self.start + (self.i + 1) * self.period   # frame i arrives at its period's end
        time.sleep(max(0.0, due - time.monotonic()))
        frame = np.full((8, 8, 3), self.i, np.uint8)
        self.i += 1
        return True, frame

    def release(self):
        self.released = True


def test_a_slow_loop_gets_the_newest_camera_frame_stamped_when_it_arrived(monkeypatch):
    """Behind a slow model the loop must get the newest frame, stamped when it arrived, not the
    oldest queued one stamped when read (it was counted fresh while 4 periods old)."""
    import time

    import cv2

    from crossing_assist.runtime import sources

    cam = _QueueingCamera(period=0.02, n=40)
    monkeypatch.setattr(cv2, "VideoCapture", lambda index: cam)
    src = sources.CameraSource(0)
    taken = []
    for t, rgb in src:
        taken.append((int(rgb[0, 0, 0]), t, time.monotonic()))
        time.sleep(0.1)                                   # the model: five camera periods a frame
    indices = [i for i, _, _ in taken]
    assert indices == sorted(indices) and len(indices) < 20 and src.dropped > 20
    for i, t, got in taken[1:]:
        assert abs(t - (cam.start + (i + 1) * cam.period)) < 0.1    # stamped on arrival (a read stamp
        assert got - t < 0.1                                         # lagged 0.08 s more each frame)
    assert cam.released


def test_the_offline_demo_draws_its_timeline_where_matplotlib_is_installed(tmp_path, toy_bundle, monkeypatch):  # noqa: F811
    pytest.importorskip("matplotlib")
    summary, _, _, trace = run(tmp_path, toy_bundle, np.linspace(0.1, 0.9, 40), "tl")
    png = cv2.imread(summary.outputs["timeline"])
    assert png is not None and png.shape[0] > 300 and png.shape[1] > 600
    import crossing_assist.plotting as plotting

    def missing():
        raise ImportError("no matplotlib")

    monkeypatch.setattr(plotting, "pyplot", missing)
    summary, _, _, _ = run(tmp_path, toy_bundle, np.linspace(0.1, 0.9, 40), "tl2")
    assert summary.outputs["timeline"].startswith("skipped (matplotlib is not installed")
    assert not (tmp_path / "tl2" / "timeline.png").exists()


def test_timeline_spans_cover_each_run_of_stops_until_the_next_frame():
    from crossing_assist.runtime.timeline import _spans

    ts = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
    assert _spans(ts, [True, True, False, False, True, True], 0.6) == [(0.0, 0.2, 0), (0.4, 0.6, 4)]
    assert _spans(ts, [False, True, False, True, False, False], 0.6) == [(0.1, 0.2, 1), (0.3, 0.4, 3)]
    assert _spans(ts, [False] * 6, 0.6) == []
