"""Duckietown lane following (map ``udem1``) as a gymnasium environment, headless.

Needs ``duckietown-gym-daffy==6.1.34`` with ``pyglet>=1.5,<1.6`` and ``numpy<1.24`` (its
dynamics build a ragged array), so it lives in its own virtualenv (``.venv-duckietown``; see
docs/iil.md), never in the project's ``.venv``. Rendering uses pyglet's headless EGL
mode (Mesa works, no X server).

* Observation: the 160 x 120 camera frame (the thesis's size; ``obs_size`` resizes it) uint8 RGB.
* Action: ``Box([0, -1], [1, 1])`` = (velocity, steering) in the pure-pursuit teacher's
  units; the steering is multiplied by ``steer_gain`` (10, as gym-duckietown's own imitation
  example does) before it reaches ``DuckietownEnv``.
* Seeding: ``reset(seed=s)`` seeds the simulator's generator AND ``np.random`` (the
  simulator draws from both).
* Reward: the thesis's Eq. 27 with ``c = 0`` (lane following, no obstacles):
  ``R = |v|^2 dir(v) - 10 d`` inside the world, with ``dir(v)`` the cosine between the robot's
  heading and the lane (``dot_dir``), ``d`` the distance from the lane centre (m) and ``v`` the
  speed the simulator's own reward uses (its ``robot_speed``, 1.2: a constant, so the reward
  does not depend on the velocity action, as in the thesis's simulator); 0 when the robot is on
  the road but in no lane. With the measured speed (about 0.3 m/s at the expert's throttle)
  ``|v|^2`` is about 0.09 and the expert's steps would be mostly penalties, which the thesis's
  Table 3 (9 penalty units in 5120 expert steps) rules out. The simulator's proximity term
  (``40 * proximity penalty``: about -1950 per 512 expert steps on udem1, for passing houses)
  is not part of the reward.
* Invalid pose (off the road or a collision; the simulator's ``done``): reward -1000,
  ``info["out_of_bounds"] = True``, terminated; the simulator's own step limit is disabled, so
  the horizon is the caller's alone.
* ``info["reward_terms"]``: ``speed`` (``|v|^2 dir``) and ``lateral`` (``-10 d``), which sum to
  the reward, and ``proximity_unused`` (the simulator's ``40 * proximity penalty``, reported
  for reference only, not part of the reward).
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

from ..protocols import IILDefaults

LANE_HALF_WIDTH_M = 0.15  # risk 1 at this lateral offset from the lane centre
ANGLE_LIMIT_DEG = 45.0


def duckietown_available() -> tuple[bool, str]:
    """(True, "") when the simulator can be imported and an EGL context made here; else
    (False, reason)."""
    try:
        import pyglet  # noqa: PLC0415
        if not pyglet.version.startswith("1.5"):
            return False, f"pyglet {pyglet.version} found; duckietown-gym-daffy needs pyglet 1.5.x"
        pyglet.options["headless"] = True
        import gym_duckietown  # noqa: F401,PLC0415
    except Exception as exc:  # noqa: BLE001 - any import failure means unavailable
        return False, f"gym_duckietown not importable ({type(exc).__name__}: {exc})"
    if tuple(int(p) for p in np.__version__.split(".")[:2]) >= (1, 24):
        return False, f"numpy {np.__version__} found; duckietown-gym-daffy 6.1.34 needs numpy<1.24"
    return True, ""


def _preload_torch_compiler() -> None:
    """Import torch's compiler stack (and triton's LLVM) before Mesa loads its own LLVM for
    the EGL context: the other order segfaults when the optimiser first imports torch._dynamo."""
    try:
        import torch._dynamo  # noqa: F401,PLC0415
    except Exception:  # noqa: BLE001 - torch absent or without a compiler: nothing to preload
        pass


class DuckietownLaneEnv(gym.Env):
    metadata = {"render_modes": []}
    iil_defaults = IILDefaults(expert_threshold=1.0, learner_threshold=0.003, ensemble_threshold=0.003,
                               hg_threshold=0.5, max_discrepancy=0.3)
    source = "duckietown udem1"

    def __init__(self, map_name: str = "udem1", obs_size: tuple[int, int] = (160, 120), steer_gain: float = 10.0,
                 ref_velocity: float = 0.7, following_distance: float = 0.24):
        ok, why = duckietown_available()
        if not ok:
            raise RuntimeError(f"Duckietown is not available here: {why}; see docs/iil.md")
        _preload_torch_compiler()
        from gym_duckietown.envs import DuckietownEnv  # noqa: PLC0415

        self.sim = DuckietownEnv(map_name=map_name, domain_rand=False, max_steps=10**9, camera_width=160,
                                 camera_height=120, distortion=False, full_transparency=True, seed=0)
        self.obs_size, self.steer_gain = tuple(obs_size), float(steer_gain)
        self.ref_velocity, self.following_distance = float(ref_velocity), float(following_distance)
        w, h = self.obs_size
        self.observation_space = gym.spaces.Box(0, 255, (h, w, 3), np.uint8)
        self.action_space = gym.spaces.Box(np.array([0.0, -1.0], np.float32), np.array([1.0, 1.0], np.float32))

    def _obs(self, frame: np.ndarray) -> np.ndarray:
        import cv2  # noqa: PLC0415
        if frame.shape[1::-1] == self.obs_size:
            return np.ascontiguousarray(frame)
        return cv2.resize(np.ascontiguousarray(frame), self.obs_size, interpolation=cv2.INTER_AREA)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if seed is not None:
            np.random.seed(seed % 2**32)
            self.sim.seed(int(seed))
        return self._obs(self.sim.reset()), {}

    def step(self, action):
        v, steer = (float(a) for a in np.asarray(action, dtype=float).reshape(2))
        v, steer = min(max(v, 0.0), 1.0), min(max(steer, -1.0), 1.0)
        frame, sim_reward, done, info = self.sim.step(np.array([v, steer * self.steer_gain]))
        oob = bool(sim_reward <= -1000.0)
        terms = {} if oob else self._terms()
        reward = -1000.0 if oob else terms.get("speed", 0.0) + terms.get("lateral", 0.0)
        return self._obs(frame), float(reward), bool(done), False, {"out_of_bounds": oob, "reward_terms": terms}

    def _terms(self) -> dict:
        """Eq. 27's terms (c = 0) and, for reference, the simulator's proximity term."""
        s = self.sim.unwrapped
        prox = 40.0 * float(s.proximity_penalty2(s.cur_pos, s.cur_angle))
        try:
            lp = s.get_lane_pos2(s.cur_pos, s.cur_angle)
        except Exception:  # noqa: BLE001 - NotInLane
            return {"proximity_unused": prox}
        speed = float(s.robot_speed)
        return {"speed": speed * speed * float(lp.dot_dir), "lateral": -10.0 * abs(float(lp.dist)),
                "proximity_unused": prox}

    # -- the scripted expert -------------------------------------------------------------------
    def _curve_point(self, lookup: float):
        s = self.sim.unwrapped
        point, tangent = s.closest_curve_point(s.cur_pos, s.cur_angle)
        if point is None:
            return None, None, None
        for _ in range(10):
            follow = point + tangent * lookup
            curve_point, curve_tangent = s.closest_curve_point(follow, s.cur_angle)
            if curve_point is not None and curve_tangent is not None:
                return float(np.dot(curve_tangent, tangent)), point, curve_point
            lookup *= 0.5
        return None, None, None

    def oracle(self):
        """Pure pursuit (gym-duckietown's imitation teacher, re-implemented): steer towards a
        point ``following_distance`` ahead on the lane's curve, half speed in curves. Risk
        from the lane pose: max(|d| / 0.15 m, |angle| / 45 deg), 1 when not in a lane."""
        s = self.sim.unwrapped
        projected, _, _ = self._curve_point(0.3)
        _, closest, curve_point = self._curve_point(self.following_distance)
        if closest is None:
            return np.array([0.0, 0.0], np.float32), 1.0
        tile = s._get_tile(*s.get_grid_coords(s.cur_pos))
        slow = (tile is not None and "curve" in tile["kind"]) or (projected is not None and abs(projected) < 0.92)
        vec = curve_point - s.cur_pos
        vec = vec / max(np.linalg.norm(vec), 1e-9)
        right = np.array([math.sin(s.cur_angle), 0.0, math.cos(s.cur_angle)])
        omega = float(np.clip(-np.dot(right, vec), -1.0, 1.0))
        action = np.array([self.ref_velocity * (0.5 if slow else 1.0), omega], np.float32)
        try:
            lp = s.get_lane_pos2(s.cur_pos, s.cur_angle)
            risk = max(abs(float(lp.dist)) / LANE_HALF_WIDTH_M, abs(float(lp.angle_deg)) / ANGLE_LIMIT_DEG)
        except Exception:  # noqa: BLE001 - NotInLane
            risk = 1.0
        return action, float(min(1.0, risk))

    def safe_action(self):
        return np.array([0.0, 0.0], np.float32)

    def close(self):
        self.sim.close()
