"""Exhaustive tests of the action vocabulary: every bin, every space, every edge."""

import math

import numpy as np
import pytest

from crossing_assist import actions as A

EXPECTED_GROUPS = {
    4: [(), (1, 2, 3, 4), (5, 6, 7, 8), (9, 10, 11, 12)],
    8: [(), (1,), (2, 3), (4, 5), (6, 7), (8, 9), (10, 11), (12,)],
    13: [()] + [(b,) for b in range(1, 13)],
}


@pytest.mark.parametrize("n", A.VALID_SPACES)
def test_groups_are_the_thesis_spaces(n):
    space = A.get_space(n)
    assert space.n == n
    assert [space.action_bins(a) for a in range(n)] == EXPECTED_GROUPS[n]
    # the strips partition 1..12 exactly once
    covered = sorted(b for a in range(1, n) for b in space.action_bins(a))
    assert covered == list(range(1, 13))


@pytest.mark.parametrize("n", A.VALID_SPACES)
@pytest.mark.parametrize("b", range(0, 13))
def test_bin_to_action_every_bin(n, b):
    space = A.get_space(n)
    a = space.bin_to_action(b)
    if b == 0:
        assert a == A.UNKNOWN
    else:
        assert b in space.action_bins(a)
    assert space.bins_to_actions(np.array([b]))[0] == a


@pytest.mark.parametrize("n", A.VALID_SPACES)
@pytest.mark.parametrize("b", range(0, 13))
def test_mirror_commutes_with_grouping(n, b):
    space = A.get_space(n)
    assert space.bin_to_action(A.mirror_bin(b)) == space.mirror_action(space.bin_to_action(b))


@pytest.mark.parametrize("n", A.VALID_SPACES)
def test_mirror_action_is_an_involution_and_keeps_unknown(n):
    space = A.get_space(n)
    assert space.mirror_action(0) == 0
    for a in range(n):
        assert space.mirror_action(space.mirror_action(a)) == a
    if n == 4:
        assert [space.mirror_action(a) for a in range(4)] == [0, 3, 2, 1]


def test_mirror_bin_values():
    assert [A.mirror_bin(b) for b in range(13)] == [0] + list(range(12, 0, -1))
    for b in range(13):
        assert A.mirror_bin(A.mirror_bin(b)) == b


@pytest.mark.parametrize("x", [0.0, 0.01, 0.25, 0.5, 0.77, 1.0])
def test_mirror_x(x):
    assert A.mirror_x(x) == pytest.approx(1 - x)
    if (12 * x) % 1:  # not on a strip boundary, where floor() breaks the symmetry
        assert A.x_to_bin(A.mirror_x(x)) == A.mirror_bin(A.x_to_bin(x))


def test_x_to_bin_matches_ptl_formula_and_edges():
    xs = np.linspace(0, 1, 1201)
    for x in xs:
        assert A.x_to_bin(x) == min(12, int(np.floor(12 * x)) + 1)
    assert A.x_to_bin(0.0) == 1
    assert A.x_to_bin(1.0) == 12
    assert A.x_to_bin(1 / 12) == 2
    assert A.x_to_bin(1 / 12 - 1e-9) == 1


@pytest.mark.parametrize("b", range(1, 13))
def test_bin_center_round_trip(b):
    assert A.x_to_bin(A.bin_center_x(b)) == b


@pytest.mark.parametrize("fov", [30.0, 60.0, 90.0, 120.0, 170.0])
def test_heading_edges_and_inverse(fov):
    assert A.x_to_heading(0.0, fov) == pytest.approx(-fov / 2)
    assert A.x_to_heading(1.0, fov) == pytest.approx(fov / 2)
    assert A.x_to_heading(0.5, fov) == pytest.approx(0.0)
    for x in np.linspace(0, 1, 11):
        assert A.heading_to_x(A.x_to_heading(x, fov), fov) == pytest.approx(x)


def test_heading_is_pinhole_not_linear():
    # bin 1's centre under a 90 degree pinhole camera: atan(-11/12)
    assert A.x_to_heading(A.bin_center_x(1)) == pytest.approx(math.degrees(math.atan(-11 / 12)))


@pytest.mark.parametrize("n", A.VALID_SPACES)
def test_action_heading_every_action(n):
    space = A.get_space(n)
    headings = [space.action_heading(a) for a in range(1, n)]
    assert all(np.diff(headings) > 0), "headings increase left to right"
    for a in range(1, n):
        bins = space.action_bins(a)
        cx = (bins[0] - 1 + bins[-1]) / 24
        assert space.action_center_x(a) == pytest.approx(cx)
        assert space.action_heading(a, 60.0) == pytest.approx(A.x_to_heading(cx, 60.0))
        # mirror symmetry of headings
        assert space.action_heading(space.mirror_action(a)) == pytest.approx(-space.action_heading(a))
    with pytest.raises(ValueError, match="unknown"):
        space.action_heading(0)
    if n == 4:
        assert space.action_heading(2) == pytest.approx(0.0)
        assert space.action_heading(1) == pytest.approx(math.degrees(math.atan(-2 / 3)))


def test_heading_to_pan_edges_sign_and_saturation():
    assert A.heading_to_pan(0.0) == 0.0
    assert A.heading_to_pan(-45.0) == -1.0
    assert A.heading_to_pan(45.0) == 1.0
    assert A.heading_to_pan(-80.0) == -1.0
    assert A.heading_to_pan(80.0) == 1.0
    assert A.heading_to_pan(22.5) == pytest.approx(0.5)
    assert A.heading_to_pan(-10.0, full_scale_deg=20.0) == pytest.approx(-0.5)
    for a in range(1, 13):
        h = A.get_space(13).action_heading(a)
        assert np.sign(A.heading_to_pan(h)) == (-1 if a <= 6 else 1)
    with pytest.raises(ValueError, match="full_scale_deg"):
        A.heading_to_pan(0.0, full_scale_deg=0)
    with pytest.raises(ValueError):
        A.heading_to_pan(float("nan"))


@pytest.mark.parametrize("n", A.VALID_SPACES)
def test_bin_probs_to_action_probs(n):
    space = A.get_space(n)
    rng = np.random.default_rng(0)
    p = rng.dirichlet(np.ones(13), size=5)
    q = space.bin_probs_to_action_probs(p)
    assert q.shape == (5, n)
    np.testing.assert_allclose(q.sum(-1), 1.0)
    np.testing.assert_allclose(q[:, 0], p[:, 0])
    for a in range(1, n):
        np.testing.assert_allclose(q[:, a], p[:, list(space.action_bins(a))].sum(-1))
    with pytest.raises(ValueError, match="13"):
        space.bin_probs_to_action_probs(np.ones((2, 12)))


def test_names():
    assert A.get_space(4).names == ("unknown", "left", "straight", "right")
    assert A.get_space(8).names[:3] == ("unknown", "1", "2-3")
    assert A.get_space(13).names[12] == "12"


@pytest.mark.parametrize("text,value", [("unknown", 0), ("Unknown ", 0), ("0", 0), ("1", 1), ("12", 12), (7, 7), (0, 0)])
def test_parse_label(text, value):
    assert A.parse_label(text) == value
    assert A.parse_label(A.format_label(value)) == value


@pytest.mark.parametrize("bad", ["13", "-1", "", "left", 13, -1, 2.5, None])
def test_parse_label_rejects(bad):
    with pytest.raises(ValueError, match="1..12 or 'unknown'"):
        A.parse_label(bad)


def test_errors_name_the_valid_range():
    with pytest.raises(ValueError, match="valid: 4, 8, 13"):
        A.get_space(5)
    with pytest.raises(ValueError, match=r"valid: 0 \(unknown\) or 1..12"):
        A.mirror_bin(13)
    with pytest.raises(ValueError, match=r"valid: 1..12"):
        A.bin_center_x(0)
    with pytest.raises(ValueError, match=r"0 <= x <= 1"):
        A.x_to_bin(1.5)
    with pytest.raises(ValueError, match=r"0 <= x <= 1"):
        A.x_to_bin(float("nan"))
    with pytest.raises(ValueError, match="0..3"):
        A.get_space(4).action_bins(4)
    with pytest.raises(ValueError, match="0..7"):
        A.get_space(8).mirror_action(-1)
    with pytest.raises(ValueError, match="0 < fov < 180"):
        A.x_to_heading(0.5, 180.0)
    with pytest.raises(ValueError, match="-90 < heading < 90"):
        A.heading_to_x(90.0)
    with pytest.raises(ValueError, match="0..12"):
        A.get_space(13).bins_to_actions(np.array([3, 14]))
    with pytest.raises(TypeError):
        A.mirror_bin(True)
    with pytest.raises(TypeError):
        A.get_space(4).action_bins(1.0)
