"""Experts: ``act(obs) -> (action or None, uncertainty >= 0)``.

``None`` means the expert offers no action this step (a human who is not pressing a key);
its uncertainty is then ``inf``. A *continuous* uncertainty matters: UPMS's exploration
branch fires with probability ``1 - alpha(U_T)``, which is never positive for an expert that
only says 0 or inf while answering.

* :class:`OracleExpert` - asks the environment's privileged ``oracle()`` (our environments
  implement it: the crossing's true bin, Duckietown's pure-pursuit controller, the toy
  env's target) and reports its confidence from the environment's risk measure.
* :class:`HumanExpert` - a person at a keyboard or gamepad; events arrive through an
  :class:`EventSource` (real: :class:`PygameWindow`, a window that shows the learner's frame
  and reads the keys; tests: :class:`ScriptedEvents`, or the real window fed synthetic events).

Counting interventions and labels is the loop's job (see :mod:`crossing_assist.iil.loop`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable, Protocol

import numpy as np

from .protocols import Expert, iil_env  # noqa: F401 (Expert: the contract, re-exported)


def risk_to_uncertainty(risk: float, scale: float = 1.0) -> float:
    """Map a risk in [0, 1] (0 = perfectly safe, 1 = about to fail) to an uncertainty in
    [0, inf]: ``scale * (1 - r) / r``. A worried expert (r -> 1) is certain (U -> 0); a
    relaxed one (r -> 0) does not care which action is taken (U -> inf)."""
    r = float(np.clip(risk, 0.0, 1.0))
    return math.inf if r == 0.0 else scale * (1.0 - r) / r


class OracleExpert:
    """Scripted expert over an environment with ``oracle() -> (action, risk in [0, 1])``.

    ``binary_risk=None`` (default): always answers, with the continuous uncertainty
    :func:`risk_to_uncertainty`. ``binary_risk=r0``: the thesis's expert, whose uncertainty is
    only 0 (risk above ``r0``: it wants to intervene) or inf (otherwise); its action is still
    there when asked (the thesis's teacher labels every state it is asked about)."""

    def __init__(self, env, scale: float = 1.0, binary_risk: float | None = None):
        self.env, self.scale, self.binary_risk = env, float(scale), binary_risk
        self._oracle = iil_env(env).oracle

    def act(self, obs: np.ndarray) -> tuple[object | None, float]:
        action, risk = self._oracle()
        if action is None:
            return None, math.inf
        if self.binary_risk is not None:
            return action, (0.0 if risk > self.binary_risk else math.inf)
        return action, risk_to_uncertainty(risk, self.scale)


class EventSource(Protocol):
    """Input events: ``poll() -> list of (kind, value)``; kind ``"down"``/``"up"`` with a key
    name, or ``"axis"`` with a float in [-1, 1] (gamepad stick, right positive)."""

    def poll(self) -> list[tuple[str, object]]: ...


class ScriptedEvents:
    """An :class:`EventSource` that replays a fixed script: ``script[k]`` are the events
    delivered at the k-th poll (empty list: nothing happened). Used by tests and demos."""

    def __init__(self, script: Iterable[list[tuple[str, object]]]):
        self._script = list(script)
        self._k = 0

    def poll(self) -> list[tuple[str, object]]:
        events = self._script[self._k] if self._k < len(self._script) else []
        self._k += 1
        return list(events)


@dataclass(frozen=True)
class KeyMap:
    """Keys to discrete actions: ``keys[name] = action``. Default for the 13 crossing bins:
    ``1``..``9``, ``0``, ``-``, ``=`` are bins 1..12 and space is ``unknown`` (stop)."""

    keys: dict

    @staticmethod
    def crossing() -> "KeyMap":
        names = ["1", "2", "3", "4", "5", "6", "7", "8", "9", "0", "-", "="]
        return KeyMap({**{k: b + 1 for b, k in enumerate(names)}, "space": 0})

    @staticmethod
    def toy() -> "KeyMap":
        """The toy lane: left / right arrows steer, space stays."""
        return KeyMap({"left": 1, "right": 2, "space": 0})


class HumanExpert:
    """A person steering with keys (discrete actions) or a gamepad axis (mapped by
    ``axis_to_action``). While a key is held the expert acts with uncertainty 0; with no
    key held it gives no action (None, inf). A gamepad deflection ``|v|`` gives a continuous
    confidence: ``U = (1 - |v|) / |v|`` (full deflection: certain; centred: no action)."""

    def __init__(self, events: EventSource, keymap: KeyMap | None = None,
                 axis_to_action: Callable[[float], object] | None = None):
        self.events, self.keymap, self.axis_to_action = events, keymap or KeyMap.crossing(), axis_to_action
        self._held: list[str] = []
        self._axis = 0.0

    def act(self, obs: np.ndarray) -> tuple[object | None, float]:
        show = getattr(self.events, "show", None)
        if show is not None and obs is not None:
            show(obs)  # a window: the person sees what the learner sees, then we read the keys
        for kind, value in self.events.poll():
            if kind == "quit":
                raise KeyboardInterrupt("the expert closed the window")
            if kind == "down" and value in self.keymap.keys and value not in self._held:
                self._held.append(value)
            elif kind == "up" and value in self._held:
                self._held.remove(value)
            elif kind == "axis":
                self._axis = float(np.clip(value, -1.0, 1.0))
        if self._held:
            return self.keymap.keys[self._held[-1]], 0.0
        if self.axis_to_action is not None and abs(self._axis) > 0.05:
            return self.axis_to_action(self._axis), risk_to_uncertainty(abs(self._axis))
        return None, math.inf


class PygameWindow:
    """A real window (pygame, imported lazily; ``pip install pygame`` or the ``human`` extra):
    :meth:`show` draws the frame the learner sees, scaled up, at most ``fps`` frames a second
    (the pace a person can follow); :meth:`poll` returns its keyboard/gamepad events (``quit``
    when the window is closed). Without a display, SDL's ``dummy`` video driver gives a window
    that receives posted events (how the tests drive it)."""

    NAMES = {"minus": "-", "equals": "="}

    def __init__(self, scale: int = 6, fps: float = 5.0, caption: str = "crossing-iil: you are the expert"):
        try:
            import pygame  # noqa: PLC0415
        except ImportError as exc:
            raise RuntimeError("the human expert needs pygame: pip install pygame (or '.[human]')") from exc
        self.pg, self.scale, self.fps = pygame, int(scale), float(fps)
        pygame.display.init()
        pygame.joystick.init()
        self.sticks = [pygame.joystick.Joystick(k) for k in range(pygame.joystick.get_count())]
        self.caption, self.screen, self.clock, self.frames = caption, None, pygame.time.Clock(), 0

    def show(self, frame: np.ndarray) -> None:
        pg = self.pg
        h, w = frame.shape[:2]
        if self.screen is None:
            self.screen = pg.display.set_mode((w * self.scale, h * self.scale))
            pg.display.set_caption(self.caption)
        surf = pg.surfarray.make_surface(np.ascontiguousarray(np.asarray(frame, np.uint8).transpose(1, 0, 2)))
        self.screen.blit(pg.transform.scale(surf, self.screen.get_size()), (0, 0))
        pg.display.flip()
        self.frames += 1
        if self.fps > 0:
            self.clock.tick(self.fps)

    def poll(self) -> list[tuple[str, object]]:
        pg, out = self.pg, []
        for ev in pg.event.get():
            if ev.type == pg.QUIT:
                out.append(("quit", None))
            elif ev.type in (pg.KEYDOWN, pg.KEYUP):
                name = pg.key.name(ev.key)
                out.append(("down" if ev.type == pg.KEYDOWN else "up", self.NAMES.get(name, name)))
            elif ev.type == pg.JOYAXISMOTION and ev.axis == 0:
                out.append(("axis", float(ev.value)))
        return out

    def close(self) -> None:
        self.pg.display.quit()


PygameEvents = PygameWindow  # the earlier name
