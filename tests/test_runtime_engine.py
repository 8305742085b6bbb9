"""The engine on a toy bundle (built without torch): typed predictions, errors never raised."""

import json
import math

import numpy as np
import pytest
from runtime_toy import bar_frame, make_toy_bundle, toy_bundle  # noqa: F401  (fixture)

from crossing_assist.actions import bin_center_x, x_to_heading
from crossing_assist.bundle import BundleError
from crossing_assist.runtime.engine import Engine


@pytest.fixture(scope="module")
def engine(toy_bundle):  # noqa: F811
    return Engine(toy_bundle)


@pytest.mark.parametrize("k", [1, 4, 9, 12])
def test_prediction_follows_the_bar(engine, k):
    p = engine.predict(bar_frame(bin_center_x(k)))
    assert p.ok and p.action == k and p.probs.shape == (13,)
    assert p.probs.sum() == pytest.approx(1.0, abs=1e-5)
    assert p.heading_deg == pytest.approx(x_to_heading(bin_center_x(k)))
    # entropy < 1.6 unless >= 5 of the 8 samples drop the bar (p=0.05 each: chance < 2e-5)
    assert k in p.conformal_set and p.uncertainty == p.entropy < 1.6


def test_no_bar_is_flat_and_uncertain(engine):
    p = engine.predict(bar_frame(None))
    assert p.ok and p.entropy > 2.4 and len(p.conformal_set) == 13


def test_mc_samples_vary(engine):
    """Dropout survives onnxruntime's optimiser: samples differ, so mutual information > 0
    (each sample drops the bar's logit with p=0.05; 8 samples all keep it with chance 0.66,
    so over 40 frames the chance that none varies is 0.66**40 < 1e-7)."""
    mis = [engine.predict(bar_frame(0.3)).mutual_info for _ in range(40)]
    assert max(mis) > 0.01 and len(set(mis)) > 1


def test_a_seed_replays_the_mc_masks_and_another_seed_draws_others(toy_bundle):  # noqa: F811
    """``seed`` seeds onnxruntime's random ops: an engine opened with the same seed draws the same
    masks frame after frame (so a rerun hears the same), another seed other masks."""
    frames = [bar_frame(0.3)] * 40

    def draws(seed):
        e = Engine(toy_bundle, seed=seed)
        return [e.predict(f).mutual_info for f in frames]

    first, other, again = draws(1), draws(2), draws(1)
    assert len(set(first)) > 1                       # still fresh masks from frame to frame
    assert again == first and other != first
    for bad in (-1, 2 ** 63, 1.5, True):
        with pytest.raises(BundleError, match="Invalid seed"):
            Engine(toy_bundle, seed=bad)


def test_bad_frames_and_failing_sessions_come_back_as_failed_predictions(engine, monkeypatch):
    for bad in (np.zeros((4, 4), np.uint8), np.zeros((8, 8, 3), np.float32), None):
        p = engine.predict(bad)
        assert not p.ok and p.error and p.probs is None and math.isinf(p.uncertainty)

    class Broken:
        def run(self, *a, **k):
            raise RuntimeError("device lost")

    monkeypatch.setattr(engine, "session", Broken())
    p = engine.predict(bar_frame(0.5))
    assert not p.ok and "device lost" in p.error


def test_unusable_bundles_raise_one_clear_line(tmp_path, toy_bundle):  # noqa: F811
    with pytest.raises(BundleError, match="not a folder"):
        Engine(tmp_path / "nope")
    b = make_toy_bundle(tmp_path / "b")
    meta = json.loads((b / "bundle.json").read_text())
    meta["actions"] = {"n": 4, "names": ["unknown", "left", "straight", "right"],
                       "bins": [[], [1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12]]}
    (b / "bundle.json").write_text(json.dumps(meta))
    with pytest.raises(BundleError) as err:
        Engine(b)
    assert "\n" not in str(err.value)
