"""Beacon synthesis: constant-power pan, ITD, pulse rate, the stop cue, click-free changes."""

import numpy as np
import pytest

from crossing_assist.runtime.beacon import (KIND_BEACON, KIND_STOP, BeaconConfig, Cue, CuePlayer, pan_gains,
                                            render_cue)

CFG = BeaconConfig(sample_rate=16000)


def energy(x: np.ndarray) -> np.ndarray:
    return (x.astype(np.float64) ** 2).sum(axis=0)


def dominant_hz(mono: np.ndarray, sr: int) -> float:
    spec = np.abs(np.fft.rfft(mono))
    return float(np.fft.rfftfreq(len(mono), 1 / sr)[np.argmax(spec)])


@pytest.mark.parametrize("pan", np.linspace(-1, 1, 21))
def test_pan_is_constant_power(pan):
    left, right = pan_gains(pan)
    assert left ** 2 + right ** 2 == pytest.approx(1.0, abs=1e-12)
    assert left >= 0 and right >= 0


def test_pan_sign_and_ends():
    assert pan_gains(-1.0) == pytest.approx((1.0, 0.0))
    assert pan_gains(1.0) == pytest.approx((0.0, 1.0))
    with pytest.raises(ValueError):
        pan_gains(1.5)


@pytest.mark.parametrize("heading,pan", [(-30.0, -0.66), (0.0, 0.0), (40.0, 0.9)])
def test_rendered_beacon_energy_follows_the_pan(heading, pan):
    loop = render_cue(Cue(KIND_BEACON, pan=pan, heading_deg=heading, rate_hz=3.0), CFG)
    el, er = energy(loop)
    gl, gr = pan_gains(pan)
    assert el / (el + er) == pytest.approx(gl ** 2, abs=1e-3)
    assert dominant_hz(loop.sum(1), CFG.sample_rate) == pytest.approx(CFG.tone_hz, abs=5)


def test_itd_delays_the_far_ear():
    cfg = BeaconConfig(sample_rate=48000)
    loop = render_cue(Cue(KIND_BEACON, pan=0.0, heading_deg=60.0, rate_hz=3.0), cfg)
    first = [int(np.argmax(np.abs(loop[:, ch]) > 1e-4)) for ch in (0, 1)]
    assert first[0] - first[1] == round(cfg.sample_rate * 0.0875 / 343 * (np.pi / 3 + np.sin(np.pi / 3)))
    flat = render_cue(Cue(KIND_BEACON, pan=0.0, heading_deg=60.0, rate_hz=3.0), BeaconConfig(sample_rate=48000, itd=False))
    assert np.array_equal(flat[:, 0], flat[:, 1])


def test_pulse_rate_sets_the_loop_length_and_loops_start_and_end_silent():
    for rate in (2.0, 4.0, 6.0):
        loop = render_cue(Cue(KIND_BEACON, pan=0.2, heading_deg=9.0, rate_hz=rate), CFG)
        assert len(loop) == round(CFG.sample_rate / rate)
        assert np.all(loop[:3] == 0) and np.all(loop[-3:] == 0)
        assert loop.dtype == np.float32 and loop.shape[1] == 2


def test_stop_cue_is_distinct_centred_and_lower():
    stop = render_cue(Cue(KIND_STOP), CFG)
    assert np.allclose(stop[:, 0], stop[:, 1])
    assert dominant_hz(stop[:, 0], CFG.sample_rate) < CFG.tone_hz / 1.5
    assert len(stop) == round(CFG.stop_period_s * CFG.sample_rate)
    active = np.abs(stop[:, 0]) > 1e-3
    onsets = np.flatnonzero(np.diff(active.astype(int)) == 1)
    assert len(onsets) >= 2  # two beeps, not one pulse


def max_step(x: np.ndarray) -> float:
    return float(np.abs(np.diff(x, axis=0)).max())


def test_cue_changes_never_click():
    """Switching cues every few ms (random pans, rates, stop) keeps every sample-to-sample step
    below what the tone itself does; a bare switch without the player's fade clicks."""
    cfg = BeaconConfig(sample_rate=48000)
    tone_step = 2 * np.pi * cfg.tone_hz / cfg.sample_rate * cfg.amplitude
    bound = 1.15 * tone_step
    rng = np.random.default_rng(0)
    player = CuePlayer(cfg)
    out = []
    for i in range(200):
        if i % 17 == 5:
            cue = Cue(KIND_STOP)
        else:
            pan = float(rng.uniform(-1, 1))
            cue = Cue(KIND_BEACON, pan=pan, heading_deg=45 * pan, rate_hz=float(rng.uniform(2, 6)))
        player.set_cue(cue)
        out.append(player.render(int(rng.integers(100, 1800)), block=int(rng.integers(16, 512))))
    audio = np.concatenate(out)
    assert np.abs(audio).max() > 0.3  # it did play
    assert max_step(audio) < bound
    # the same changes spliced without a fade would click: the test can tell
    a = render_cue(Cue(KIND_BEACON, pan=-1.0, heading_deg=-45, rate_hz=2.0), cfg)
    b = render_cue(Cue(KIND_BEACON, pan=1.0, heading_deg=45, rate_hz=2.0), cfg)
    mid = np.flatnonzero(np.abs(a[:, 0]) > 0.4)[0]
    assert max_step(np.concatenate([a[:mid], b[mid:]])) > 2 * bound


def test_player_keeps_the_rhythm_phase_and_plays_the_loop_exactly():
    player = CuePlayer(CFG)
    loop = player.set_cue(Cue(KIND_BEACON, pan=0.5, heading_deg=20.0, rate_hz=4.0))
    got = player.render(3 * len(loop), block=3 * len(loop))  # one big block: any size works
    fade = round(CFG.fade_s * CFG.sample_rate)
    want = np.tile(loop, (3, 1))
    assert np.allclose(got[fade:], want[fade:], atol=1e-7)


def test_fill_allocates_no_sample_buffers():
    """The audio callback's work: after warm-up, 300 fills across cue changes and fades
    allocate no sample buffers (one 4096-frame stereo block would be 32 KB; Python's small
    objects, views and ints, stay far below)."""
    import tracemalloc

    cfg = BeaconConfig(sample_rate=48000)
    player = CuePlayer(cfg)
    loops = [render_cue(Cue(KIND_BEACON, pan=p, heading_deg=40 * p, rate_hz=2 + 4 * abs(p)), cfg)
             for p in (-0.8, 0.0, 0.7)] + [render_cue(Cue(KIND_STOP), cfg)]
    out = np.zeros((4096, 2), dtype=np.float32)
    for loop in loops:
        player.set_loop(loop)
        player.fill(out)
    tracemalloc.start()
    base, _ = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    for i in range(300):
        if i % 10 == 0:
            player.set_loop(loops[(i // 10) % len(loops)])
        player.fill(out)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak - base < 12 * 1024
