"""Calibration (numpy only): temperature, split-conformal threshold, gate threshold, source split.

The stochastic checks use fixed seeds, so they are deterministic; the tolerances are set at
about 4 standard errors, so a different seed would fail by luck with probability < 1e-4.
"""

import math

import numpy as np
import pytest

from crossing_assist.export.calibrate import (
    conformal_threshold,
    cross_fit,
    fit_temperature,
    nll,
    softmax_mc,
    source_folds,
    uncalibrated,
    uncertainty_threshold,
)
from crossing_assist.conformal import conformal_report, conformal_sets


def mc_logits(rng, t=4, n=3000, a=6, spread=3.0):
    base = rng.normal(0, spread, (1, n, a))
    return base + rng.normal(0, 0.5, (t, n, a))


def sample_labels(rng, probs):
    u = rng.random((len(probs), 1))
    return (probs.cumsum(1) < u).sum(1).clip(0, probs.shape[1] - 1)


def test_softmax_mc_averages_samples():
    logits = np.log(np.array([[[0.9, 0.1]], [[0.1, 0.9]]]))
    np.testing.assert_allclose(softmax_mc(logits), [[0.5, 0.5]])
    np.testing.assert_allclose(softmax_mc(np.zeros((3, 2, 4)), 7.0), np.full((2, 4), 0.25))


@pytest.mark.parametrize("true_t", [0.5, 1.0, 2.5])
def test_fit_temperature_recovers_the_generating_temperature(true_t):
    rng = np.random.default_rng(int(true_t * 10))
    logits = mc_logits(rng)
    labels = sample_labels(rng, softmax_mc(logits, true_t))
    t = fit_temperature(logits, labels)
    assert abs(math.log(t / true_t)) < 0.12, (t, true_t)
    assert nll(logits, labels, t) <= nll(logits, labels, 1.0) + 1e-9


def test_fit_temperature_rejects_bad_shapes():
    with pytest.raises(ValueError, match=r"\[T, N, A\]"):
        fit_temperature(np.zeros((5, 4)), np.zeros(5, int))


def test_conformal_threshold_is_the_kth_largest_true_probability():
    probs = np.array([[0.1, 0.9], [0.6, 0.4], [0.3, 0.7], [0.8, 0.2], [0.5, 0.5],
                      [0.05, 0.95], [0.35, 0.65], [0.45, 0.55], [0.25, 0.75]])
    labels = np.array([1, 1, 1, 0, 0, 1, 0, 1, 1])
    # true-class probs sorted descending: .95 .9 .8 .75 .7 .55 .5 .4 .35
    # coverage 0.8: k = ceil(10 * 0.8) = 8 -> 0.4
    assert conformal_threshold(probs, labels, 0.8) == pytest.approx(0.4)
    assert conformal_threshold(probs, labels, 0.95) == 0.0  # k = 10 > n: every action in the set
    with pytest.raises(ValueError, match="coverage"):
        conformal_threshold(probs, labels, 1.0)


def test_conformal_sets_cover_new_exchangeable_frames_at_the_target():
    """Calibrate on 600 frames, measure on 20,000 from the same model. Split-conformal
    coverage given the calibration set is Beta-distributed with sd ~ 0.012 here; the band
    [0.9 - 0.04, 0.9 + 1/601 + 0.04] is > 3 sd wide on each side (seeded, so deterministic)."""
    rng = np.random.default_rng(7)
    cal_logits, test_logits = mc_logits(rng, n=600), mc_logits(rng, n=20000)
    cal_probs, test_probs = softmax_mc(cal_logits), softmax_mc(test_logits)
    cal_labels, test_labels = sample_labels(rng, cal_probs), sample_labels(rng, test_probs)
    t = conformal_threshold(cal_probs, cal_labels, 0.9)
    rep = conformal_report(test_probs, test_labels, t)
    assert 0.86 <= rep["coverage"] <= 0.9 + 1 / 601 + 0.04
    assert 1.0 <= rep["mean_size"] < 6.0  # informative: smaller than the full set
    assert sum(rep["size_hist"]) == 20000


def test_conformal_report_on_a_hand_example():
    probs = np.array([[0.7, 0.2, 0.1], [0.4, 0.35, 0.25], [0.1, 0.1, 0.8]])
    rep = conformal_report(probs, np.array([0, 1, 0]), 0.3)
    np.testing.assert_array_equal(conformal_sets(probs, 0.3), [[1, 0, 0], [1, 1, 0], [0, 0, 1]])
    assert rep["coverage"] == pytest.approx(2 / 3)
    assert rep["mean_size"] == pytest.approx(4 / 3) and rep["empty"] == 0.0
    assert rep["size_hist"] == [0, 2, 1, 0]
    with pytest.raises(ValueError, match="labels"):
        conformal_report(probs, np.array([0, 1]), 0.3)


def test_uncertainty_threshold_finds_where_half_are_right():
    rng = np.random.default_rng(3)
    u = rng.uniform(0, 2, 5000)
    correct = rng.random(5000) < 1 / (1 + np.exp(-5 * (1.2 - u)))
    assert uncertainty_threshold(u, correct) == pytest.approx(1.2, abs=0.08)


def test_uncertainty_threshold_without_signal_is_clipped_to_the_observed_range():
    rng = np.random.default_rng(4)
    u = rng.uniform(0.5, 1.5, 2000)
    lo, hi = np.quantile(u, [0.05, 0.95])
    assert uncertainty_threshold(u, rng.random(2000) < 0.9) == pytest.approx(hi)  # mostly right
    assert uncertainty_threshold(u, rng.random(2000) < 0.1) == pytest.approx(lo)  # mostly wrong
    assert uncertainty_threshold(u, u < 1.0) > 0  # perfectly separable: finite and positive


def test_source_folds_never_share_a_source_and_cover_every_frame():
    sources = np.array(["heon"] * 187 + ["img"] * 79 + ["john"] * 323 + ["sam"] * 275)
    folds = source_folds(sources)
    assert len(folds) == 4  # fewer sources than folds: one source a fold
    assert sorted(np.concatenate(folds).tolist()) == list(range(len(sources)))
    assert [set(sources[f]) for f in folds] == [{"john"}, {"sam"}, {"heon"}, {"img"}]
    two = source_folds(np.array(["a"] * 10 + ["b", "c", "d"]), k=2)  # largest first, to the smallest fold
    assert [len(f) for f in two] == [10, 3]


def test_source_folds_with_one_source_cut_contiguous_blocks():
    assert [f.tolist() for f in source_folds(["x"] * 9, k=3)] == [[0, 1, 2], [3, 4, 5], [6, 7, 8]]
    with pytest.raises(ValueError, match="at least 2"):
        source_folds(["x"])


def labelled_logits(rng, n, truth_temperature=1.0):
    """MC logits [4, n, 6] and labels drawn from the model's own probabilities (calibrated);
    drawn at ``truth_temperature`` > 1 the labels are noisier than the model believes (a harder,
    shifted source)."""
    logits = mc_logits(rng, n=n)
    p = softmax_mc(logits, truth_temperature)
    labels = (p.cumsum(1) < rng.random((n, 1))).sum(1).clip(0, p.shape[1] - 1)
    return logits, labels


def test_cross_fit_coverage_is_near_the_target_on_exchangeable_sources():
    rng = np.random.default_rng(7)
    logits, labels = labelled_logits(rng, 4000)
    sources = np.array([f"s{i % 5}" for i in range(4000)])
    out = cross_fit(logits, labels, source_folds(sources), 0.9, sources)
    assert abs(out["coverage"] - 0.9) < 0.015 and len(out["folds"]) == 5
    assert all(abs(f["coverage"] - 0.9) < 0.04 for f in out["folds"])


def test_cross_fit_never_calibrates_on_the_measured_fold():
    """A hard source measured with thresholds fitted on the easy ones loses coverage; were its
    own frames in the calibration, it would not."""
    rng = np.random.default_rng(8)
    easy, y_easy = labelled_logits(rng, 3000)
    hard, y_hard = labelled_logits(rng, 1000, truth_temperature=3.0)
    logits, labels = np.concatenate([easy, hard], 1), np.r_[y_easy, y_hard]
    sources = np.array(["easy1", "easy2", "easy3"] * 1000 + ["hard"] * 1000)
    out = cross_fit(logits, labels, source_folds(sources, k=4), 0.9, sources)
    hard_fold = next(f for f in out["folds"] if f["sources"] == ["hard"])
    assert hard_fold["coverage"] < 0.85
    in_sample = conformal_threshold(softmax_mc(logits), labels, 0.9)
    assert (softmax_mc(logits)[np.arange(3000, 4000), y_hard] >= in_sample).mean() > hard_fold["coverage"]


def test_uncalibrated_defaults_are_safe():
    c = uncalibrated(13)
    assert c.threshold == 0.0 and c.n_frames == 0 and c.temperature == 1.0
    assert c.uncertainty_threshold == pytest.approx(math.log(13) / 2)
    assert c.spec().to_json()["conformal"]["threshold"] == 0.0 and c.spec().uncertainty.threshold == c.uncertainty_threshold


@pytest.mark.parametrize("module", ["crossing_assist.export", "crossing_assist.export.calibrate",
                                    "crossing_assist.conformal", "crossing_assist.inference"])
def test_torch_free_export_modules(module):
    import subprocess
    import sys

    code = f"import sys, {module}; sys.exit(3 if 'torch' in sys.modules else 0)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0, f"{module} imported torch"
