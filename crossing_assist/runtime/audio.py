"""Audio out: a live sounddevice stream fed by a :class:`CuePlayer`, and WAV files (soundfile).

sounddevice (PortAudio) is imported only inside :meth:`LiveAudio.start`, so importing this
module needs no audio library. The stream callback calls :meth:`CuePlayer.fill` and counts the
block: it copies prepared samples (no inference, locks or I/O).

Audio gets interrupted in the field (headphones pulled, a Bluetooth link dropped): a watch thread
sees the callbacks stop (or the stream go inactive), says so on stderr, and reopens the stream
every ``check_s`` until it plays again; the player keeps the latest decision's cue (the watchdog
puts the stop cue there when decisions go stale), so what resumes is never an old direction.
"""

from __future__ import annotations

import sys
import threading
from pathlib import Path

import numpy as np

from crossing_assist.errors import UserError
from crossing_assist.fileio import atomic_path
from crossing_assist.runtime.beacon import CuePlayer


class AudioDeviceError(UserError, RuntimeError):
    """No usable audio output; the message is one line saying what to do."""


class LiveAudio:
    """A stereo float32 output stream playing ``player``; use as a context manager.

    ``device`` is a sounddevice device index or name (None = the system default); ``check_s``:
    how often the watch thread looks for a dead stream (None: no watch). ``lost`` and ``reopened``
    count the interruptions seen and the streams opened again.
    """

    def __init__(self, player: CuePlayer, *, device: int | str | None = None, blocksize: int = 512,
                 check_s: float | None = 1.0) -> None:
        self.player = player
        self.device = device
        self.blocksize = int(blocksize)
        if check_s is not None and not check_s > 0:
            raise ValueError(f"check_s {check_s!r}: a positive number of seconds, or None for no watch")
        self.check_s = check_s
        self.status_count = 0
        self.blocks = 0
        self.lost = 0
        self.reopened = 0
        self._stream = None
        self._closing = threading.Event()
        self._watch: threading.Thread | None = None

    def _callback(self, outdata: np.ndarray, frames: int, time, status) -> None:  # noqa: ARG002
        if status:
            self.status_count += 1
        self.player.fill(outdata)
        self.blocks += 1

    def _open(self):
        """A started output stream; AudioDeviceError (one line) when impossible."""
        try:
            import sounddevice as sd
        except (ImportError, OSError) as exc:
            raise AudioDeviceError(f"no audio output: sounddevice/PortAudio unavailable ({exc}); "
                                   "install libportaudio2 and 'pip install sounddevice', or run without --live") from None
        try:
            stream = sd.OutputStream(samplerate=self.player.cfg.sample_rate, channels=2, dtype="float32",
                                     blocksize=self.blocksize, device=self.device, callback=self._callback)
            stream.start()
        except (sd.PortAudioError, ValueError, OSError) as exc:
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise AudioDeviceError(f"no audio output device ({msg}); connect headphones or pick one "
                                   "with --audio-device, or run without --live") from None
        return stream

    def start(self) -> "LiveAudio":
        """Open and start the stream, and the watch; raises :class:`AudioDeviceError` (one line)
        when no stream can be opened."""
        self._stream = self._open()
        if self.check_s is not None:
            self._closing.clear()
            self._watch = threading.Thread(target=self._watch_loop, name="audio-watch", daemon=True)
            self._watch.start()
        return self

    def _watch_loop(self) -> None:
        seen = -1
        while not self._closing.wait(self.check_s):
            stream = self._stream
            if stream is not None and stream.active and self.blocks != seen:
                seen = self.blocks
                continue
            if stream is not None:       # callbacks stopped or the stream ended: it is gone
                self.lost += 1
                print("audio output lost (device disconnected?); retrying every "
                      f"{self.check_s:g} s; guidance is silent until it plays again", file=sys.stderr)
                self._stream = None
                _close(stream)
            try:
                self._stream = self._open()
            except AudioDeviceError:
                continue
            self.reopened += 1
            seen = -1
            print("audio output back", file=sys.stderr)

    def stop(self) -> None:
        """Stop the watch, then stop and close the stream (idempotent)."""
        self._closing.set()
        if self._watch is not None:
            self._watch.join()
            self._watch = None
        stream, self._stream = self._stream, None
        if stream is not None:
            try:
                stream.stop()
                stream.close()
            except Exception:  # noqa: BLE001 - the device went away under it: abort instead
                _close(stream)

    def __enter__(self) -> "LiveAudio":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _close(stream) -> None:
    """Close a stream whose device may be gone, without raising."""
    try:
        stream.abort()
        stream.close()
    except Exception:  # noqa: BLE001 - PortAudio's errors on a vanished device vary; it is closed either way
        pass


def write_wav(path: str | Path, samples: np.ndarray, sample_rate: int) -> Path:
    """Write (n, 2) float samples in [-1, 1] as 16-bit PCM WAV, atomically; returns the path."""
    import soundfile as sf

    path = Path(path)
    with atomic_path(path) as tmp:
        sf.write(tmp, np.clip(samples, -1.0, 1.0), int(sample_rate), subtype="PCM_16", format="WAV")
    return path
