"""Draw a decision onto a frame: the 12 strips, the model's probabilities, the heading, the
uncertainty, the gate state and the stop cue (OpenCV; returns a new BGR image for writing)."""

from __future__ import annotations

import cv2
import numpy as np

from crossing_assist.actions import N_BINS, heading_to_x
from crossing_assist.runtime.engine import Prediction
from crossing_assist.runtime.decide import Decision

GREEN, AMBER, RED, WHITE, GREY = (60, 200, 60), (0, 170, 255), (40, 40, 230), (255, 255, 255), (150, 150, 150)


def annotate(frame_rgb: np.ndarray, pred: Prediction, dec: Decision, space, fov_deg: float | None) -> np.ndarray:
    """The frame (H x W x 3 RGB uint8) with the overlay, as BGR uint8 of the same size
    (``fov_deg`` None: no heading line, the frame's FOV was refused)."""
    img = cv2.cvtColor(frame_rgb, cv2.COLOR_RGB2BGR)
    h, w = img.shape[:2]
    for k in range(1, N_BINS):
        x = round(k * w / N_BINS)
        cv2.line(img, (x, 0), (x, h - 1), GREY, 1)
    if pred.ok and pred.probs is not None:  # model probabilities as bars along the bottom
        bins = space.bin_probs_to_action_probs(np.eye(N_BINS + 1))  # 13 x A indicator
        for k in range(1, N_BINS + 1):
            a = int(np.argmax(bins[k]))
            p = float(pred.probs[a]) / len(space.groups[a])
            x0, x1 = round((k - 1) * w / N_BINS) + 2, round(k * w / N_BINS) - 2
            cv2.rectangle(img, (x0, h - 1 - round(p * h * 0.3)), (x1, h - 1), AMBER, -1)
    color = RED if dec.stop else (GREEN if dec.gate == "learner" else AMBER)
    if dec.heading_deg is not None and fov_deg is not None:
        x = heading_to_x(max(-89.0, min(89.0, dec.heading_deg)), fov_deg)
        xp = round(min(max(x, 0.0), 1.0) * (w - 1))
        cv2.line(img, (xp, 0), (xp, h - 1), color, 3)
    scale = max(0.4, w / 900)
    gap = round(26 * scale) + 4
    u = f"{pred.uncertainty:.2f}" if pred.ok else "--"
    lines = [f"{dec.t:.2f}s {dec.gate.upper()} ({dec.reason})",
             f"U {u}  aL {dec.alpha_learner:.2f}  aF {dec.alpha_hold:.2f}",
             "STOP / SCAN" if dec.stop else f"{dec.heading_deg:+.0f} deg  {dec.rate_hz:.1f} Hz"]
    for i, text in enumerate(lines):
        y = (i + 1) * gap
        cv2.putText(img, text, (6, y), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(img, text, (6, y), cv2.FONT_HERSHEY_SIMPLEX, scale, color if i == 2 else WHITE, 1, cv2.LINE_AA)
    if dec.stop:
        cv2.rectangle(img, (0, 0), (w - 1, h - 1), RED, max(3, w // 100))
    return img
