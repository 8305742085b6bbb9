"""A tiny, fast lane for unit tests: a 16 x 16 frame shows a bright column at the agent's
lateral position; three actions (0 stay, 1 left, 2 right); drift pushes it off-centre."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from ..protocols import IILDefaults


class ToyLaneEnv(gym.Env):
    """Position ``x`` in [-1, 1]; ``|x| > 1`` is out of bounds (reward -1000, terminated).
    Reward ``0.5 - |x|`` per step (negative beyond 0.5: a penalty)."""

    metadata = {"render_modes": []}
    iil_defaults = IILDefaults(expert_threshold=1.0, learner_threshold=0.5, ensemble_threshold=0.05,
                               hg_threshold=1.0)

    def __init__(self, size: int = 16, drift: float = 0.15):
        self.size, self.drift = int(size), float(drift)
        self.observation_space = gym.spaces.Box(0, 255, (self.size, self.size, 3), np.uint8)
        self.action_space = gym.spaces.Discrete(3)
        self.x = 0.0

    def _obs(self) -> np.ndarray:
        img = np.zeros((self.size, self.size, 3), np.uint8)
        col = int(np.clip((self.x + 1) / 2 * (self.size - 1), 0, self.size - 1))
        img[:, col] = 255
        return img

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = float(self.np_random.uniform(-0.3, 0.3))
        return self._obs(), {}

    def step(self, action):
        move = {0: 0.0, 1: -0.2, 2: 0.2}[int(action)]
        self.x += move + float(self.np_random.normal(0.0, self.drift))
        oob = abs(self.x) > 1.0
        reward = -1000.0 if oob else 0.5 - abs(self.x)
        info = {"out_of_bounds": oob, "reward_terms": {} if oob else {"centre": 0.5 - abs(self.x)}}
        return self._obs(), reward, oob, False, info

    def oracle(self):
        """Steer back to the centre; risk is how far off-centre the agent is."""
        action = 0 if abs(self.x) < 0.1 else (1 if self.x > 0 else 2)
        return action, min(1.0, abs(self.x))

    def safe_action(self):
        return 0
