"""scripts/heading_error.py: heading errors in degrees from saved held-out predictions."""

import sys
from pathlib import Path

import numpy as np
import pytest
from runtime_toy import bar_frame, toy_bundle  # noqa: F401  (fixture)

from crossing_assist.actions import UNKNOWN, bin_center_x, x_to_heading
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.listen import Listener

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import heading_error as he  # noqa: E402


def test_strip_heading_is_the_strip_centres_heading_at_each_fov():
    got = he.strip_heading(np.array([1, 6, 7, 12]), np.array([67.0, 67.0, 53.0, 40.8]))
    want = [x_to_heading(bin_center_x(b), f) for b, f in ((1, 67.0), (6, 67.0), (7, 53.0), (12, 40.8))]
    assert got == pytest.approx(want)
    assert he.strip_heading(np.array([1]), np.array([67.0]))[0] == pytest.approx(-he.strip_heading(np.array([12]), np.array([67.0]))[0])


def test_view_errors_counts_in_view_clips_and_the_beacon_only_when_heard(toy_bundle):  # noqa: F811
    lis = Listener(Engine(toy_bundle), seconds=0.5)
    for strip in (2, 6, 11):
        lis.add(bar_frame(bin_center_x(strip)), strip)
    lis.add(bar_frame(bin_center_x(9)), 3)         # labelled 3, the bar (and the model) in strip 9
    lis.add(bar_frame(None), UNKNOWN)              # no crossing: never counted
    e = he.view_errors(lis, [0, 1, 2, 3, 4], threshold=100.0)
    assert e["right"].tolist() == [True, True, True, False]
    fov = e["fov"][0]
    six_strips = abs(x_to_heading(bin_center_x(9), fov) - x_to_heading(bin_center_x(3), fov))
    assert e["model"] == pytest.approx([0, 0, 0, six_strips], abs=1e-9)
    assert (e["heard"][:3] < fov / 24).all() and e["heard"][3] == pytest.approx(six_strips, abs=fov / 24)
    assert e["label"].tolist() == [2, 6, 11, 3] and e["wrong"].tolist() == [False, False, False, True]
    assert he.by_strip("x", e) == ["| x | 2 | 1 | 100.0 % | 0.00 % |", "| x | 3 | 1 | 100.0 % | 100.00 % |",
                                   "| x | 6 | 1 | 100.0 % | 0.00 % |", "| x | 11 | 1 | 100.0 % | 0.00 % |"]
    off = he.view_errors(lis, [0, 1], threshold=1e-6)      # nothing passes a tiny threshold: nothing heard
    assert np.isnan(off["heard"]).all() and off["model"] == pytest.approx([0, 0], abs=1e-9)
    assert not off["wrong"].any() and he.by_strip("x", off)[0] == "| x | 2 | 1 | 0.0 % | 0.00 % |"
    assert "| x | 2 |" in he.row("x", off) and "| 0.0 % | n/a |" in he.row("x", off)
