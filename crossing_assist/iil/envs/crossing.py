"""A street crossing for interactive imitation learning.

A walker stands at the near kerb of a crossing ``length`` metres long and ``2 * half_width``
wide and walks towards the far end. Its heading drifts (a per-crossing veering bias plus
noise, in degrees per step), as a blind pedestrian's does. Each step the guidance policy
sees the frame the phone camera would show for the walker's heading and answers one of the
13 actions (``crossing_assist.actions``: 0 = unknown, 1..12 = the strip holding the far end).
A bin turns the walker by ``turn_gain`` times that strip's heading and it walks ``step_m``;
``unknown`` makes it stop and scan (no progress, no turn).

Frames: real PTL photos re-rendered by a yaw homography (the rotation of
``data_tools.augment.yaw``) so that the far end appears at the walker's current bearing; or,
without the photos, a simple synthetic zebra crossing drawn for that bearing. Lateral offset
changes only the bearing (no parallax is rendered). The part of the turned view that the photo
does not cover is filled by reflecting the photo at its edges (:func:`yaw_reflect`), never left
black: a black border's side and width would tell the learner the label.

Reward per step: ``progress - |y| / half_width`` (progress = metres gained towards the far
kerb / step_m); leaving the corridor (``|y| > half_width``) is out of bounds (-1000,
terminated); reaching the far kerb ends the crossing (terminated, a new one starts).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

from crossing_assist.actions import DEFAULT_FOV_DEG, N_BINS, UNKNOWN, get_space, heading_to_x, x_to_bin, x_to_heading
from crossing_assist.iil.protocols import IILDefaults

SHARED_PTL = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "ptl"


@dataclass(frozen=True)
class CrossingConfig:
    """``photos``: a PTL folder, ``"auto"`` ($CROSSING_PTL_DIR, else ../shared/data/ptl, when
    present; otherwise synthetic frames) or None (synthetic)."""

    photos: str | None = "auto"
    n_photos: int = 48
    width: int = 64
    height: int = 48
    length_m: float = 12.0
    half_width_m: float = 1.5
    step_m: float = 0.5
    turn_gain: float = 0.7
    veer_deg: float = 3.0      # max |per-crossing bias| in degrees per step
    noise_deg: float = 2.0     # heading noise per step (std, degrees)
    start_heading_deg: float = 25.0  # max |initial heading| (the walker at the corner turns)
    fov_deg: float = DEFAULT_FOV_DEG


def _load_photos(cfg: CrossingConfig, rng: np.random.Generator) -> list[tuple[np.ndarray, float]]:
    env_dir = os.environ.get("CROSSING_PTL_DIR")
    root = (Path(env_dir) if env_dir else SHARED_PTL) if cfg.photos == "auto" else Path(cfg.photos)
    if cfg.photos == "auto" and not (root / "labels.csv").is_file():
        return []
    from crossing_assist.data_tools.images import load_rgb  # noqa: PLC0415
    from crossing_assist.data_tools.ptl import read_ptl_labels  # noqa: PLC0415

    rows = [r for r in read_ptl_labels(root) if r.split == "train" and r.far_x is not None]
    pick = rng.choice(len(rows), size=min(cfg.n_photos, len(rows)), replace=False)
    out = []
    for k in pick:
        img = load_rgb(root / rows[k].image)
        img = cv2.resize(img, (2 * cfg.width, 2 * cfg.height), interpolation=cv2.INTER_AREA)  # undo 4:3 squash
        out.append((img, rows[k].far_x))
    return out


class CrossingEnv(gym.Env):
    metadata = {"render_modes": []}
    iil_defaults = IILDefaults(expert_threshold=1.0, learner_threshold=1.0, ensemble_threshold=0.05,
                               hg_threshold=0.5)

    def __init__(self, cfg: CrossingConfig = CrossingConfig(), photo_seed: int = 0):
        self.cfg = cfg
        self.space13 = get_space(13)
        self.observation_space = gym.spaces.Box(0, 255, (cfg.height, cfg.width, 3), np.uint8)
        self.action_space = gym.spaces.Discrete(N_BINS + 1)
        self.photos = _load_photos(cfg, np.random.default_rng(photo_seed)) if cfg.photos else []
        self.source = "ptl" if self.photos else "synthetic"
        self.y = self.s = self.phi = self.bias = 0.0
        self.photo = 0

    # -- geometry -------------------------------------------------------------------------
    def bearing(self) -> float:
        """Heading (degrees, right positive) of the far end relative to where the walker faces."""
        b = math.degrees(math.atan2(-self.y, max(self.cfg.length_m - self.s, 1e-3)))
        return (b - self.phi + 180.0) % 360.0 - 180.0

    def true_bin(self) -> int:
        """The strip holding the far end, or unknown when it is outside the field of view."""
        h = self.bearing()
        if abs(h) >= self.cfg.fov_deg / 2:
            return UNKNOWN
        return x_to_bin(min(max(heading_to_x(h, self.cfg.fov_deg), 0.0), 1.0))

    # -- gymnasium --------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        r = self.np_random
        self.y, self.s = float(r.uniform(-0.3, 0.3)), 0.0
        self.phi = float(r.uniform(-self.cfg.start_heading_deg, self.cfg.start_heading_deg))
        self.bias = float(r.uniform(-self.cfg.veer_deg, self.cfg.veer_deg))
        self.photo = int(r.integers(0, len(self.photos))) if self.photos else 0
        return self._obs(), {}

    def step(self, action):
        a = int(action)
        if not 0 <= a <= N_BINS:
            raise ValueError(f"Invalid action: {action}; valid: 0..12")
        c, r = self.cfg, self.np_random
        progress = 0.0
        if a != UNKNOWN:
            self.phi += c.turn_gain * self.space13.action_heading(a, c.fov_deg)
            self.phi += self.bias + float(r.normal(0.0, c.noise_deg))
            rad = math.radians(self.phi)
            self.s += c.step_m * math.cos(rad)
            self.y += c.step_m * math.sin(rad)
            progress = math.cos(rad)
        oob = abs(self.y) > c.half_width_m
        done = oob or self.s >= c.length_m
        dev = -abs(self.y) / c.half_width_m
        reward = -1000.0 if oob else progress + dev
        info = {"out_of_bounds": oob, "reward_terms": {} if oob else {"progress": progress, "deviation": dev},
                "reached": self.s >= c.length_m and not oob}
        return self._obs(), reward, done, False, info

    def oracle(self):
        """The true strip (the edge strip towards the far end when it is out of view); risk is
        the larger of the lateral offset (fraction of the half width) and the bearing error
        (fraction of 45 degrees)."""
        h = self.bearing()
        b = self.true_bin()
        if b == UNKNOWN:
            b = 1 if h < 0 else N_BINS
        risk = max(abs(self.y) / self.cfg.half_width_m, min(1.0, abs(h) / 45.0))
        return b, float(min(1.0, risk))

    def safe_action(self):
        return UNKNOWN

    # -- frames -----------------------------------------------------------------------------
    def _obs(self) -> np.ndarray:
        h = self.bearing()
        if self.photos:
            return self._photo_frame(h)
        return synthetic_frame(h, self.cfg.width, self.cfg.height, self.cfg.fov_deg, seed=self.photo)

    def _photo_frame(self, h: float) -> np.ndarray:
        img, far_x = self.photos[self.photo]
        h0 = x_to_heading(far_x, self.cfg.fov_deg)
        psi = float(np.clip(h0 - h, -80.0, 80.0))  # turning right by psi moves the goal to h0 - psi
        warped = yaw_reflect(img, psi, self.cfg.fov_deg)
        return cv2.resize(warped, (self.cfg.width, self.cfg.height), interpolation=cv2.INTER_AREA)


def _reflect(coord: np.ndarray, size: int) -> np.ndarray:
    """Pixel coordinates folded back into ``[0, size - 1]`` by mirroring at the edges."""
    r = np.mod(coord + 0.5, 2.0 * size)
    r = np.where(r >= size, 2.0 * size - r, r) - 0.5
    return np.clip(r, 0.0, size - 1.0)


def yaw_reflect(image: np.ndarray, psi_deg: float, fov_deg: float = DEFAULT_FOV_DEG) -> np.ndarray:
    """The view of ``image`` turned right by ``psi_deg`` (the homography of
    ``data_tools.augment.yaw``), with every pixel filled: rays that miss the photo take the
    photo mirrored at its edges, rays from behind the photo's camera take the nearest column
    that is in front. Same shape and dtype as ``image``."""
    from crossing_assist.data_tools.augment import intrinsics  # noqa: PLC0415

    h, w = image.shape[:2]
    k = intrinsics(w, h, fov_deg)
    f, cx, cy = k[0, 0], k[0, 2], k[1, 2]
    c, s = math.cos(math.radians(psi_deg)), math.sin(math.radians(psi_deg))
    xn = (np.arange(w, dtype=np.float64) - cx) / f
    z = c - s * xn
    ahead = z > 0.05
    if not ahead.any():
        ahead = z >= z.max()
    idx = np.arange(w)
    good = idx[ahead]
    nearest = good[np.clip(np.searchsorted(good, idx), 0, len(good) - 1)]
    left = good[np.clip(np.searchsorted(good, idx) - 1, 0, len(good) - 1)]
    nearest = np.where(np.abs(left - idx) < np.abs(nearest - idx), left, nearest)
    xn, z = xn[nearest], z[nearest]
    sx = f * (c * xn + s) / z + cx
    yn = (np.arange(h, dtype=np.float64) - cy) / f
    sy = f * yn[:, None] / z[None, :] + cy
    map_x = np.broadcast_to(_reflect(sx, w)[None, :], (h, w)).astype(np.float32)
    map_y = _reflect(sy, h).astype(np.float32)
    return cv2.remap(np.ascontiguousarray(image), map_x, map_y, interpolation=cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REFLECT)


def synthetic_frame(heading_deg: float, width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG,
                    seed: int = 0) -> np.ndarray:
    """A plain zebra crossing whose far end lies at ``heading_deg``: grey road, white bands
    converging from the bottom centre to the far end on the horizon (H x W x 3 uint8)."""
    img = np.full((height, width, 3), 90 + 10 * (seed % 5), np.uint8)
    horizon = int(0.4 * height)
    img[:horizon] = (150, 170, 200)
    x_goal = heading_to_x(float(np.clip(heading_deg, -89.0, 89.0)), fov_deg) * width
    rows = np.arange(horizon, height)
    frac = (rows - horizon) / max(height - horizon - 1, 1)          # 0 at horizon, 1 at bottom
    centre = x_goal + (width / 2 - x_goal) * frac
    half = 1 + frac * width * 0.35
    band = ((np.sqrt(frac + 1e-3) * 12).astype(int) % 2) == 0
    cols = np.arange(width)[None, :]
    mask = (np.abs(cols - centre[:, None]) <= half[:, None]) & band[:, None]
    img[horizon:][mask] = 235
    return img
