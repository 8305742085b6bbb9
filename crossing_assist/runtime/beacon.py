"""Beacon synthesis: a decision becomes a cue, a cue becomes one loop of stereo samples.

Pure functions (numpy) plus :class:`CuePlayer`, the only piece the audio callback touches.

* **Beacon cue**: a pulsed ``tone_hz`` sine, constant-power panned (``theta = (pan + 1) pi/4``,
  ``L = cos theta``, ``R = sin theta``, so ``L^2 + R^2 = 1``), optionally with an interaural time
  difference (Woodworth: ``itd = r/c (phi + sin phi)``, the far ear delayed). The **pulse rate
  says how sure the guidance is**: ``rate_min_hz`` when the gate's best coefficient is at its
  minimum, up to ``rate_max_hz`` when fully confident (slow pulses = slow down, re-scan soon).
* **Stop/scan cue**: centred, two lower descending beeps (``stop_hz`` then ``0.75 stop_hz``)
  once a second: different pitch, rhythm and place from the beacon.
* **No clicks**: each pulse has raised-cosine attack/release ramps and every loop begins and
  ends in silence; :class:`CuePlayer` cross-fades (raised cosine, ``fade_s``) when the cue
  changes and keeps the rhythm's phase.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crossing_assist.runtime.decide import Decision

KIND_BEACON = "beacon"
KIND_STOP = "stop"
KIND_SILENCE = "silence"
HEAD_RADIUS_M = 0.0875
SPEED_OF_SOUND_MS = 343.0


@dataclass(frozen=True)
class BeaconConfig:
    """Sound design. Frequencies in Hz, durations in seconds, ``amplitude`` is the peak in [0, 1]."""

    sample_rate: int = 48000
    tone_hz: float = 1000.0
    pulse_s: float = 0.06
    ramp_s: float = 0.005
    amplitude: float = 0.5
    itd: bool = True
    stop_hz: float = 440.0
    stop_beep_s: float = 0.12
    stop_period_s: float = 1.0
    fade_s: float = 0.01

    def __post_init__(self) -> None:
        if not 8000 <= int(self.sample_rate) <= 192000:
            raise ValueError(f"Invalid sample_rate: {self.sample_rate}; valid: 8000..192000")
        if not 0.0 < self.amplitude <= 1.0:
            raise ValueError(f"Invalid amplitude: {self.amplitude}; valid: 0 < amplitude <= 1")
        if not 0.0 < 2 * self.ramp_s <= self.pulse_s:
            raise ValueError(f"Invalid ramp_s: {self.ramp_s}; valid: 0 < 2 ramp_s <= pulse_s ({self.pulse_s})")


@dataclass(frozen=True)
class Cue:
    """What to play: ``kind`` beacon/stop/silence; ``pan`` in [-1, 1]; ``heading_deg`` (ITD);
    ``rate_hz`` pulses per second (beacon only)."""

    kind: str
    pan: float = 0.0
    heading_deg: float = 0.0
    rate_hz: float = 1.0


SILENCE = Cue(KIND_SILENCE)


def cue_for(decision: Decision) -> Cue:
    """The cue of a decision: the stop/scan cue when it stops, else the panned beacon."""
    if decision.stop or decision.heading_deg is None or decision.pan is None:
        return Cue(KIND_STOP)
    return Cue(KIND_BEACON, pan=float(decision.pan), heading_deg=float(decision.heading_deg),
               rate_hz=float(decision.rate_hz))


def pan_gains(pan: float) -> tuple[float, float]:
    """Constant-power gains ``(L, R)`` for ``pan`` in [-1, 1]: ``L^2 + R^2 = 1``, -1 = left only."""
    p = float(pan)
    if not -1.0 <= p <= 1.0:
        raise ValueError(f"Invalid pan: {pan}; valid: -1 <= pan <= 1")
    theta = (p + 1.0) * math.pi / 4.0
    return math.cos(theta), math.sin(theta)


def itd_seconds(heading_deg: float) -> float:
    """Interaural time difference (s, > 0 = right ear leads) of a source at ``heading_deg``."""
    phi = math.radians(max(-90.0, min(90.0, float(heading_deg))))
    return HEAD_RADIUS_M / SPEED_OF_SOUND_MS * (phi + math.sin(phi))


def _burst(n: int, freq: float, ramp: int, sr: int, amp: float) -> np.ndarray:
    """A tone burst of ``n`` samples with raised-cosine ramps of ``ramp`` samples, shape (n,)."""
    t = np.arange(n) / sr
    env = np.ones(n)
    r = 0.5 - 0.5 * np.cos(np.pi * np.arange(ramp) / ramp)
    env[:ramp] = r
    env[n - ramp:] = r[::-1]
    return amp * env * np.sin(2 * np.pi * freq * t)


def render_cue(cue: Cue, cfg: BeaconConfig) -> np.ndarray:
    """One loop of the cue, float32 (n, 2) stereo, starting and ending in silence.

    Beacon: one period ``round(sr / rate_hz)`` samples holding one pulse; stop: one
    ``stop_period_s`` holding the two beeps; silence: 0.1 s of zeros.
    """
    sr = int(cfg.sample_rate)
    ramp = max(1, round(cfg.ramp_s * sr))
    if cue.kind == KIND_SILENCE:
        return np.zeros((round(0.1 * sr), 2), dtype=np.float32)
    if cue.kind == KIND_STOP:
        n = round(cfg.stop_period_s * sr)
        beep = round(cfg.stop_beep_s * sr)
        mono = np.zeros(n)
        mono[ramp:ramp + beep] = _burst(beep, cfg.stop_hz, ramp, sr, cfg.amplitude)
        start2 = ramp + beep + beep // 2
        mono[start2:start2 + beep] = _burst(beep, 0.75 * cfg.stop_hz, ramp, sr, cfg.amplitude)
        g = math.sqrt(0.5)
        return np.stack([g * mono, g * mono], axis=1).astype(np.float32)
    if cue.kind != KIND_BEACON:
        raise ValueError(f"Unknown cue kind: {cue.kind!r}; valid: beacon, stop, silence")
    if not cue.rate_hz > 0:
        raise ValueError(f"Invalid rate_hz: {cue.rate_hz}; valid: > 0")
    n = round(sr / cue.rate_hz)
    pulse = min(round(cfg.pulse_s * sr), n // 2)
    mono = np.zeros(n)
    mono[ramp:ramp + pulse] = _burst(pulse, cfg.tone_hz, ramp, sr, cfg.amplitude)
    gl, gr = pan_gains(cue.pan)
    left, right = gl * mono, gr * mono
    if cfg.itd:
        lag = round(abs(itd_seconds(cue.heading_deg)) * sr)
        if cue.heading_deg > 0:  # source on the right: the left ear hears it later
            left = np.roll(left, lag)
        else:
            right = np.roll(right, lag)
    return np.stack([left, right], axis=1).astype(np.float32)


def _copy_loop(dst: np.ndarray, buf: np.ndarray, pos: int) -> int:
    """Fill ``dst`` (k, 2) from the looped ``buf`` starting at ``pos``; returns the next position.
    Copies only into existing memory (no array allocation)."""
    n, size, i = len(dst), len(buf), 0
    while i < n:
        k = min(n - i, size - pos)
        dst[i:i + k] = buf[pos:pos + k]
        i += k
        pos = (pos + k) % size
    return pos


class CuePlayer:
    """Plays the latest prepared loop; the real-time side of the beacon.

    Producer thread: :meth:`set_loop` (a reference swap; GIL-atomic, no lock). Audio thread:
    :meth:`fill` copies samples into the device buffer; on a change it cross-fades from the old
    loop over ``fade`` samples using buffers allocated here, in ``__init__``, never in
    :meth:`fill`. A change arriving during a fade waits until the fade ends.
    """

    def __init__(self, cfg: BeaconConfig) -> None:
        self.cfg = cfg
        self._fade_n = max(1, round(cfg.fade_s * cfg.sample_rate))
        i = np.arange(self._fade_n, dtype=np.float64)
        up = (0.5 - 0.5 * np.cos(np.pi * (i + 1) / (self._fade_n + 1))).astype(np.float32)
        self._up = up[:, None].copy()
        self._down = (1.0 - up)[:, None].copy()
        self._scratch = np.zeros((self._fade_n, 2), dtype=np.float32)  # the old loop during a fade
        silent = render_cue(SILENCE, cfg)
        self._next = silent
        self._cur = silent
        self._old = silent
        self._pos = 0
        self._old_pos = 0
        self._fade_i = self._fade_n

    @property
    def queued_loop(self) -> np.ndarray:
        """The loop most recently queued with :meth:`set_loop` (what plays next)."""
        return self._next

    def set_loop(self, loop: np.ndarray) -> None:
        """Make ``loop`` (n, 2) float32, from :func:`render_cue`, the next thing played."""
        self._next = loop

    def set_cue(self, cue: Cue) -> np.ndarray:
        """Render ``cue`` (producer side) and queue it; returns the loop."""
        loop = render_cue(cue, self.cfg)
        self.set_loop(loop)
        return loop

    def fill(self, out: np.ndarray) -> None:
        """Write ``len(out)`` frames into ``out`` (n, 2) float32 in place; audio-callback safe."""
        n = len(out)
        nxt = self._next
        if nxt is not self._cur and self._fade_i >= self._fade_n:
            self._old, self._old_pos = self._cur, self._pos
            self._pos = (self._pos * len(nxt)) // len(self._cur)
            self._cur = nxt
            self._fade_i = 0
        self._pos = _copy_loop(out, self._cur, self._pos)
        if self._fade_i < self._fade_n:
            k = min(n, self._fade_n - self._fade_i)
            old = self._scratch[:k]
            self._old_pos = _copy_loop(old, self._old, self._old_pos)
            j = self._fade_i
            np.multiply(out[:k], self._up[j:j + k], out=out[:k])
            np.multiply(old, self._down[j:j + k], out=old)
            np.add(out[:k], old, out=out[:k])
            self._fade_i += k

    def render(self, n: int, block: int = 4096) -> np.ndarray:
        """Offline: the next ``n`` frames as a new (n, 2) float32 array."""
        out = np.zeros((n, 2), dtype=np.float32)
        for i in range(0, n, block):
            self.fill(out[i:i + block])
        return out
