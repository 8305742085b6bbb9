"""Live path: watchdog, frozen and failing input, real audio through an ALSA file PCM, no
device, and the torch-free import."""

import json
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest
from runtime_toy import bar_frame, needs_audio, toy_bundle  # noqa: F401  (fixture)

from crossing_assist.runtime.beacon import KIND_STOP, BeaconConfig, Cue, CuePlayer, render_cue
from crossing_assist.runtime.engine import Engine, Prediction
from crossing_assist.runtime.live import LiveConfig, run_live
from crossing_assist.runtime.pipeline import Pipeline
from crossing_assist.runtime.watchdog import Watchdog

BEACON = BeaconConfig(sample_rate=16000)


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_watchdog_fires_once_after_the_period():
    clock, fired = FakeClock(), []
    dog = Watchdog(0.5, lambda: fired.append(clock.now), clock=clock)
    dog.beat()
    clock.now += 0.49
    assert not dog.poll() and fired == []
    clock.now += 0.02
    assert dog.poll() and fired == [pytest.approx(100.51)]
    clock.now += 1.0
    assert dog.poll() and len(fired) == 1  # once per stale episode
    dog.beat()
    assert not dog.poll()


STOP_LOOP = render_cue(Cue(KIND_STOP), BEACON)


def _is_stop(loop) -> bool:
    return loop.shape == STOP_LOOP.shape and np.array_equal(loop, STOP_LOOP)


def _live(engine, frames, clock, watchdog_s=0.5, player=None):
    player = player or CuePlayer(BEACON)
    pipeline = Pipeline(engine, engine.decision_config(watchdog_s=watchdog_s), BEACON)
    steps = []
    th = threading.Thread(target=run_live, args=(frames, pipeline, player, LiveConfig(watchdog_s=watchdog_s)),
                          kwargs={"clock": clock, "on_step": lambda i, s: steps.append(s)}, daemon=True)
    th.start()
    return player, steps, th


def test_frozen_frame_source_triggers_the_stop_cue_within_the_watchdog_period(toy_bundle):  # noqa: F811
    """Frames come for 1 s (clock injected), then the source freezes; the stop cue must be
    queued once the clock passes the 0.5 s period, and not before."""
    engine, clock = Engine(toy_bundle), FakeClock()
    frozen, release, checked = threading.Event(), threading.Event(), {}

    def frames():
        for i in range(30):
            clock.now = 100.0 + i / 30
            yield i / 30, bar_frame(0.2 + 0.01 * (i % 2))
        frozen.set()
        release.wait(10)  # the camera hangs

    player, steps, th = _live(engine, frames(), clock)
    assert frozen.wait(20)
    time.sleep(0.1)
    checked["beacon_before"] = not _is_stop(player.queued_loop) and not steps[-1].decision.stop
    clock.now += 0.45
    time.sleep(0.15)  # several real polls
    checked["still_beacon"] = not _is_stop(player.queued_loop)
    clock.now += 0.1  # 0.55 s after the last frame
    deadline = time.monotonic() + 2.0
    while not _is_stop(player.queued_loop) and time.monotonic() < deadline:
        time.sleep(0.01)
    checked["stopped"] = _is_stop(player.queued_loop)
    release.set()
    th.join(5)
    assert checked == {"beacon_before": True, "still_beacon": True, "stopped": True}


def test_repeated_identical_frames_count_as_frozen(toy_bundle):  # noqa: F811
    engine, clock = Engine(toy_bundle), FakeClock()
    done = threading.Event()

    def frames():
        frame = bar_frame(0.7)
        for i in range(60):  # the same bytes for 2 s: a frozen camera
            clock.now = 100.0 + i / 30
            yield i / 30, frame
            time.sleep(0.005)
        done.set()

    player, steps, th = _live(engine, frames(), clock)
    th.join(20)
    assert len(steps) == 1  # only the first copy was used
    assert done.is_set()


def test_failing_inference_queues_the_stop_cue(toy_bundle, monkeypatch):  # noqa: F811
    engine, clock = Engine(toy_bundle), FakeClock()
    real, seen = engine.predict, {}

    def flaky(frame, fov_deg=None, roll_deg=None):   # Engine.predict's signature
        return Prediction(ok=False, error="RuntimeError: boom") if seen.get("fail") else real(frame, fov_deg, roll_deg)

    monkeypatch.setattr(engine, "predict", flaky)
    gate = threading.Event()
    states = []

    def frames():
        for i in range(40):
            clock.now = 100.0 + i / 30
            if i == 20:
                seen["fail"] = True
            yield i / 30, bar_frame(0.2 + 0.01 * (i % 2))
            gate.wait(0.01)
            states.append(_is_stop(player.queued_loop))

    player = CuePlayer(BEACON)
    _, steps, th = _live(engine, frames(), clock, player=player)
    th.join(20)
    assert states[15] is False and all(states[20:])
    assert all(s.decision.reason == "failed" for s in steps[20:])


ALSA_CONF = """
pcm.!default {{
  type plug
  slave {{ pcm "capturefile"; format S16_LE; rate {sr}; channels 2 }}
}}
pcm.capturefile {{
  type file
  slave.pcm "null"
  file "{path}"
  format "raw"
}}
"""

PLAY = textwrap.dedent("""
    import time
    from crossing_assist.runtime.beacon import BeaconConfig, CuePlayer, Cue, KIND_BEACON
    from crossing_assist.runtime.audio import LiveAudio
    p = CuePlayer(BeaconConfig(sample_rate={sr}))
    p.set_cue(Cue(KIND_BEACON, pan=0.6, heading_deg=27.0, rate_hz=4.0))
    with LiveAudio(p):
        time.sleep(0.05)
""")



@needs_audio
def test_live_audio_through_an_alsa_file_pcm_plays_exactly_the_cue(tmp_path):
    sr = 16000
    raw = tmp_path / "played.raw"
    (tmp_path / ".asoundrc").write_text(ALSA_CONF.format(sr=sr, path=raw))
    env = {"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([sys.executable, "-c", PLAY.format(sr=sr)], env=env, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    played = np.fromfile(raw, dtype="<i2").reshape(-1, 2).astype(np.float64) / 32768
    raw.unlink()
    want_player = CuePlayer(BeaconConfig(sample_rate=sr))
    loop = want_player.set_cue(Cue("beacon", pan=0.6, heading_deg=27.0, rate_hz=4.0))
    m = 3 * len(loop)
    want = want_player.render(m).astype(np.float64)
    assert len(played) > m + 8192, "too little audio came through"
    first = lambda x: int(np.argmax(np.abs(x[:, 1]) > 0.05))  # noqa: E731
    off0 = first(played) - first(want)
    errs = {off: np.abs(played[off:off + m] - want[:m]).max() for off in range(max(0, off0 - 2), off0 + 3)}
    assert min(errs.values()) < 2.5 / 32768  # 16-bit quantisation only
    el, er = (played ** 2).sum(0)
    assert er / (el + er) == pytest.approx(np.sin(0.4 * np.pi) ** 2, abs=0.01)  # pan 0.6, constant power


@needs_audio
def test_no_audio_device_is_one_clear_line(tmp_path, toy_bundle):  # noqa: F811
    (tmp_path / ".asoundrc").write_text("pcm.!default { type hw; card 99 }\nctl.!default { type hw; card 99 }\n")
    from runtime_toy import write_clip

    clip = write_clip(tmp_path / "c.mp4", [0.5] * 5)
    env = {"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([sys.executable, "-m", "crossing_assist.runtime.demo", str(clip), "--bundle",
                           str(toy_bundle), "--live", "--out", str(tmp_path / "o")], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: no audio output device") and proc.stderr.count("\n") == 1


def test_import_runtime_leaves_torch_out():
    code = ("import sys, crossing_assist.runtime, crossing_assist.runtime.demo, crossing_assist.runtime.offline, "
            "crossing_assist.runtime.live, crossing_assist.runtime.engine, crossing_assist.runtime.status, "
            "crossing_assist.runtime.camera, crossing_assist.testing.vectors; "
            "bad = [m for m in sys.modules if m == 'torch' or m.startswith(('torch.', 'crossing_assist.models', "
            "'crossing_assist.export', 'crossing_assist.iil'))]; print(bad); sys.exit(3 if bad else 0)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_a_decision_later_than_the_watchdog_plays_the_stop_cue_and_the_trace_says_late(toy_bundle, monkeypatch):  # noqa: F811
    """A board too slow for the bundle: each inference takes 0.6 s (the clock moves inside
    predict), over the 0.5 s period. Every step plays the stop cue and is marked late in the
    trace, though the Decider itself did not find the frames stale (frames 0.6 s apart each meet
    a fresh belief, step 4a, so they need not be beacons); at 0.1 s an inference the same frames
    play the beacon."""
    from crossing_assist.runtime.pipeline import trace_record

    def run(seconds_a_frame):
        engine, clock = Engine(toy_bundle), FakeClock()
        real = engine.predict

        def slow(frame, fov_deg=None, roll_deg=None):
            clock.now += seconds_a_frame
            return real(frame, fov_deg, roll_deg)

        monkeypatch.setattr(engine, "predict", slow)

        def frames():
            for i in range(8):
                yield clock.now - 100.0, bar_frame(0.2 + 0.01 * (i % 2))   # offsets from the start

        player, steps, th = _live(engine, frames(), clock)
        th.join(20)
        return player, steps

    player, steps = run(0.6)
    assert len(steps) == 8 and all(s.late and s.cue.kind == KIND_STOP for s in steps)
    assert not any(s.decision.reason == "stale" for s in steps), "the stop came from lateness, not the Decider"
    recs = [trace_record(i, s) for i, s in enumerate(steps)]
    assert all(r["late"] and r["cue"] == "stop" for r in recs)
    _, fast = run(0.1)
    assert not any(s.late for s in fast) and fast[-1].cue.kind != KIND_STOP


REOPEN = textwrap.dedent("""
    import json, sys, time
    from crossing_assist.runtime.beacon import BeaconConfig, CuePlayer, Cue, KIND_BEACON
    from crossing_assist.runtime.audio import LiveAudio
    p = CuePlayer(BeaconConfig(sample_rate={sr}))
    p.set_cue(Cue(KIND_BEACON, pan=0.6, heading_deg=27.0, rate_hz=4.0))
    la = LiveAudio(p, check_s=0.2).start()
    time.sleep(0.5)
    la._stream.abort()              # the device went away: no more callbacks
    before = la.blocks
    deadline = time.monotonic() + 10
    while la.reopened == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    out = dict(lost=la.lost, reopened=la.reopened, resumed=la.blocks > before)
    la.stop()
    print(json.dumps(out))
""")


@needs_audio
def test_an_interrupted_audio_stream_is_said_and_reopened(tmp_path):
    """Headphones pulled or a Bluetooth link dropped: the callbacks stop; the watch says so on
    stderr and opens the stream again, and the player's cue plays on."""
    sr = 16000
    (tmp_path / ".asoundrc").write_text(ALSA_CONF.format(sr=sr, path=tmp_path / "played.raw"))
    env = {"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([sys.executable, "-c", REOPEN.format(sr=sr)], env=env, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got == {"lost": 1, "reopened": 1, "resumed": True}, (got, proc.stderr)
    assert "audio output lost" in proc.stderr and "audio output back" in proc.stderr


def test_the_audio_watch_counts_a_stream_whose_callbacks_stop_as_lost(capsys):
    """A vanished device can leave PortAudio's stream 'active' with no more callbacks: no new
    block within check_s is a loss too; a failed reopen is retried until one opens."""
    from crossing_assist.runtime.audio import AudioDeviceError, LiveAudio

    class Stream:
        active = True

        def abort(self):
            pass

        close = stop = abort

    class Playing(Stream):            # a stream that calls back: a block between any two checks
        @property
        def active(self):
            la.blocks += 1
            return True

    la = LiveAudio(CuePlayer(BeaconConfig()), check_s=0.05)
    opens = iter([Stream(), AudioDeviceError("gone"), AudioDeviceError("gone"), Playing()])

    def fake_open():
        got = next(opens)
        if isinstance(got, Exception):
            raise got
        return got

    la._open = fake_open
    la.start()                       # the first stream never calls back
    deadline = time.monotonic() + 5
    while la.reopened == 0 and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(0.3)                  # the reopened stream plays: no second loss
    la.stop()
    assert (la.lost, la.reopened) == (1, 1)
    err = capsys.readouterr().err
    assert err.count("audio output lost") == 1 and err.count("audio output back") == 1


def _panning_frames(still: int, turning: int, px: int) -> list[np.ndarray]:
    """A smoothed random texture (something to read the turn from) with one bright bar (the toy's
    goal, in view throughout), seen still for ``still`` frames, then panned ``px`` pixels a frame."""
    rng = np.random.default_rng(3)
    h, w = 72, 96
    scene = rng.uniform(0, 255, (h, w + px * turning, 3))
    for axis in (0, 1):
        scene = sum(np.roll(scene, k, axis=axis) for k in range(-3, 4)) / 7
    scene = np.clip((scene - scene.mean()) * 2 + 60, 0, 120)
    scene[:, 86:94] = 240
    scene = scene.astype(np.uint8)
    offsets = [0] * still + [px * k for k in range(1, turning + 1)]
    # a pixel's worth of sensor noise: a still camera's frames are never identical (else frozen)
    return [np.ascontiguousarray(scene[:, o:o + w]) + rng.integers(0, 2, (h, w, 3), dtype=np.uint8) for o in offsets]


@pytest.mark.parametrize("visual_yaw", [True, False])
def test_without_a_gyroscope_a_decision_the_turn_makes_stale_plays_as_a_stop(toy_bundle, monkeypatch, visual_yaw):  # noqa: F811
    """Live, a decision plays from the end of its model run (0.15 s here, each frame read as the
    last one is decided) until the next one, 0.15 s later, while the user may keep turning. With no gyroscope nothing turns it, so a frame
    whose turn read from the picture (4 px a frame of 96, 30-50 deg/s) carries it past half a strip
    by then plays the stop cue, and the trace gives that turn; so does the still frame's decision
    once the first turned frame is read (before its model run); still frames play the beacon as
    decided. With the picture's turn off (``visual_yaw=False``) nothing is told and nothing stopped."""
    from crossing_assist.runtime.pipeline import trace_record

    engine, clock = Engine(toy_bundle), FakeClock()
    real = engine.predict

    def slow(frame, fov_deg=None, roll_deg=None):
        clock.now += 0.15
        return real(frame, fov_deg, roll_deg)

    monkeypatch.setattr(engine, "predict", slow)
    frames = _panning_frames(6, 8, 4)
    pipeline = Pipeline(engine, engine.decision_config(), BEACON, visual_yaw=visual_yaw)
    steps: list = []
    played: list = []   # each loop handed to the player, and how many steps had come by then

    class Player(CuePlayer):
        def set_loop(self, loop):
            played.append((len(steps), _is_stop(loop)))
            super().set_loop(loop)

    run_live(((clock.now - 100.0, f) for f in frames), pipeline, Player(BEACON), LiveConfig(),
             clock=clock, on_step=lambda i, s: steps.append(s))
    assert len(steps) == len(frames)
    still, turning = steps[1:6], steps[6:]
    assert all(not s.decision.stop and s.stale_turn_deg is None for s in still), [s.decision.reason for s in still]
    fov = pipeline.decider.cfg.fov_deg
    if not visual_yaw:
        assert all(s.yaw_rate_dps == 0 and s.stale_turn_deg is None and s.cut_turn_deg is None for s in steps)
        assert not turning[-1].decision.stop
        return
    assert all(s.yaw_rate_dps > 20 for s in turning), [s.yaw_rate_dps for s in turning]   # turning right
    for s in turning:
        assert s.decision.stop and s.cue.kind == KIND_STOP and _is_stop(s.loop)
        # the rate read, carried through the model's run and the frame interval until the next decision
        assert s.stale_turn_deg == pytest.approx(s.yaw_rate_dps * 0.3) and s.stale_turn_deg > fov / 24
    # the still frame's decision was playing when the first turned frame was read: its turn since
    # then, carried through the next model run, stopped it before that frame's decision came
    assert not steps[5].decision.stop and turning[0].cut_turn_deg == pytest.approx(turning[0].yaw_rate_dps * 0.3)
    assert all(s.cut_turn_deg is None for s in steps[:6] + turning[1:])   # the turning ones were stops already
    assert played[played.index((5, False)) + 1] == (6, True)   # the stop played before that frame's decision
    rec = trace_record(6, turning[0])
    assert rec["stop"] and rec["stale_turn_deg"] == turning[0].stale_turn_deg and rec["yaw_rate_dps"] > 20
    assert rec["cut_turn_deg"] == turning[0].cut_turn_deg


def test_a_video_played_live_behind_a_slow_model_drops_frames_as_a_camera_does(toy_bundle, monkeypatch):  # noqa: F811
    """``pace``: a 10 fps video behind a model that takes 0.25 s a frame. Each decision is of the
    newest frame due when the loop asks (the others are dropped, as a camera's are), so it stays
    fresh to the end; played frame by frame instead, the loop fell 0.15 s further behind each frame
    and every decision from the fifth on came too late to play."""
    engine, clock = Engine(toy_bundle), FakeClock()
    real = engine.predict

    def slow(frame, fov_deg=None, roll_deg=None):
        clock.now += 0.25
        return real(frame, fov_deg, roll_deg)

    def sleep(s):
        assert s > 0
        clock.now += s

    monkeypatch.setattr(engine, "predict", slow)
    video = [(i / 10, bar_frame(0.2 + 0.01 * (i % 2))) for i in range(60)]   # 6 s
    pipeline = Pipeline(engine, engine.decision_config(watchdog_s=0.5), BEACON)
    steps: list = []
    n = run_live(video, pipeline, CuePlayer(BEACON), LiveConfig(watchdog_s=0.5, pace=True, frozen_check=False),
                 clock=clock, sleep=sleep, on_step=lambda i, s: steps.append((i, clock.now, s)))
    index = [i for i, _, _ in steps]
    assert n == 60 and index[0] == 0 and index[-1] >= 57   # the whole video, in its own time
    assert 20 <= len(steps) <= 26, len(steps)               # ~one frame decided every 0.25 s
    assert index == sorted(set(index))                      # the video's own frame numbers, in order
    for i, decided, s in steps:
        assert not s.late and decided - (100.0 + i / 10) <= 0.35 + 1e-9, (i, decided)   # its frame's age
    assert not steps[-1][2].decision.stop
    # a fast model reads every frame, each at its time
    monkeypatch.setattr(engine, "predict", real)
    clock.now, steps = 100.0, []
    run_live(video, pipeline, CuePlayer(BEACON), LiveConfig(watchdog_s=0.5, pace=True, frozen_check=False),
             clock=clock, sleep=sleep, on_step=lambda i, s: steps.append((i, clock.now, s)))
    assert [i for i, _, _ in steps] == list(range(60)) and all(t == 100.0 + i / 10 for i, t, _ in steps)


def _gyro_run(toy_bundle, monkeypatch, rate_dps, turning=12, follow_gyro=False, visual_yaw=True):  # noqa: F811
    """The panning toy camera (6 still frames, then ``turning`` panned 4 px a frame) behind a 0.15 s
    model, with a gyroscope sampled at 100 Hz (an IMU thread, here fed as the clock moves) reading
    ``rate_dps`` while the camera pans and 0 before (None: no gyroscope)."""
    from crossing_assist.runtime.gyro import YawIntegrator

    engine, clock, gyro = Engine(toy_bundle), FakeClock(), YawIntegrator()
    real = engine.predict
    turning_since = [None]

    def slow(frame, fov_deg=None, roll_deg=None):
        for _ in range(15):   # 0.15 s of model run, 100 gyroscope samples a second
            clock.now += 0.01
            on = turning_since[0] is not None and clock.now > turning_since[0]
            gyro.add((rate_dps or 0.0) if on else 0.0, clock.now)
        return real(frame, fov_deg, roll_deg)

    monkeypatch.setattr(engine, "predict", slow)
    gyro.add(0.0, clock.now)
    frames = _panning_frames(6, turning, 4)

    def video():
        for k, f in enumerate(frames):
            if k == 6:
                turning_since[0] = clock.now - 0.15   # the pan began at the frame before's capture
            yield clock.now - 100.0, f

    pipeline = Pipeline(engine, engine.decision_config(), BEACON, visual_yaw=visual_yaw)
    steps: list = []
    run_live(video(), pipeline, CuePlayer(BEACON), LiveConfig(), clock=clock,
             on_step=lambda i, s: steps.append(s), gyro=gyro if rate_dps is not None else None,
             follow_gyro=follow_gyro)
    return pipeline, steps


def test_with_a_gyroscope_followed_the_beacon_turns_with_the_user_instead_of_stopping(toy_bundle, monkeypatch):  # noqa: F811
    """A gyroscope reporting and followed (``follow_gyro``, the app's opt-in): the decision logic is
    told its turn, and each decision plays turned by the gyroscope's turn from its capture to its
    decision, 0.15 s at 30 deg/s = 4.5 deg, instead of the stop the picture's turn gives without one."""
    pipeline, steps = _gyro_run(toy_bundle, monkeypatch, 30.0, follow_gyro=True)
    still, turning = steps[1:6], steps[7:]
    assert all(s.yaw_source == "gyro" for s in steps)
    assert all(not s.decision.stop and s.turn_deg == pytest.approx(0.0) for s in still)
    assert all(s.yaw_rate_dps == pytest.approx(30.0) for s in turning)   # the gyroscope's, told the Decider
    fov = pipeline.decider.cfg.fov_deg
    on = [s for s in turning if not s.decision.stop]
    assert len(on) >= len(turning) - 2, [s.decision.reason for s in turning]
    for s in on:
        assert s.turn_deg == pytest.approx(4.5, abs=0.01) and s.stale_turn_deg is None
        assert s.decision.heading_deg < fov / 2   # turned right: the goal moved left of where it was seen
    # without a gyroscope the same turning decisions are stops: the picture's turn makes them stale
    _, without = _gyro_run(toy_bundle, monkeypatch, None)
    assert all(s.yaw_source == "camera" and s.decision.stop and s.stale_turn_deg for s in without[7:])


def test_a_gyroscope_is_followed_once_the_picture_confirms_it_and_never_when_it_reads_the_wrong_way(toy_bundle, monkeypatch):  # noqa: F811
    """By default a gyroscope is followed once the picture's turn has confirmed its sign (8 frames
    both read turning, as the app's GyroCheck); until then a decision plays as a stop once the
    gyroscope's turn since its capture, carried on at its rate to the end of the play (the next
    decision, a frame interval later), passes half a strip. One reading turns the wrong way is
    found out by the picture and never followed: the picture's turn is the decision logic's."""
    pipeline, right = _gyro_run(toy_bundle, monkeypatch, 30.0)
    sources = [s.yaw_source for s in right]
    first = sources.index("gyro")
    assert set(sources[:first]) == {"camera"} and set(sources[first:]) == {"gyro"} and 6 + 7 <= first < len(right)
    half_strip = pipeline.decider.cfg.fov_deg / 24
    for s in right[7:first]:   # turning, not yet confirmed: the gyroscope's turn stops it
        # 0.15 s of model run turned 4.5 deg, and 30 deg/s for the 0.15 s until the next decision
        assert s.turn_deg == pytest.approx(9.0, abs=0.01) and (s.turn_deg > half_strip) == s.decision.stop
    assert any(not s.decision.stop for s in right[first:])
    _, wrong = _gyro_run(toy_bundle, monkeypatch, -30.0)
    assert all(s.yaw_source == "camera" for s in wrong)
    assert all(s.yaw_rate_dps > 15 for s in wrong[8:])   # the picture's turn, right


def test_between_decisions_the_follower_turns_the_playing_decision_and_never_overrides_a_newer_cue(toy_bundle):  # noqa: F811
    """The :class:`Follower` re-plays the decision playing turned by the gyroscope's turn since its
    capture at each tick; a stop queued since (the watchdog's) is never replaced by a turned cue; a
    gyroscope that stops reporting while a decision plays is a fault: the stop cue."""
    from crossing_assist.runtime.beacon import cue_for
    from crossing_assist.runtime.decide import turned
    from crossing_assist.runtime.gyro import YawIntegrator
    from crossing_assist.runtime.live import Follower

    engine, clock, gyro = Engine(toy_bundle), FakeClock(), YawIntegrator()
    pipeline = Pipeline(engine, engine.decision_config(), BEACON, visual_yaw=False)
    player = CuePlayer(BEACON)
    for k in range(5):
        step = pipeline.step(bar_frame(0.5), k * 0.1)
    assert not step.decision.stop
    stop_loop = render_cue(Cue(KIND_STOP), BEACON)
    follower = Follower(player, pipeline, gyro, stop_loop, clock)
    fov = pipeline.decider.cfg.fov_deg

    def turn_for(seconds, rate):
        for _ in range(int(round(seconds / 0.01))):
            clock.now += 0.01
            gyro.add(rate, clock.now)

    captured = clock.now
    gyro.add(0.0, captured)
    turn_for(0.1, 20.0)
    played = follower.play(step, captured, followed=True)
    assert played.turn_deg == pytest.approx(2.0) and played.decision.heading_deg == pytest.approx(step.decision.heading_deg - 2.0)
    turn_for(0.1, -10.0)
    follower.tick()   # 2 deg right, then 1 back: turned by 1
    want = render_cue(cue_for(turned(step.decision, 1.0, fov)), BEACON)
    assert np.array_equal(player.queued_loop, want)
    follower.stop()   # the watchdog
    turn_for(0.05, 20.0)
    follower.tick()
    assert _is_stop(player.queued_loop)
    follower.play(step, clock.now, followed=True)
    clock.now += 0.3   # no sample for 0.3 s: not reporting
    follower.tick()
    assert _is_stop(player.queued_loop)
    # a follower's own thread ticks too
    turn_for(0.01, 0.0)
    follower.play(step, clock.now, followed=True)
    turn_for(0.1, 30.0)
    follower.start()
    want = render_cue(cue_for(turned(step.decision, 3.0, fov)), BEACON)
    deadline = time.monotonic() + 5
    while not np.array_equal(player.queued_loop, want) and time.monotonic() < deadline:
        time.sleep(0.01)
    follower.close()
    assert np.array_equal(player.queued_loop, want)
