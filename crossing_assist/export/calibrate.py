"""Calibration stored in the bundle (numpy only): temperature, conformal threshold, gate threshold.

All three are fitted on the labelled validation frames. How well the procedure holds on frames
it never saw is measured by :func:`cross_fit`: :func:`source_folds` cuts the frames by their
leakage unit (photographer, video, place), and each fold is measured with a temperature and a
threshold fitted on the other folds only, never on its own frames or sources.

* Temperature ``tau`` minimises the negative log-likelihood of the MC-averaged probabilities
  ``mean_t softmax(logits_t / tau)`` (the bundle's ``probs``), by golden-section search on
  ``log tau`` in [0.05, 20].
* Split-conformal threshold (Vovk; Angelopoulos & Bates 2021, "LAC" scores): with ``n``
  calibration frames and target coverage ``1 - alpha``, the threshold is the
  ``k = ceil((n + 1)(1 - alpha))``-th largest probability of the true action. The set
  ``{a : probs[a] >= threshold}`` then holds the true action with probability >= 1 - alpha on
  exchangeable new frames (and < 1 - alpha + 1/(n + 1) on average).
* Gate threshold: the gate's coefficient ``1 - tanh(c U)`` should be about one half where the
  learner is right about half the time. We fit ``P(correct | U) = sigmoid(a + b U)`` by
  logistic regression on the calibration frames and take the ``U`` where it crosses 0.5,
  clipped to the 5..95 % range of the observed ``U``; when ``U`` carries no signal (``b >= 0``)
  or the crossing lies outside that range, the clip decides (5 % when the learner is mostly
  wrong, 95 % when mostly right).

A fit that ends on one of these clips did not find what it looks for: :func:`temperature_warning`
and :func:`gate_warnings` say so in one line each (``crossing-export`` prints them as warnings).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crossing_assist.bundle import Calibration, ConformalSpec, UncertaintySpec

TEMP_RANGE = (0.05, 20.0)


def softmax_mc(logits: np.ndarray, temperature: float = 1.0) -> np.ndarray:
    """Mean over samples of ``softmax(logits / temperature)``: logits [T, N, A] -> probs [N, A]."""
    z = np.asarray(logits, dtype=np.float64) / temperature
    z = z - z.max(-1, keepdims=True)
    p = np.exp(z)
    p /= p.sum(-1, keepdims=True)
    return p.mean(0)


def nll(logits: np.ndarray, labels: np.ndarray, temperature: float = 1.0) -> float:
    """Mean negative log-likelihood (nats) of ``labels`` [N] under the MC-averaged probabilities."""
    p = softmax_mc(logits, temperature)
    return float(-np.log(np.maximum(p[np.arange(len(labels)), labels], 1e-12)).mean())


def fit_temperature(logits: np.ndarray, labels: np.ndarray, *, iters: int = 60) -> float:
    """Temperature (> 0) minimising :func:`nll` of MC logits [T, N, A] on action labels [N]."""
    labels = np.asarray(labels, dtype=np.int64)
    logits = np.asarray(logits)
    if logits.ndim != 3 or logits.shape[1] != len(labels) or len(labels) == 0:
        raise ValueError(f"logits must be [T, N, A] with N = len(labels) = {len(labels)} > 0, got {logits.shape}")
    lo, hi = math.log(TEMP_RANGE[0]), math.log(TEMP_RANGE[1])
    g = (math.sqrt(5) - 1) / 2
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    fa, fb = nll(logits, labels, math.exp(a)), nll(logits, labels, math.exp(b))
    for _ in range(iters):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = nll(logits, labels, math.exp(a))
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = nll(logits, labels, math.exp(b))
    return float(math.exp((lo + hi) / 2))


def conformal_threshold(probs: np.ndarray, labels: np.ndarray, coverage: float) -> float:
    """Split-conformal threshold for sets ``{a : probs[a] >= t}`` at the given coverage.

    probs [N, A] (calibration frames), labels [N] action indices, 0 < coverage < 1. Returns
    0.0 (every action in every set) when there are too few frames for the coverage
    (``ceil((n + 1) coverage) > n``).
    """
    if not 0.0 < coverage < 1.0:
        raise ValueError(f"Invalid coverage: {coverage}; valid: 0 < coverage < 1")
    probs = np.asarray(probs, dtype=np.float64)
    labels = np.asarray(labels, dtype=np.int64)
    n = len(labels)
    k = math.ceil((n + 1) * coverage)
    if n == 0 or k > n:
        return 0.0
    true_p = np.sort(probs[np.arange(n), labels])[::-1]  # descending
    return float(true_p[k - 1])


def _logistic(u: np.ndarray, y: np.ndarray, iters: int = 50) -> tuple[float, float]:
    """Newton's method for P(y=1|u) = sigmoid(a + b u) (small ridge for separable data)."""
    x = np.stack([np.ones_like(u), u], 1)
    w = np.zeros(2)
    ridge = 1e-3 * np.eye(2)
    for _ in range(iters):
        p = 1 / (1 + np.exp(-np.clip(x @ w, -30, 30)))
        grad = x.T @ (p - y) + ridge @ w
        hess = (x * (p * (1 - p))[:, None]).T @ x + ridge
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.abs(step).max() < 1e-9:
            break
    return float(w[0]), float(w[1])


@dataclass(frozen=True)
class GateFit:
    """The gate threshold of :func:`fit_gate` and how it was decided."""

    threshold: float
    clip: str | None    # None: where the fitted P(correct | U) crosses 0.5; "5 %" / "95 %": that quantile of U decided
    signal: bool        # False: U carried no signal (the fitted P(correct | U) does not fall as U grows)
    accuracy: float     # of the frames it was fitted on


def fit_gate(uncertainty: np.ndarray, correct: np.ndarray) -> GateFit:
    """:func:`uncertainty_threshold` with whether (and why) a clip decided it."""
    u = np.asarray(uncertainty, dtype=np.float64)
    y = np.asarray(correct, dtype=np.float64)
    if len(u) == 0 or len(u) != len(y):
        raise ValueError(f"uncertainty and correct must be equally long and non-empty ({len(u)}, {len(y)})")
    lo, hi = (float(q) for q in np.quantile(u, [0.05, 0.95]))
    scale = max(float(u.std()), 1e-12)
    a, b = _logistic((u - u.mean()) / scale, y)
    if b >= 0:
        t = lo if y.mean() < 0.5 else hi
    else:
        t = float(u.mean() + scale * (-a / b))
    clip = "5 %" if t <= lo else "95 %" if t >= hi else None
    return GateFit(float(max(min(max(t, lo), hi), 1e-6)), clip, b < 0, float(y.mean()))


def uncertainty_threshold(uncertainty: np.ndarray, correct: np.ndarray) -> float:
    """The uncertainty where the fitted P(correct | U) is 0.5, clipped to U's 5..95 % quantiles.

    uncertainty [N] (e.g. entropy in nats), correct [N] bool (argmax == label). Always > 0.
    """
    return fit_gate(uncertainty, correct).threshold


def measure_max(measure: str, n_actions: int) -> float:
    """The largest value the gate measure can take with ``n_actions`` actions."""
    return {"entropy": math.log(n_actions), "mutual_info": math.log(n_actions), "variance": 0.25,
            "far_mass": 1.0}[measure]


def temperature_warning(temperature: float, where: str = "--calib-data") -> str | None:
    """One line when a fitted temperature ended on a bound of :data:`TEMP_RANGE`, else None."""
    lo, hi = TEMP_RANGE
    if math.log(hi) - math.log(temperature) < 1e-3:
        return (f"temperature {temperature:.3g} is at its upper clip {hi:g}: the fit flattened the model's "
                f"probabilities as far as it may, the model is confidently wrong on {where} (check the labels, "
                "the split and that the run was trained for these frames)")
    if math.log(temperature) - math.log(lo) < 1e-3:
        return (f"temperature {temperature:.3g} is at its lower clip {lo:g}: the fit sharpened the model's "
                f"probabilities as far as it may, its logits barely tell the actions apart on {where}")
    return None


def gate_warnings(uncertainty: np.ndarray, fit: GateFit, threshold: float, measure: str, n_actions: int,
                  where: str = "--calib-data") -> list[str]:
    """One line for each way the shipped gate ``threshold`` (the fitted one of ``fit``, perhaps
    scaled) on the ``uncertainty`` [N] of the calibration frames is not a calibrated gate: its
    fit ended on a clip, it lies at the measure's largest possible value, or no calibration
    frame is at or above it (the gate speaks on every one)."""
    u = np.asarray(uncertainty, dtype=np.float64)
    passed = float((u < threshold).mean())
    out = []
    if fit.clip is not None:
        mostly = "right" if fit.clip == "95 %" else "wrong"
        if fit.accuracy in (0.0, 1.0):
            why = f"the model is {'right' if fit.accuracy else 'wrong'} on every one of them"
        elif not fit.signal:
            why = f"{measure} does not tell the frames the model gets right from those it gets wrong"
        else:
            why = f"the model is {mostly} more than half the time at every {measure} there"
        out.append(f"the gate threshold fit ended on its clip, the {fit.clip} quantile of {measure} on {where} "
                   f"({fit.threshold:.4g}): {why}; the gate ({measure} < {threshold:.4g}) passes {passed:.0%} "
                   f"of those {len(u)} frames")
    top = measure_max(measure, n_actions)
    if threshold >= 0.99 * top:
        out.append(f"the gate threshold {threshold:.4g} is within 1 % of the largest {measure} possible with "
                   f"{n_actions} actions ({top:.4g}): the gate passes nearly every frame, however unsure the model is")
    elif passed == 1.0:
        out.append(f"the gate threshold {threshold:.4g} is above the {measure} of every frame of {where} "
                   f"(largest {u.max():.4g}): the gate passes all {len(u)} of them")
    return out


def source_folds(sources: list[str] | np.ndarray, k: int = 5) -> list[np.ndarray]:
    """Cut frames into at most ``k`` folds (index arrays) that never share a source.

    Whole sources go, largest first, to the fold with the fewest frames, so no photographer,
    video or place is on both sides of a calibrate/measure cut. With fewer sources than ``k``
    each source is a fold; with a single source the frames are cut into ``k`` contiguous
    blocks in their given order (neighbouring frames stay together).
    """
    sources = np.asarray(sources).astype(str)
    n = len(sources)
    if n < 2 or k < 2:
        raise ValueError(f"need at least 2 labelled frames and 2 folds to calibrate and measure, got {n} and {k}")
    names, counts = np.unique(sources, return_counts=True)
    if len(names) == 1:
        return [b for b in np.array_split(np.arange(n), min(k, n)) if len(b)]
    k = min(k, len(names))
    fold_of, sizes = {}, np.zeros(k, np.int64)
    for i in np.argsort(-counts, kind="stable"):
        f = int(np.argmin(sizes))
        fold_of[names[i]] = f
        sizes[f] += counts[i]
    which = np.array([fold_of[s] for s in sources])
    return [np.flatnonzero(which == f) for f in range(k)]


def cross_fit(logits: np.ndarray, labels: np.ndarray, folds: list[np.ndarray], coverage: float,
              sources: np.ndarray | None = None) -> dict:
    """Held-out conformal coverage of the whole calibration procedure, fold by fold.

    For each fold, the temperature and the conformal threshold are fitted on the *other*
    folds only (MC logits [T, N, A], action labels [N]) and the sets are measured on the fold.
    Returns the pooled coverage and mean set size over all frames (each measured exactly once,
    never with a threshold fitted on itself) and one entry per fold.
    """
    logits = np.asarray(logits)
    labels = np.asarray(labels, dtype=np.int64)
    covered = np.zeros(len(labels), bool)
    size = np.zeros(len(labels))
    per_fold = []
    for idx in folds:
        rest = np.setdiff1d(np.arange(len(labels)), idx)
        tau = fit_temperature(logits[:, rest], labels[rest])
        probs = softmax_mc(logits, tau)
        t = conformal_threshold(probs[rest], labels[rest], coverage)
        sets = probs[idx] >= t
        covered[idx] = sets[np.arange(len(idx)), labels[idx]]
        size[idx] = sets.sum(1)
        entry = {"n": int(len(idx)), "coverage": float(covered[idx].mean()), "mean_set_size": float(size[idx].mean()),
                 "temperature": tau, "threshold": t}
        if sources is not None:
            entry["sources"] = sorted(set(np.asarray(sources)[idx].astype(str).tolist()))
        per_fold.append(entry)
    return {"target": coverage, "coverage": float(covered.mean()), "mean_set_size": float(size.mean()),
            "n": int(len(labels)), "folds": per_fold}


@dataclass(frozen=True)
class CalibrationResult:
    """What goes into ``bundle.json``'s ``calibration`` plus how it was measured."""

    temperature: float
    coverage: float
    threshold: float
    n_frames: int
    measure: str
    uncertainty_threshold: float
    portrait_uncertainty_threshold: float | None = None   # None: portrait frames use uncertainty_threshold
    fitted_uncertainty_threshold: float | None = None     # before the held-out scales (informative)

    def spec(self) -> Calibration:
        """The bundle's typed ``calibration`` block."""
        return Calibration(temperature=self.temperature,
                           conformal=ConformalSpec(self.coverage, self.threshold, self.n_frames),
                           uncertainty=UncertaintySpec(self.measure, self.uncertainty_threshold,
                                                       self.portrait_uncertainty_threshold,
                                                       self.fitted_uncertainty_threshold))


def uncalibrated(n_actions: int, measure: str = "entropy") -> CalibrationResult:
    """Honest defaults when no labelled data is given: temperature 1, every action in every
    conformal set (threshold 0), gate threshold at half the maximum of the measure."""
    return CalibrationResult(1.0, 0.9, 0.0, 0, measure, measure_max(measure, n_actions) / 2)
