"""Field corruptions: what a phone camera meets outside (numpy + OpenCV; labels never move).

Each corruption maps an H x W x 3 uint8 RGB frame to one of the same shape, drawing its
strength from ``rng`` (an explicit ``np.random.Generator``): :data:`CORRUPTIONS` names them.
Camera roll is geometric (the goal moves) and lives in :mod:`.augment`.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np


def night(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Low light: dark gamma, a warm/blue street-light tint, shot noise, crushed blacks."""
    x = img.astype(np.float32) / 255.0
    x = x ** rng.uniform(1.6, 3.0) * rng.uniform(0.25, 0.6)
    x *= np.asarray([rng.uniform(0.8, 1.15), 1.0, rng.uniform(0.8, 1.25)], np.float32)
    x += rng.normal(0.0, rng.uniform(0.01, 0.04), x.shape).astype(np.float32)
    return np.clip(x * 255.0, 0, 255).astype(np.uint8)


def overexposure(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sun in the lens: gain, lifted blacks, clipped highlights."""
    x = img.astype(np.float32) * rng.uniform(1.4, 2.4) + rng.uniform(10, 60)
    return np.clip(x, 0, 255).astype(np.uint8)


def rain(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Rain streaks (slanted bright lines, motion-blurred) and a grey veil."""
    h, w = img.shape[:2]
    layer = np.zeros((h, w), np.float32)
    n = int(rng.uniform(0.002, 0.006) * h * w)
    ys, xs = rng.integers(0, h, n), rng.integers(0, w, n)
    layer[ys, xs] = rng.uniform(0.5, 1.0, n)
    length = max(3, int(rng.uniform(0.04, 0.1) * h))
    angle = rng.uniform(-20, 20)
    k = np.zeros((length, length), np.float32)
    k[:, length // 2] = 1.0
    rot = cv2.getRotationMatrix2D((length / 2 - 0.5, length / 2 - 0.5), angle, 1.0)
    k = cv2.warpAffine(k, rot, (length, length))
    layer = cv2.filter2D(layer, -1, k / max(k.sum(), 1e-6)) * length * 0.6
    veil = rng.uniform(0.1, 0.3)
    x = img.astype(np.float32) * (1 - veil) + 200.0 * veil + 255.0 * np.clip(layer, 0, 1)[..., None] * 0.5
    return np.clip(x, 0, 255).astype(np.uint8)


def motion_blur(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A walking user's shake: a linear blur kernel of random length and direction."""
    length = int(rng.integers(5, max(6, img.shape[1] // 20)))
    k = np.zeros((length, length), np.float32)
    k[length // 2, :] = 1.0
    rot = cv2.getRotationMatrix2D((length / 2 - 0.5, length / 2 - 0.5), rng.uniform(0, 180), 1.0)
    k = cv2.warpAffine(k, rot, (length, length))
    return cv2.filter2D(img, -1, k / max(k.sum(), 1e-6))


def jpeg(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """JPEG compression at quality 20..90 (streamed or saved frames)."""
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(20, 91))])
    return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if ok else img


def sensor_noise(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Gaussian read noise plus a little colour noise."""
    sigma = rng.uniform(5, 20)
    noise = rng.normal(0, sigma, img.shape) + rng.normal(0, sigma / 3, img.shape[:2] + (1,))
    return np.clip(img.astype(np.float32) + noise, 0, 255).astype(np.uint8)


def occluder(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A person or vehicle passing in front: a dark, textured blob covering 10..35 % of the width."""
    h, w = img.shape[:2]
    out = img.copy()
    bw = int(rng.uniform(0.1, 0.35) * w)
    x0 = int(rng.integers(0, max(1, w - bw)))
    if rng.random() < 0.5:   # person: tall, rounded top
        top = int(rng.uniform(0.1, 0.5) * h)
        mask = np.zeros((h, w), np.uint8)
        cv2.rectangle(mask, (x0, top + bw // 2), (x0 + bw, h), 1, -1)
        cv2.circle(mask, (x0 + bw // 2, top + bw // 2), bw // 2, 1, -1)
    else:                    # vehicle: wide, low box
        bw = int(bw * 1.8)
        top = int(rng.uniform(0.35, 0.7) * h)
        mask = np.zeros((h, w), np.uint8)
        cv2.rectangle(mask, (x0, top), (min(w, x0 + bw), min(h, top + int(rng.uniform(0.2, 0.4) * h))), 1, -1)
    colour = rng.integers(10, 120, 3).astype(np.float32)
    tex = colour + rng.normal(0, 12, (h, w, 1))
    out[mask.astype(bool)] = np.clip(tex[mask.astype(bool)], 0, 255).astype(np.uint8)
    return out


CORRUPTIONS: dict[str, Callable[[np.ndarray, np.random.Generator], np.ndarray]] = {
    "night": night, "overexposure": overexposure, "rain": rain, "motion_blur": motion_blur,
    "jpeg": jpeg, "noise": sensor_noise, "occluder": occluder,
}


def corrupt(img: np.ndarray, name: str, rng: np.random.Generator) -> np.ndarray:
    """Apply corruption ``name`` (one of :data:`CORRUPTIONS`) to an RGB uint8 frame."""
    if name not in CORRUPTIONS:
        raise ValueError(f"Unknown corruption: {name!r}; valid: {', '.join(CORRUPTIONS)}")
    return CORRUPTIONS[name](np.ascontiguousarray(img), rng)
