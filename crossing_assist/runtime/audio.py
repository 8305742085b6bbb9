"""Audio out: a live sounddevice stream fed by a :class:`CuePlayer`, and WAV files (soundfile).

sounddevice (PortAudio) is imported only inside :meth:`LiveAudio.start`, so importing this
module needs no audio library. The stream callback calls :meth:`CuePlayer.fill` and nothing
else: it copies prepared samples (no inference, allocation, locks or I/O).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crossing_assist.errors import UserError
from crossing_assist.fileio import atomic_path
from crossing_assist.runtime.beacon import CuePlayer


class AudioDeviceError(UserError, RuntimeError):
    """No usable audio output; the message is one line saying what to do."""


class LiveAudio:
    """A stereo float32 output stream playing ``player``; use as a context manager.

    ``device`` is a sounddevice device index or name (None = the system default).
    """

    def __init__(self, player: CuePlayer, *, device: int | str | None = None, blocksize: int = 512) -> None:
        self.player = player
        self.device = device
        self.blocksize = int(blocksize)
        self.status_count = 0
        self._stream = None

    def _callback(self, outdata: np.ndarray, frames: int, time, status) -> None:  # noqa: ARG002
        if status:
            self.status_count += 1
        self.player.fill(outdata)

    def start(self) -> "LiveAudio":
        """Open and start the stream; raises :class:`AudioDeviceError` (one line) when impossible."""
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
        self._stream = stream
        return self

    def stop(self) -> None:
        """Stop and close the stream (idempotent)."""
        stream, self._stream = self._stream, None
        if stream is not None:
            stream.stop()
            stream.close()

    def __enter__(self) -> "LiveAudio":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def write_wav(path: str | Path, samples: np.ndarray, sample_rate: int) -> Path:
    """Write (n, 2) float samples in [-1, 1] as 16-bit PCM WAV, atomically; returns the path."""
    import soundfile as sf

    path = Path(path)
    with atomic_path(path) as tmp:
        sf.write(tmp, np.clip(samples, -1.0, 1.0), int(sample_rate), subtype="PCM_16", format="WAV")
    return path
