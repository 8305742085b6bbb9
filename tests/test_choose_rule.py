"""scripts/choose_gate.py's threshold rule: the most beacon-on within the confidently-wrong limit,
read either at the rate measured or at the upper end of its 95 % interval (``--upper``)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import choose_gate as cg  # noqa: E402


def _curve(wrong_frames, frames=1600, silence=1.0):
    """Scales 1, 2, ... with rising beacon-on and these confidently-wrong counts out of ``frames``."""
    return [{"scale": float(i + 1), "beacon_on": 0.5 + 0.05 * i, "confidently_wrong_frames": k, "frames": frames,
             "confidently_wrong": k / frames, "silence_no_crossing": silence} for i, k in enumerate(wrong_frames)]


def test_the_rate_rule_takes_the_most_beacon_on_at_the_limit_and_the_upper_rule_a_stricter_point():
    curve = _curve([0, 1, 3, 5, 8, 12])          # 8 of 1600 is exactly 0.5 %
    best, met = cg.choose(curve)
    assert met and best["scale"] == 5.0
    up, met_up = cg.choose(curve, upper=True)
    # its 95 % upper bound must be within 0.5 %: 8 / 1600 (upper ~0.98 %) and 5 / 1600 (~0.73 %) are not
    assert met_up and up["beacon_on"] < best["beacon_on"]
    assert cg.wilson(up["confidently_wrong_frames"], up["frames"])[1] <= 0.005
    nxt = curve[curve.index(up) + 1]
    assert cg.wilson(nxt["confidently_wrong_frames"], nxt["frames"])[1] > 0.005
    assert up["scale"] == 2.0                    # 1 of 1600: upper ~0.35 %; 3 of 1600: ~0.55 %


def test_more_photos_let_the_upper_rule_go_further_at_the_same_measured_rate():
    few = cg.choose(_curve([0, 1, 3, 5, 8], frames=1600), upper=True)[0]
    many = cg.choose(_curve([0, 10, 30, 50, 80], frames=16000), upper=True)[0]   # the same rates, 10 x the photos
    assert many["scale"] > few["scale"]


def test_with_no_point_within_the_limit_the_nearest_is_returned_and_flagged():
    curve = _curve([20, 30, 40])
    best, met = cg.choose(curve, upper=True)
    assert not met and best["scale"] == 1.0
    # silence counts too: a point under the wrong limit but loud off-crossing does not qualify
    loud = _curve([0, 0], silence=0.9)
    assert cg.choose(loud) == (loud[1], False)


def test_upper_tag_names_the_files_apart():
    assert cg.upper_tag(True) == "_upper" and cg.upper_tag(False) == ""
