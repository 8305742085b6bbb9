"""Watchdog: when no fresh decision arrived within ``period_s`` the beacon stops.

Independent of the decision logic (defence in depth): a thread polls :meth:`Watchdog.poll`
every ``poll_s``; a stalled camera, a hung inference or a crashed loop all stop beating it.
The clock is injectable so tests can freeze time.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

DEFAULT_WATCHDOG_S = 0.5   # the longest time without a fresh decision before the beacon stops


class Ticker:
    """``fn()`` every ``period_s`` on a daemon thread named ``name``, from :meth:`start` until
    :meth:`stop` (the watchdog's poll, the live loop's gyroscope follower)."""

    def __init__(self, period_s: float, fn: Callable[[], None], name: str) -> None:
        self.period_s, self.fn, self.name = period_s, fn, name
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> "Ticker":
        def loop() -> None:
            while not self._stop.wait(self.period_s):
                self.fn()
        self._thread = threading.Thread(target=loop, name=self.name, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None


class Watchdog:
    """Calls ``on_stale()`` once each time ``clock() - last_beat > period_s`` becomes true."""

    def __init__(self, period_s: float, on_stale: Callable[[], None], *,
                 clock: Callable[[], float] = time.monotonic, poll_s: float | None = None) -> None:
        if not period_s > 0:
            raise ValueError(f"Invalid watchdog period: {period_s}; valid: > 0 seconds")
        self.period_s = float(period_s)
        self.on_stale = on_stale
        self.clock = clock
        self.poll_s = float(poll_s) if poll_s else min(0.02, self.period_s / 10)
        self._last = clock()
        self.stale = False
        self.fired = 0
        self._ticker = Ticker(self.poll_s, self.poll, "crossing-watchdog")

    def beat(self, t: float | None = None) -> None:
        """A fresh decision (made from a frame captured at clock time ``t``; default now)."""
        self._last = self.clock() if t is None else float(t)
        self.stale = False

    def age(self) -> float:
        """Seconds since the last beat."""
        return self.clock() - self._last

    def poll(self) -> bool:
        """Check now; returns whether the beacon is stale (fires ``on_stale`` on the transition)."""
        if self.age() > self.period_s:
            if not self.stale:
                self.stale = True
                self.fired += 1
                self.on_stale()
            return True
        return False

    def start(self) -> "Watchdog":
        """Poll in a daemon thread until :meth:`stop`."""
        self._ticker.start()
        return self

    def stop(self) -> None:
        """Stop the polling thread."""
        self._ticker.stop()
