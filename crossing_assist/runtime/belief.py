"""Temporal filter: a discrete Bayes filter over the 12 bins + ``unknown`` (numpy only, pure).

State: ``b`` (13,) float64, a probability vector; ``b[0]`` = unknown (goal not in view), ``b[k]``
= goal in strip ``k`` (1..12). Each step of ``dt`` seconds first *predicts* (yaw shift, spatial
diffusion, forgetting), then *updates* with the frame's evidence. Every formula is written
out in docs/runtime.md ("Decision logic"); the phone app reproduces it from
android_demo/test_vectors.json, so change nothing here without regenerating the vectors.

* yaw shift: the user turned right by ``psi = yaw_rate * dt`` degrees, so every bin centre
  ``x_k`` moves to ``x' = heading_to_x(x_to_heading(x_k) - psi)`` (pinhole camera, bundle FOV);
  its mass is split linearly between the two nearest bin centres; mass leaving the frame
  (``x' < 0`` or ``x' > 1``, or ``|heading| >= 90``) goes to ``unknown``. An edge strip (1 or 12)
  means "at this edge or beyond it" (a goal out of view but inferable is labelled so), so a turn
  towards it does not bring its mass in to one known place: that mass is spread evenly between
  its moved centre and the edge strip's own centre (:func:`spread_edge`).
* diffusion: ``d = 0.25 (1 - exp(-dt / tau_diffuse))``; ``b_k <- (1-2d) b_k + d b_{k-1} + d b_{k+1}``
  over bins 1..12 with reflecting edges (``b_0 := b_1``, ``b_13 := b_12`` inside the sum).
* forgetting: ``lam = exp(-dt / tau_forget)``; ``b <- lam b + (1 - lam) / 13``: without evidence a
  heading fades (a heading is only as fresh as its evidence).
* update: per-bin probabilities ``q_k = probs[a(k)] / |bins(a(k))|``, ``q_0 = probs[0]``;
  ``b <- b * (q + eps)^w`` normalised, where ``w`` is the frame's evidence weight (0 = no change).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crossing_assist.actions import N_BINS, ActionSpace, bin_center_x, heading_to_x, x_to_heading

N_STATES = N_BINS + 1


@dataclass(frozen=True)
class FilterConfig:
    """Time constants in seconds; ``eps`` floors the per-bin likelihood (0 < eps)."""

    tau_forget_s: float = 2.0
    tau_diffuse_s: float = 2.0
    tau_evidence_s: float = 0.1
    eps: float = 0.01

    def __post_init__(self) -> None:
        for name in ("tau_forget_s", "tau_diffuse_s", "tau_evidence_s", "eps"):
            if not float(getattr(self, name)) > 0:
                raise ValueError(f"Invalid {name}: {getattr(self, name)}; valid: > 0")


def uniform_belief() -> np.ndarray:
    """The belief with no evidence: 1/13 everywhere, shape (13,)."""
    return np.full(N_STATES, 1.0 / N_STATES)


def yaw_shift(b: np.ndarray, psi_deg: float, fov_deg: float) -> np.ndarray:
    """Move the bin mass for a turn of ``psi_deg`` (positive = user turned right; goal moves left).

    ``b`` (13,) -> (13,); mass leaving the field of view goes to unknown (index 0).
    """
    if psi_deg == 0.0:
        return b.copy()
    out = np.zeros(N_STATES)
    out[0] = b[0]
    for k in range(1, N_STATES):
        h = x_to_heading(bin_center_x(k), fov_deg) - psi_deg
        if not -90.0 < h < 90.0:
            out[0] += b[k]
            continue
        x = heading_to_x(h, fov_deg)
        if (k == N_BINS and psi_deg > 0.0) or (k == 1 and psi_deg < 0.0):
            spread_edge(out, k, N_BINS * x - 0.5, b[k])
            continue
        if x < 0.0 or x > 1.0:
            out[0] += b[k]
            continue
        z = min(max(N_BINS * x - 0.5, 0.0), N_BINS - 1.0)  # 0-based continuous bin index
        i = int(math.floor(z))
        f = z - i
        if i >= N_BINS - 1:
            out[N_BINS] += b[k]
        else:
            out[i + 1] += (1.0 - f) * b[k]
            out[i + 2] += f * b[k]
    return out


def spread_edge(out: np.ndarray, k: int, z: float, mass: float) -> None:
    """Add an edge bin's ``mass`` to ``out`` after a turn moved its centre inward to ``z`` (a
    0-based continuous bin index, unclipped): spread evenly over the interval from ``z`` to the
    edge bin's own centre, each bin taking the share its cell ``[i - 0.5, i + 0.5]`` covers, the
    part beyond the far edge of the frame to unknown. A goal seen at an edge may lie anywhere
    beyond it, so after the turn it may be anywhere from ``z`` back out to the edge."""
    e = float(k - 1)
    lo, hi = min(z, e), max(z, e)
    span = hi - lo
    if not span > 1e-12:
        out[k] += mass
        return
    inside = 0.0
    for i in range(N_BINS):
        share = min(hi, i + 0.5) - max(lo, i - 0.5)
        if share > 0.0:
            out[i + 1] += mass * share / span
            inside += share
    out[0] += mass * max(0.0, span - inside) / span


def diffuse(b: np.ndarray, dt: float, tau_s: float) -> np.ndarray:
    """Spread bin mass to neighbours (reflecting edges); unknown untouched. (13,) -> (13,)."""
    d = 0.25 * (1.0 - math.exp(-dt / tau_s))
    bins = b[1:]
    left = np.concatenate(([bins[0]], bins[:-1]))
    right = np.concatenate((bins[1:], [bins[-1]]))
    out = b.copy()
    out[1:] = (1.0 - 2.0 * d) * bins + d * left + d * right
    return out


def forget(b: np.ndarray, dt: float, tau_s: float) -> np.ndarray:
    """Relax toward the uniform belief: ``lam b + (1 - lam)/13`` with ``lam = exp(-dt/tau)``."""
    lam = math.exp(-dt / tau_s)
    return lam * b + (1.0 - lam) / N_STATES


def bin_likelihood(probs: np.ndarray, space: ActionSpace) -> np.ndarray:
    """Per-state probabilities (13,) from action probabilities (A,): an action's mass is split
    evenly over its bins; unknown maps to state 0."""
    probs = np.asarray(probs, dtype=np.float64)
    q = np.empty(N_STATES)
    q[0] = probs[0]
    for k in range(1, N_STATES):
        a = int(space.lookup[k])
        q[k] = probs[a] / len(space.groups[a])
    return q


def update(b: np.ndarray, q: np.ndarray, weight: float, eps: float) -> np.ndarray:
    """Tempered Bayes update ``b * (q + eps)^weight`` normalised; ``weight = 0`` returns ``b``."""
    if weight <= 0.0:
        return b.copy()
    post = b * np.power(q + eps, weight)
    return post / post.sum()


def predict(b: np.ndarray, dt: float, yaw_rate_dps: float, fov_deg: float, cfg: FilterConfig) -> np.ndarray:
    """The prediction half of a step: yaw shift by ``yaw_rate_dps * dt``, diffusion, forgetting."""
    if dt <= 0.0:
        return b.copy()
    b = yaw_shift(b, yaw_rate_dps * dt, fov_deg)
    b = diffuse(b, dt, cfg.tau_diffuse_s)
    return forget(b, dt, cfg.tau_forget_s)


def entropy(p: np.ndarray) -> float:
    """Entropy (nats) of a probability vector, ``-sum p log p`` with 0 log 0 = 0 (the one numpy
    copy: the belief's, and the test vectors' frames)."""
    p = np.asarray(p)
    p = p[p > 0]
    return float(-(p * np.log(p)).sum())


def far_mass(p: np.ndarray) -> float:
    """Probability outside the most probable action and its neighbours: ``1 - sum p[a-1..a+1]``
    over the strips (``a`` = argmax, first on ties; the neighbours stop at strips 1 and A-1, never
    unknown), ``1 - p[0]`` when ``a`` is unknown. Low = the mass sits within one strip of the
    argmax, so the beacon, if on, is at most one strip off by the model's own account; a central goal whose
    probability spreads over neighbouring strips is not doubted for that, as entropy doubts it."""
    p = np.asarray(p, dtype=np.float64)
    a = int(np.argmax(p))
    if a == 0:
        return float(1.0 - p[0])
    return float(max(0.0, 1.0 - p[max(1, a - 1):min(len(p) - 1, a + 1) + 1].sum()))


#: The gate measures a probability vector gives (a frame's ``probs`` or the belief in the action
#: space), by name: the belief is gated with the frames' measure when it is one of these.
PROBS_MEASURES = {"entropy": entropy, "far_mass": far_mass}


def belief_heading(b: np.ndarray, space: ActionSpace, fov_deg: float) -> tuple[int, float | None]:
    """The belief's most probable action (first on ties) and its heading in degrees.

    Unknown -> ``(0, None)``. Otherwise the heading of ``x_hat``, the belief-weighted mean of the
    bin centres over the action's bins widened by one bin each side (sub-bin precision without
    averaging two separate modes).
    """
    p = space.bin_probs_to_action_probs(b)
    a = int(np.argmax(p))
    if a == 0:
        return 0, None
    bins = space.groups[a]
    lo, hi = max(1, bins[0] - 1), min(N_BINS, bins[-1] + 1)
    ks = np.arange(lo, hi + 1)
    w = b[ks]
    xs = (ks - 0.5) / N_BINS
    x_hat = float((w * xs).sum() / w.sum())
    return a, x_to_heading(x_hat, fov_deg)
