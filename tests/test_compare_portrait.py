"""scripts/compare_portrait.py: a photo's placement carried into its portrait views."""

import sys
from pathlib import Path

import numpy as np
import pytest

from crossing_assist.actions import N_BINS, bin_center_x, x_to_bin
from crossing_assist.data_tools.augment import phone_views, portrait_views

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import compare_portrait as cp  # noqa: E402


def _probs(**strips):
    p = np.zeros(N_BINS + 1)
    for b, v in strips.items():
        p[int(b[1:])] = v
    return p


def test_placed_x_is_the_argmax_centre_or_refined_by_its_neighbours():
    p = _probs(s5=0.5, s6=0.3, s4=0.1, s11=0.1)
    assert cp.placed_x(p, refine=False) == bin_center_x(5)
    # refined: 4, 5 and 6 weighted 0.1, 0.5, 0.3 (strip 11 is not a neighbour)
    assert cp.placed_x(p, refine=True) == pytest.approx((0.1 * bin_center_x(4) + 0.5 * bin_center_x(5) + 0.3 * bin_center_x(6)) / 0.9)
    assert bin_center_x(5) < cp.placed_x(p, refine=True) < bin_center_x(6)
    # unknown is not a place; an edge strip has one neighbour
    assert cp.placed_x(_probs(s0=0.9, s12=0.06, s11=0.04), refine=True) == pytest.approx(
        (0.06 * bin_center_x(12) + 0.04 * bin_center_x(11)) / 0.1)


def test_carried_bin_reads_the_window_strip_and_clips_beyond_its_edges():
    x0, w = 0.25, 0.5625
    for b in range(1, N_BINS + 1):
        assert cp.carried_bin(x0 + w * bin_center_x(b), x0, w) == b
    assert cp.carried_bin(0.1, x0, w) == 1 and cp.carried_bin(0.95, x0, w) == N_BINS


@pytest.mark.parametrize("phone", [False, True])
def test_in_view_gives_each_cut_its_place_on_the_photo(phone):
    img = np.zeros((240, 320, 3), np.uint8)
    for far_x in (0.05, 0.3, 0.52, 0.77, 0.97):
        label = x_to_bin(far_x)
        views = (phone_views(img, far_x, label, 3, fov_deg=53.0, train_fov_deg=67.0) if phone
                 else portrait_views(img, far_x, label, 3))
        cuts = cp.in_view(views, img.shape[1])
        assert len(cuts) == sum(v[3] for v in views) >= 1
        for _, lab, x, x0, frac in cuts:
            # the goal's place on the photo, carried into the cut, is the cut's own label and x
            assert x == pytest.approx((far_x - x0) / frac, abs=1e-9)
            assert cp.carried_bin(far_x, x0, frac) == lab
